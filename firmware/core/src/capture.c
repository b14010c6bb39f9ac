#include "lhb/capture.h"

#include <string.h>

#include "lhb/config.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"

void lhb_capture_init(lhb_capture_t *c, const lhb_hw_t *hw, uint32_t *storage,
                      uint32_t storage_records, const lhcap_header_t *tmpl)
{
    memset(c, 0, sizeof *c);
    if (hw != NULL) {
        c->hw = *hw;
    }
    c->tmpl = *tmpl;
    /* the image size must fit in u32: cap the record count accordingly */
    uint32_t max_records = (0xFFFFFFFFu - LHCAP_HEADER_LEN - LHCAP_TRAILER_LEN) / LHCAP_RECORD_LEN;
    if (storage_records > max_records) {
        storage_records = max_records;
    }
    lhb_edges_init(&c->edges, storage, storage_records);
    c->state = LHB_STATE_IDLE;
}

static void hw_stop(lhb_capture_t *c)
{
    if (c->hw.stop != NULL) {
        c->hw.stop(c->hw.ctx);
    }
}

int lhb_capture_arm(lhb_capture_t *c, uint32_t duration_ms, uint32_t delay_ms,
                    uint64_t host_time_us, uint32_t now_ms)
{
    if (duration_ms == 0u || duration_ms > LHB_MAX_DURATION_MS || delay_ms > LHB_MAX_DELAY_MS ||
        host_time_us > UINT64_MAX - (uint64_t)delay_ms * 1000u) {
        return -LHB_E_ARG; /* (the last: start time = host time + delay must not wrap) */
    }
    if (c->state == LHB_STATE_ARMED || c->state == LHB_STATE_CAPTURING) {
        return -LHB_E_STATE;
    }
    uint64_t target = (uint64_t)duration_ms * c->tmpl.sample_rate / 1000u;
    if (c->fixed_samples != 0u) {
        target = c->fixed_samples;
    }
    if (target == 0u || target > 0xFFFFFFFFull) {
        return -LHB_E_ARG;
    }
    c->duration_ms = duration_ms;
    c->delay_ms = delay_ms;
    c->arm_ms = now_ms;
    c->host_time_us = host_time_us;
    c->target = (uint32_t)target;
    c->samples_done = 0;
    c->done = 0;
    c->hw_error = 0;
    c->finalising = false;
    c->image_size = 0;
    c->image_crc = 0;
    c->flags = 0;
    lhb_edges_init(&c->edges, c->edges.storage, c->edges.cap);
    c->state = LHB_STATE_ARMED;
    return LHB_OK;
}

void lhb_capture_abort(lhb_capture_t *c)
{
    if (c->state == LHB_STATE_CAPTURING) {
        c->state = LHB_STATE_IDLE; /* first, so that a late feed() is ignored */
    }
    hw_stop(c);
    c->state = LHB_STATE_IDLE;
    c->finalising = false;
    c->image_size = 0;
    c->image_crc = 0;
}

bool lhb_capture_feed(lhb_capture_t *c, const uint32_t *samples, size_t n)
{
    if (c->state != LHB_STATE_CAPTURING || c->done != 0u) {
        return true;
    }
    uint32_t want = c->target - c->samples_done;
    size_t take = n < want ? n : want;
    size_t used = lhb_edges_feed(&c->edges, samples, take);
    c->samples_done += (uint32_t)used;
    if (c->edges.overflow || c->samples_done >= c->target) {
        c->done = 1u;
        return true;
    }
    return false;
}

uint32_t lhb_capture_delay_left(const lhb_capture_t *c, uint32_t now_ms)
{
    if (c->state != LHB_STATE_ARMED) {
        return 0;
    }
    uint32_t elapsed = now_ms - c->arm_ms; /* wraps correctly */
    return elapsed >= c->delay_ms ? 0u : c->delay_ms - elapsed;
}

static void finalise_begin(lhb_capture_t *c)
{
    lhcap_header_t h = c->tmpl;
    c->flags = c->tmpl.flags | (c->edges.overflow ? LHCAP_FLAG_OVERFLOW : 0u);
    h.flags = c->flags;
    if (!c->fixed_start_time) {
        h.start_time_us = c->host_time_us == 0u
                              ? 0u
                              : c->host_time_us + (uint64_t)c->delay_ms * 1000u;
    }
    h.capture_samples = c->samples_done;
    h.n_records = c->edges.n;
    lhcap_header_pack(&h, c->header);
    c->crc = lhb_crc32(c->header, LHCAP_HEADER_LEN);
    c->crc_next = 0;
    c->finalising = true;
}

static bool finalise_step(lhb_capture_t *c)
{
    uint32_t end = c->crc_next + LHB_FINALISE_STEP;
    if (end > c->edges.n || end < c->crc_next) {
        end = c->edges.n;
    }
    uint8_t rec[LHCAP_RECORD_LEN];
    for (uint32_t i = c->crc_next; i < end; i++) {
        lhb_put_le32(rec, c->edges.storage[2u * i]);
        lhb_put_le32(rec + 4, c->edges.storage[2u * i + 1u]);
        c->crc = lhb_crc32_update(c->crc, rec, sizeof rec);
    }
    c->crc_next = end;
    return end == c->edges.n;
}

void lhb_capture_poll(lhb_capture_t *c, uint32_t now_ms)
{
    if (c->state == LHB_STATE_ARMED && lhb_capture_delay_left(c, now_ms) == 0u) {
        c->state = LHB_STATE_CAPTURING; /* before start: the first DMA interrupt may be quick */
        if (c->hw.start != NULL && c->hw.start(c->hw.ctx, c->target) != 0) {
            hw_stop(c);
            c->hw_error = 1u;
            c->state = LHB_STATE_IDLE;
        }
        return;
    }
    if (c->state != LHB_STATE_CAPTURING || c->done == 0u) {
        return;
    }
    if (!c->finalising) {
        hw_stop(c);
        finalise_begin(c);
    }
    if (finalise_step(c)) {
        c->finalising = false;
        c->image_crc = c->crc;
        c->image_size = LHCAP_HEADER_LEN + LHCAP_RECORD_LEN * c->edges.n + LHCAP_TRAILER_LEN;
        c->state = LHB_STATE_READY;
    }
}

int lhb_capture_read(const lhb_capture_t *c, uint32_t offset, uint8_t *dst, uint32_t len)
{
    if (c->state != LHB_STATE_READY) {
        return -LHB_E_STATE;
    }
    if (offset > c->image_size || len > c->image_size - offset || (dst == NULL && len != 0u)) {
        return -LHB_E_RANGE;
    }
    uint32_t rec_end = LHCAP_HEADER_LEN + LHCAP_RECORD_LEN * c->edges.n;
    while (len > 0u) {
        uint32_t chunk;
        if (offset < LHCAP_HEADER_LEN) {
            chunk = LHCAP_HEADER_LEN - offset;
            chunk = chunk < len ? chunk : len;
            memcpy(dst, c->header + offset, chunk);
        } else if (offset < rec_end) {
            uint32_t rel = offset - LHCAP_HEADER_LEN;
            uint32_t word = rel / 4u;
            uint32_t in_word = rel % 4u;
            uint8_t tmp[4];
            lhb_put_le32(tmp, c->edges.storage[word]);
            chunk = 4u - in_word;
            chunk = chunk < len ? chunk : len;
            memcpy(dst, tmp + in_word, chunk);
        } else {
            uint8_t tmp[4];
            lhb_put_le32(tmp, c->image_crc);
            uint32_t in_tr = offset - rec_end;
            chunk = 4u - in_tr;
            chunk = chunk < len ? chunk : len;
            memcpy(dst, tmp + in_tr, chunk);
        }
        dst += chunk;
        offset += chunk;
        len -= chunk;
    }
    return LHB_OK;
}
