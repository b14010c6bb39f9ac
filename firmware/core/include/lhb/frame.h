/* Link frames: type u8 | seq u8 | len u16 | payload[len] | crc32 u32 (all little-endian),
 * CRC over type..payload, then COBS-encoded and terminated by 0x00. */
#ifndef LHB_FRAME_H
#define LHB_FRAME_H

#include <stddef.h>
#include <stdint.h>

#include "lhb/cobs.h"

/* Commands (host -> board). Responses use type | 0x80; errors use type 0xFF. */
enum {
    LHB_CMD_INFO = 0x01,
    LHB_CMD_ARM = 0x02,
    LHB_CMD_STATUS = 0x03,
    LHB_CMD_READ = 0x04,
    LHB_CMD_ABORT = 0x05,
    LHB_RESP_FLAG = 0x80,
    LHB_RESP_ERROR = 0xFF,
};

typedef struct {
    uint8_t type;
    uint8_t seq;
    uint16_t len;
    const uint8_t *payload; /* points into the decoded buffer */
} lhb_frame_t;

/* Checks a decoded frame (size, CRC, length field). Returns LHB_OK or -lhb_err_t. */
int lhb_frame_parse(const uint8_t *raw, size_t n, lhb_frame_t *out);

/* Builds the wire form (COBS + delimiter) of a frame whose payload is the concatenation of
 * p1[0..n1) and p2[0..n2) (either may be NULL/0). Returns bytes written, 0 if it does not fit
 * or the payload exceeds 65535 bytes. */
size_t lhb_frame_encode(uint8_t type, uint8_t seq, const uint8_t *p1, size_t n1,
                        const uint8_t *p2, size_t n2, uint8_t *out, size_t cap);

#endif
