/* Consistent Overhead Byte Stuffing: removes every 0x00 from a frame so that 0x00 can
 * delimit frames on the wire. Encoder is streaming (no copy of the payload needed). */
#ifndef LHB_COBS_H
#define LHB_COBS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

typedef struct {
    uint8_t *out;
    size_t cap;
    size_t pos;      /* next write position */
    size_t code_pos; /* position of the current group's code byte */
    uint8_t code;    /* 1 + number of data bytes in the current group */
    bool overflow;
} lhb_cobs_enc_t;

void lhb_cobs_enc_begin(lhb_cobs_enc_t *e, uint8_t *out, size_t cap);
void lhb_cobs_enc_put(lhb_cobs_enc_t *e, uint8_t byte);
void lhb_cobs_enc_write(lhb_cobs_enc_t *e, const uint8_t *data, size_t n);
/* Closes the last group and appends the 0x00 delimiter when `delimit`. Returns the encoded
 * length, or 0 if the output buffer was too small. */
size_t lhb_cobs_enc_end(lhb_cobs_enc_t *e, bool delimit);

/* One-shot helpers. encode: returns encoded length without delimiter, 0 if cap too small.
 * decode: `src` without delimiter; returns decoded length or -LHB_E_FRAMING / -LHB_E_TOO_LONG. */
size_t lhb_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap);
long lhb_cobs_decode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap);

/* Streaming decoder fed byte by byte from the link. */
typedef struct {
    uint8_t *buf;
    size_t cap;
    size_t n;
    uint8_t code; /* code byte of the current group, 0 = at frame start */
    uint8_t left; /* data bytes still expected in the current group */
    uint8_t err;  /* first error seen in this frame (lhb_err_t), 0 = none */
} lhb_cobs_dec_t;

void lhb_cobs_dec_init(lhb_cobs_dec_t *d, uint8_t *buf, size_t cap);
/* Returns 0 while a frame is in progress or for an empty frame (0x00 0x00), the decoded
 * length + 1 (> 0) when a delimiter closes a good frame (data in d->buf), or -err when the
 * frame that just ended was bad. The decoder is ready for the next frame afterwards. */
long lhb_cobs_dec_push(lhb_cobs_dec_t *d, uint8_t byte);

#endif
