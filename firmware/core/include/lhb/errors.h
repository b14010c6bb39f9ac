/* Error codes: returned (negated) by core functions and sent in ERROR frames. */
#ifndef LHB_ERRORS_H
#define LHB_ERRORS_H

typedef enum {
    LHB_OK = 0,
    LHB_E_CRC = 1,         /* frame CRC mismatch */
    LHB_E_FRAMING = 2,     /* COBS decoding failed / frame shorter than header + CRC */
    LHB_E_TOO_LONG = 3,    /* frame larger than the receive buffer */
    LHB_E_LENGTH = 4,      /* length field or payload length wrong for the command */
    LHB_E_UNKNOWN_CMD = 5, /* command type not known */
    LHB_E_STATE = 6,       /* command not allowed in the current capture state */
    LHB_E_ARG = 7,         /* argument out of range (duration, delay) */
    LHB_E_RANGE = 8,       /* READ block index past the end of the capture */
    LHB_E_HW = 9,          /* the sampling hardware refused to start */
    LHB_E_UNREAD = 10,     /* ARM would drop a capture not yet downloaded (no discard flag) */
} lhb_err_t;

#endif
