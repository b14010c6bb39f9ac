#include "lhb/cobs.h"

#include "lhb/errors.h"

void lhb_cobs_enc_begin(lhb_cobs_enc_t *e, uint8_t *out, size_t cap)
{
    e->out = out;
    e->cap = cap;
    e->pos = 1; /* room for the first code byte */
    e->code_pos = 0;
    e->code = 1;
    e->overflow = (cap < 1);
}

static void enc_close_group(lhb_cobs_enc_t *e)
{
    if (!e->overflow) {
        e->out[e->code_pos] = e->code;
    }
}

/* Close the current group and reserve the code byte of the next one. */
static void enc_next_group(lhb_cobs_enc_t *e)
{
    enc_close_group(e);
    if (e->pos >= e->cap) {
        e->overflow = true;
        return;
    }
    e->code_pos = e->pos++;
    e->code = 1;
}

void lhb_cobs_enc_put(lhb_cobs_enc_t *e, uint8_t byte)
{
    if (e->overflow) {
        return;
    }
    if (byte == 0u) {
        enc_next_group(e);
        return;
    }
    if (e->pos >= e->cap) {
        e->overflow = true;
        return;
    }
    e->out[e->pos++] = byte;
    e->code++;
    if (e->code == 0xFFu) { /* full group: 254 data bytes, no implied zero */
        enc_next_group(e);
    }
}

void lhb_cobs_enc_write(lhb_cobs_enc_t *e, const uint8_t *data, size_t n)
{
    for (size_t i = 0; i < n; i++) {
        lhb_cobs_enc_put(e, data[i]);
    }
}

size_t lhb_cobs_enc_end(lhb_cobs_enc_t *e, bool delimit)
{
    enc_close_group(e);
    if (delimit && !e->overflow) {
        if (e->pos >= e->cap) {
            e->overflow = true;
        } else {
            e->out[e->pos++] = 0u;
        }
    }
    return e->overflow ? 0u : e->pos;
}

size_t lhb_cobs_encode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap)
{
    lhb_cobs_enc_t e;
    lhb_cobs_enc_begin(&e, dst, cap);
    lhb_cobs_enc_write(&e, src, n);
    return lhb_cobs_enc_end(&e, false);
}

void lhb_cobs_dec_init(lhb_cobs_dec_t *d, uint8_t *buf, size_t cap)
{
    d->buf = buf;
    d->cap = cap;
    d->n = 0;
    d->code = 0;
    d->left = 0;
    d->err = 0;
}

static void dec_append(lhb_cobs_dec_t *d, uint8_t b)
{
    if (d->n >= d->cap) {
        d->err = LHB_E_TOO_LONG;
        return;
    }
    d->buf[d->n++] = b;
}

long lhb_cobs_dec_push(lhb_cobs_dec_t *d, uint8_t byte)
{
    if (byte == 0u) {
        long r;
        if (d->code == 0u && d->err == 0u) {
            r = 0; /* empty frame: used as a resynchronisation marker */
        } else if (d->err != 0u) {
            r = -(long)d->err;
        } else if (d->left != 0u) {
            r = -(long)LHB_E_FRAMING; /* delimiter inside a group: bytes were lost */
        } else {
            r = (long)d->n + 1;
        }
        d->n = 0;
        d->code = 0;
        d->left = 0;
        d->err = 0;
        return r;
    }
    if (d->err != 0u) {
        return 0; /* discard the rest of a bad frame */
    }
    if (d->left == 0u) { /* a code byte */
        if (d->code != 0u && d->code != 0xFFu) {
            dec_append(d, 0u); /* the zero implied by the previous group */
        }
        d->code = byte;
        d->left = (uint8_t)(byte - 1u);
    } else {
        dec_append(d, byte);
        d->left--;
    }
    return 0;
}

long lhb_cobs_decode(const uint8_t *src, size_t n, uint8_t *dst, size_t cap)
{
    lhb_cobs_dec_t d;
    lhb_cobs_dec_init(&d, dst, cap);
    for (size_t i = 0; i < n; i++) {
        if (src[i] == 0u) {
            return -(long)LHB_E_FRAMING;
        }
        (void)lhb_cobs_dec_push(&d, src[i]);
    }
    long r = lhb_cobs_dec_push(&d, 0u);
    if (r == 0) {
        return -(long)LHB_E_FRAMING; /* no bytes at all is not a COBS encoding */
    }
    return r > 0 ? r - 1 : r;
}
