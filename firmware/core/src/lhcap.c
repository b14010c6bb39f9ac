#include "lhb/lhcap.h"

#include <string.h>

#include "lhb/endian.h"
#include "lhb/errors.h"

uint32_t lhcap_header_len(uint16_t version)
{
    return version == LHCAP_VERSION ? LHCAP_HEADER_LEN
           : version == LHCAP_VERSION_IMU ? LHCAP_HEADER_LEN_IMU
                                          : 0u;
}

void lhcap_header_pack(const lhcap_header_t *h, uint8_t out[LHCAP_HEADER_LEN_IMU])
{
    bool imu = h->version == LHCAP_VERSION_IMU;
    memcpy(out, LHCAP_MAGIC, 4);
    lhb_put_le16(out + 4, (uint16_t)(imu ? LHCAP_VERSION_IMU : LHCAP_VERSION));
    lhb_put_le16(out + 6, (uint16_t)(imu ? LHCAP_HEADER_LEN_IMU : LHCAP_HEADER_LEN));
    lhb_put_le32(out + 8, h->sample_rate);
    lhb_put_le32(out + 12, h->flags);
    lhb_put_le32(out + 16, h->board_id);
    lhb_put_le32(out + 20, h->fw_version);
    lhb_put_le64(out + 24, h->start_time_us);
    lhb_put_le64(out + 32, h->capture_samples);
    lhb_put_le32(out + 40, h->n_records);
    for (unsigned k = 0; k < LHCAP_CHANNELS; k++) {
        lhb_put_le16(out + 44 + 2 * k, (uint16_t)h->channel_map[k]);
    }
    if (imu) {
        lhb_put_le32(out + 108, h->n_imu);
        lhb_put_le32(out + 112, h->imu_missed);
        lhb_put_le16(out + 116, h->imu_part);
        lhb_put_le16(out + 118, h->imu_odr_hz);
        lhb_put_le16(out + 120, h->imu_gyro_fs_dps);
        lhb_put_le16(out + 122, h->imu_accel_fs_g);
        lhb_put_le32(out + 124, 0u);
    }
}

int lhcap_header_unpack(const uint8_t *buf, size_t len, lhcap_header_t *h)
{
    if (buf == NULL || h == NULL || len < LHCAP_HEADER_LEN || memcmp(buf, LHCAP_MAGIC, 4) != 0) {
        return -LHB_E_ARG;
    }
    uint16_t version = lhb_get_le16(buf + 4);
    uint32_t header_len = lhcap_header_len(version);
    if (header_len == 0u || lhb_get_le16(buf + 6) != header_len || len < header_len) {
        return -LHB_E_ARG;
    }
    memset(h, 0, sizeof *h);
    h->version = version;
    h->sample_rate = lhb_get_le32(buf + 8);
    h->flags = lhb_get_le32(buf + 12);
    h->board_id = lhb_get_le32(buf + 16);
    h->fw_version = lhb_get_le32(buf + 20);
    h->start_time_us = lhb_get_le64(buf + 24);
    h->capture_samples = lhb_get_le64(buf + 32);
    h->n_records = lhb_get_le32(buf + 40);
    if (h->sample_rate == 0u || (h->flags & ~LHCAP_FLAG_OVERFLOW) != 0u) {
        return -LHB_E_ARG;
    }
    for (unsigned k = 0; k < LHCAP_CHANNELS; k++) {
        h->channel_map[k] = (int16_t)lhb_get_le16(buf + 44 + 2 * k);
        if (h->channel_map[k] < -1) {
            return -LHB_E_ARG;
        }
    }
    if (version == LHCAP_VERSION_IMU) {
        h->n_imu = lhb_get_le32(buf + 108);
        h->imu_missed = lhb_get_le32(buf + 112);
        h->imu_part = lhb_get_le16(buf + 116);
        h->imu_odr_hz = lhb_get_le16(buf + 118);
        h->imu_gyro_fs_dps = lhb_get_le16(buf + 120);
        h->imu_accel_fs_g = lhb_get_le16(buf + 122);
        if (h->imu_part > LHCAP_IMU_ICM42688P || (h->imu_part == LHCAP_IMU_NONE && h->n_imu != 0u) ||
            (h->n_imu != 0u && (h->imu_gyro_fs_dps == 0u || h->imu_accel_fs_g == 0u)) ||
            lhb_get_le32(buf + 124) != 0u) {
            return -LHB_E_ARG;
        }
    }
    return LHB_OK;
}

void lhb_edges_init(lhb_edges_t *e, uint32_t *storage, uint32_t cap_records)
{
    e->storage = storage;
    e->cap = storage == NULL ? 0u : cap_records;
    e->n = 0;
    e->last = 0;
    e->index = 0;
    e->overflow = false;
}

#define LHB_INDEX_LIMIT 0x100000000ull /* sample indices are u32 in the records */

size_t lhb_edges_feed(lhb_edges_t *e, const uint32_t *samples, size_t n)
{
    if (e->overflow || samples == NULL || n == 0) {
        return 0;
    }
    uint64_t room = LHB_INDEX_LIMIT - e->index;
    size_t todo = (uint64_t)n > room ? (size_t)room : n;
    uint32_t last = e->last;
    uint32_t count = e->n;
    size_t i = 0;
    if (count == 0 && e->index == 0 && todo > 0) { /* first record: the start state */
        if (e->cap == 0) {
            e->overflow = true;
            return 0;
        }
        last = samples[0];
        e->storage[0] = 0;
        e->storage[1] = last;
        count = 1;
        i = 1;
    }
    for (; i < todo; i++) {
        uint32_t w = samples[i];
        if (w != last) {
            if (count >= e->cap) {
                e->overflow = true;
                break;
            }
            e->storage[2u * count] = (uint32_t)(e->index + i);
            e->storage[2u * count + 1u] = w;
            count++;
            last = w;
        }
    }
    if (i < n && !e->overflow) {
        e->overflow = true; /* index limit reached */
    }
    e->last = last;
    e->n = count;
    e->index += i;
    return i;
}

void lhb_imu_log_init(lhb_imu_log_t *l, uint32_t *storage, uint32_t cap_records)
{
    l->storage = storage;
    l->cap = storage == NULL ? 0u : cap_records;
    l->n = 0;
    l->missed = 0;
}

bool lhb_imu_log_add(lhb_imu_log_t *l, uint32_t sample_index, const int16_t raw[6])
{
    if (l->n >= l->cap || (l->n > 0u && sample_index <= l->storage[LHB_IMU_WORDS * (l->n - 1u)])) {
        l->missed++;
        return false;
    }
    uint32_t *w = l->storage + LHB_IMU_WORDS * l->n;
    w[0] = sample_index;
    for (unsigned k = 0; k < 3; k++) {
        w[1 + k] = (uint32_t)(uint16_t)raw[2 * k] | ((uint32_t)(uint16_t)raw[2 * k + 1] << 16);
    }
    l->n++;
    return true;
}

void lhb_imu_log_miss(lhb_imu_log_t *l)
{
    l->missed++;
}

void lhb_imu_log_trim(lhb_imu_log_t *l, uint32_t end)
{
    while (l->n > 0u && l->storage[LHB_IMU_WORDS * (l->n - 1u)] >= end) {
        l->n--;
    }
}
