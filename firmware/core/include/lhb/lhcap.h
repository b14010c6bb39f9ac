/* .lhcap header (docs/formats/lhcap.md), the edge extractor that produces the records from
 * the sampled port words, and the IMU record log (version 2). */
#ifndef LHB_LHCAP_H
#define LHB_LHCAP_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define LHCAP_MAGIC "LHCP"
#define LHCAP_VERSION 1u        /* edge records only */
#define LHCAP_VERSION_IMU 2u    /* edge records, then IMU records */
#define LHCAP_HEADER_LEN 108u
#define LHCAP_HEADER_LEN_IMU 128u
#define LHCAP_RECORD_LEN 8u
#define LHCAP_IMU_RECORD_LEN 16u /* u32 sample index, i16 ax ay az gx gy gz */
#define LHCAP_TRAILER_LEN 4u
#define LHCAP_CHANNELS 32u
#define LHCAP_FLAG_OVERFLOW 0x1u
#define LHCAP_IMU_NONE 0u       /* imu_part: no IMU answered at boot */
#define LHCAP_IMU_ICM42688P 1u  /* imu_part: TDK InvenSense ICM-42688-P */

typedef struct {
    uint16_t version;         /* LHCAP_VERSION or LHCAP_VERSION_IMU */
    uint32_t sample_rate;
    uint32_t flags;
    uint32_t board_id;
    uint32_t fw_version;
    uint64_t start_time_us;
    uint64_t capture_samples;
    uint32_t n_records;
    int16_t channel_map[LHCAP_CHANNELS];
    /* version 2 only (0 in version 1) */
    uint32_t n_imu;           /* IMU records */
    uint32_t imu_missed;      /* IMU samples the board could not record */
    uint16_t imu_part;        /* LHCAP_IMU_* */
    uint16_t imu_odr_hz;      /* the IMU's output data rate */
    uint16_t imu_gyro_fs_dps; /* gyro full scale: 32768 counts = this many deg/s */
    uint16_t imu_accel_fs_g;  /* accelerometer full scale: 32768 counts = this many g */
} lhcap_header_t;

/* Header length of a version (0 for an unknown one). */
uint32_t lhcap_header_len(uint16_t version);
/* Packs h->version's header (lhcap_header_len bytes; version 1 unless h->version is 2). */
void lhcap_header_pack(const lhcap_header_t *h, uint8_t out[LHCAP_HEADER_LEN_IMU]);
/* Strict: magic, version 1 with header length exactly 108 or version 2 with exactly 128
 * (what this firmware writes), no unknown flag bits, channel ids >= -1, no unknown IMU part,
 * no IMU records with a zero full scale, the reserved word 0.
 * Returns LHB_OK or -LHB_E_ARG. */
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

/* IMU record log: one record per IMU sample, stamped with the sample index (board clock) at
 * which the IMU's data-ready arrived. Stored as 4 native u32 per record whose little-endian
 * bytes are the file's record: index, ax | ay << 16, az | gx << 16, gy | gz << 16. */
#define LHB_IMU_WORDS 4u
typedef struct {
    uint32_t *storage;
    uint32_t cap;      /* capacity in records */
    uint32_t n;        /* records written */
    uint32_t missed;   /* samples not recorded: store full, index not increasing, or
                        * reported lost by the driver (lhb_imu_log_miss) */
} lhb_imu_log_t;

void lhb_imu_log_init(lhb_imu_log_t *l, uint32_t *storage, uint32_t cap_records);
/* Appends (index, raw = ax ay az gx gy gz); returns false (and counts a miss) when full or
 * when the index does not follow the last record's. */
bool lhb_imu_log_add(lhb_imu_log_t *l, uint32_t sample_index, const int16_t raw[6]);
void lhb_imu_log_miss(lhb_imu_log_t *l);
/* Drops the records at or past sample `end` (the capture stopped before them). */
void lhb_imu_log_trim(lhb_imu_log_t *l, uint32_t end);

#endif
