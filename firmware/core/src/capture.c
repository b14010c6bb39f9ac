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
    c->finalise_step = LHB_FINALISE_STEP;
    /* the image size must fit in u32: cap the record count accordingly */
    uint32_t max_records =
        (0xFFFFFFFFu - LHCAP_HEADER_LEN_IMU - LHCAP_TRAILER_LEN) / LHCAP_RECORD_LEN;
    if (storage_records > max_records) {
        storage_records = max_records;
    }
    lhb_edges_init(&c->edges, storage, storage_records);
    lhb_imu_log_init(&c->imu, NULL, 0u);
    c->state = LHB_STATE_IDLE;
}

void lhb_capture_set_imu(lhb_capture_t *c, uint32_t *storage, uint32_t storage_records)
{
    /* the image size must fit in u32 next to the edge records */
    uint32_t max_records = (0xFFFFFFFFu - LHCAP_HEADER_LEN_IMU - LHCAP_TRAILER_LEN -
                            LHCAP_RECORD_LEN * c->edges.cap) / LHCAP_IMU_RECORD_LEN;
    lhb_imu_log_init(&c->imu, storage,
                     storage_records > max_records ? max_records : storage_records);
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
    lhb_imu_log_init(&c->imu, c->imu.storage, c->imu.cap);
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

int lhb_capture_add_imu(lhb_capture_t *c, uint32_t sample_index, const int16_t raw[6])
{
    /* also once the samples are all taken (done), until finalising begins: a data-ready
     * near the end may be served after the DMA interrupt that completed the capture */
    if (c->state != LHB_STATE_CAPTURING || c->finalising) {
        return -LHB_E_STATE;
    }
    if (sample_index >= c->target) {
        return -LHB_E_STATE; /* past the capture's end: not part of it */
    }
    return lhb_imu_log_add(&c->imu, sample_index, raw) ? LHB_OK : -LHB_E_RANGE;
}

void lhb_capture_imu_missed(lhb_capture_t *c)
{
    if (c->state == LHB_STATE_CAPTURING && !c->finalising) {
        lhb_imu_log_miss(&c->imu);
    }
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
    if (h.version == LHCAP_VERSION_IMU) {
        lhb_imu_log_trim(&c->imu, c->samples_done);
        h.n_imu = c->imu.n;
        h.imu_missed = c->imu.missed;
    } else {
        h.version = LHCAP_VERSION;
        c->imu.n = 0; /* a version-1 image has no IMU records */
    }
    c->header_len = lhcap_header_len(h.version);
    lhcap_header_pack(&h, c->header);
    c->crc = lhb_crc32(c->header, c->header_len);
    c->crc_next = 0;
    c->finalising = true;
}

static uint32_t crc_words(uint32_t crc, const uint32_t *words, uint32_t n)
{
    uint8_t b[4];
    for (uint32_t i = 0; i < n; i++) {
        lhb_put_le32(b, words[i]);
        crc = lhb_crc32_update(crc, b, sizeof b);
    }
    return crc;
}

static bool finalise_step(lhb_capture_t *c)
{
    uint32_t total = c->edges.n + c->imu.n; /* records: edges first, then IMU */
    uint32_t step = c->finalise_step != 0u ? c->finalise_step : LHB_FINALISE_STEP;
    uint32_t end = c->crc_next + step;
    if (end > total || end < c->crc_next) {
        end = total;
    }
    for (uint32_t i = c->crc_next; i < end; i++) {
        c->crc = i < c->edges.n
                     ? crc_words(c->crc, c->edges.storage + 2u * i, 2u)
                     : crc_words(c->crc, c->imu.storage + LHB_IMU_WORDS * (i - c->edges.n),
                                 LHB_IMU_WORDS);
    }
    c->crc_next = end;
    return end == total;
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
        c->image_size = c->header_len + LHCAP_RECORD_LEN * c->edges.n +
                        LHCAP_IMU_RECORD_LEN * c->imu.n + LHCAP_TRAILER_LEN;
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
    uint32_t edges_end = c->header_len + LHCAP_RECORD_LEN * c->edges.n;
    uint32_t imu_end = edges_end + LHCAP_IMU_RECORD_LEN * c->imu.n;
    while (len > 0u) {
        uint32_t chunk;
        if (offset < c->header_len) {
            chunk = c->header_len - offset;
            chunk = chunk < len ? chunk : len;
            memcpy(dst, c->header + offset, chunk);
        } else {
            /* the rest is little-endian words: edge records, IMU records, the CRC */
            uint32_t word;
            uint32_t rel;
            if (offset < edges_end) {
                rel = offset - c->header_len;
                word = c->edges.storage[rel / 4u];
            } else if (offset < imu_end) {
                rel = offset - edges_end;
                word = c->imu.storage[rel / 4u];
            } else {
                rel = offset - imu_end;
                word = c->image_crc;
            }
            uint8_t tmp[4];
            lhb_put_le32(tmp, word);
            uint32_t in_word = rel % 4u;
            chunk = 4u - in_word;
            chunk = chunk < len ? chunk : len;
            memcpy(dst, tmp + in_word, chunk);
        }
        dst += chunk;
        offset += chunk;
        len -= chunk;
    }
    return LHB_OK;
}
