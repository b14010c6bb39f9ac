#include "lhb/lhcap.h"

#include <string.h>

#include "lhb/endian.h"
#include "lhb/errors.h"

void lhcap_header_pack(const lhcap_header_t *h, uint8_t out[LHCAP_HEADER_LEN])
{
    memcpy(out, LHCAP_MAGIC, 4);
    lhb_put_le16(out + 4, (uint16_t)LHCAP_VERSION);
    lhb_put_le16(out + 6, (uint16_t)LHCAP_HEADER_LEN);
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
}

int lhcap_header_unpack(const uint8_t *buf, size_t len, lhcap_header_t *h)
{
    if (buf == NULL || h == NULL || len < LHCAP_HEADER_LEN || memcmp(buf, LHCAP_MAGIC, 4) != 0 ||
        lhb_get_le16(buf + 4) != LHCAP_VERSION || lhb_get_le16(buf + 6) != LHCAP_HEADER_LEN) {
        return -LHB_E_ARG;
    }
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
