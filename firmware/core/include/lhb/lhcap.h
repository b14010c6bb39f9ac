/* .lhcap version 1 header (docs/formats/lhcap.md) and the edge extractor that produces the
 * records from the sampled port words. */
#ifndef LHB_LHCAP_H
#define LHB_LHCAP_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define LHCAP_MAGIC "LHCP"
#define LHCAP_VERSION 1u
#define LHCAP_HEADER_LEN 108u
#define LHCAP_RECORD_LEN 8u
#define LHCAP_TRAILER_LEN 4u
#define LHCAP_CHANNELS 32u
#define LHCAP_FLAG_OVERFLOW 0x1u

typedef struct {
    uint32_t sample_rate;
    uint32_t flags;
    uint32_t board_id;
    uint32_t fw_version;
    uint64_t start_time_us;
    uint64_t capture_samples;
    uint32_t n_records;
    int16_t channel_map[LHCAP_CHANNELS];
} lhcap_header_t;

void lhcap_header_pack(const lhcap_header_t *h, uint8_t out[LHCAP_HEADER_LEN]);
/* Strict: magic, version 1, header length exactly 108 (what this firmware writes), no
 * unknown flag bits, channel ids >= -1. Returns LHB_OK or -LHB_E_ARG. */
int lhcap_header_unpack(const uint8_t *buf, size_t len, lhcap_header_t *h);

/* Streaming edge extractor: records (sample index, port word) whenever the word changes;
 * the first sample always gives a record at index 0. Records are stored as pairs of
 * native u32 in `storage` (2 words per record). */
typedef struct {
    uint32_t *storage;
    uint32_t cap;      /* capacity in records */
    uint32_t n;        /* records written */
    uint32_t last;     /* last port word */
    uint64_t index;    /* samples consumed so far */
    bool overflow;     /* storage full or sample index past u32: extraction stopped */
} lhb_edges_t;

void lhb_edges_init(lhb_edges_t *e, uint32_t *storage, uint32_t cap_records);
/* Consumes up to n samples; returns how many were consumed (< n only on overflow). */
size_t lhb_edges_feed(lhb_edges_t *e, const uint32_t *samples, size_t n);

#endif
