#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "lhb/lhcap.h"
#include "support.h"

#define NS 20000

static uint32_t samples[NS];
static uint32_t store_a[2 * NS + 2], store_b[2 * NS + 2];

/* Synthetic photodiode lines: a few pulses of varying width on varying channels. */
static void make_samples(uint32_t seed)
{
    uint32_t rng = seed;
    uint32_t word = 0x00000001u;
    for (size_t i = 0; i < NS; i++) {
        if (test_rand(&rng) % 50 == 0) {
            word ^= 1u << (test_rand(&rng) % 32);
        }
        samples[i] = word;
    }
}

int main(void)
{
    lhb_edges_t e;
    /* simple stream */
    {
        const uint32_t s[] = {0, 0, 5, 5, 5, 0, 0x80000000u, 0x80000000u};
        uint32_t st[16];
        lhb_edges_init(&e, st, 8);
        CHECK_EQ(lhb_edges_feed(&e, s, 8), 8);
        CHECK_EQ(e.n, 4);
        const uint32_t want[] = {0, 0, 2, 5, 5, 0, 6, 0x80000000u};
        CHECK(memcmp(st, want, sizeof want) == 0);
        CHECK_EQ(e.index, 8);
        CHECK(!e.overflow);
    }
    /* the first record is written even for a constant (and zero) stream */
    {
        const uint32_t s[] = {0, 0, 0};
        uint32_t st[4] = {9, 9, 9, 9};
        lhb_edges_init(&e, st, 2);
        CHECK_EQ(lhb_edges_feed(&e, s, 3), 3);
        CHECK_EQ(e.n, 1);
        CHECK(st[0] == 0 && st[1] == 0);
    }
    /* chunking does not change the result */
    make_samples(99);
    lhb_edges_init(&e, store_a, NS);
    CHECK_EQ(lhb_edges_feed(&e, samples, NS), NS);
    uint32_t n_all = e.n;
    CHECK(n_all > 100);
    lhb_edges_t e2;
    lhb_edges_init(&e2, store_b, NS);
    uint32_t rng = 7;
    size_t pos = 0;
    while (pos < NS) {
        size_t chunk = 1 + test_rand(&rng) % 700;
        if (chunk > NS - pos) {
            chunk = NS - pos;
        }
        CHECK_EQ(lhb_edges_feed(&e2, samples + pos, chunk), chunk);
        pos += chunk;
    }
    CHECK_EQ(e2.n, n_all);
    CHECK(memcmp(store_a, store_b, 8u * n_all) == 0);
    /* records: strictly increasing indices, changing words, matching the samples */
    int ok = 1;
    for (uint32_t i = 0; i < n_all; i++) {
        uint32_t idx = store_a[2 * i], w = store_a[2 * i + 1];
        if (samples[idx] != w || (i > 0 && (idx <= store_a[2 * i - 2] || w == store_a[2 * i - 1])) ||
            (idx > 0 && samples[idx - 1] == w)) {
            ok = 0;
        }
    }
    CHECK(ok);
    CHECK_EQ(store_a[0], 0);
    /* overflow: storage for 10 records stops at the sample needing the 11th */
    lhb_edges_init(&e, store_b, 10);
    size_t used = lhb_edges_feed(&e, samples, NS);
    CHECK(e.overflow);
    CHECK_EQ(e.n, 10);
    CHECK_EQ(used, store_a[2 * 10]); /* index of record 10 */
    CHECK_EQ(lhb_edges_feed(&e, samples, NS), 0); /* stays stopped */
    /* zero capacity / NULL storage */
    lhb_edges_init(&e, NULL, 10);
    CHECK_EQ(lhb_edges_feed(&e, samples, 5), 0);
    CHECK(e.overflow);
    lhb_edges_init(&e, store_b, 10);
    CHECK_EQ(lhb_edges_feed(&e, NULL, 5), 0);
    CHECK_EQ(lhb_edges_feed(&e, samples, 0), 0);
    /* sample index limit (u32) */
    lhb_edges_init(&e, store_b, 10);
    e.index = 0xFFFFFFFEull;
    e.n = 1;
    const uint32_t s3[] = {1, 2, 3};
    CHECK_EQ(lhb_edges_feed(&e, s3, 3), 2);
    CHECK(e.overflow);
    CHECK_EQ(store_b[2], 0xFFFFFFFEu);

    /* header pack/unpack and field offsets */
    lhcap_header_t h, h2;
    default_template(&h);
    h.flags = 1;
    h.start_time_us = 0x0102030405060708ull;
    h.capture_samples = 16000000u;
    h.n_records = 123456u;
    uint8_t hb[LHCAP_HEADER_LEN_IMU];
    lhcap_header_pack(&h, hb);
    CHECK(memcmp(hb, "LHCP", 4) == 0);
    CHECK_EQ(lhb_get_le16(hb + 4), 1);
    CHECK_EQ(lhb_get_le16(hb + 6), 108);
    CHECK_EQ(lhb_get_le32(hb + 8), 2000000);
    CHECK_EQ(lhb_get_le32(hb + 12), 1);
    CHECK_EQ(lhb_get_le32(hb + 16), 0x12345678);
    CHECK_EQ(lhb_get_le64(hb + 24), 0x0102030405060708ll);
    CHECK_EQ(lhb_get_le64(hb + 32), 16000000);
    CHECK_EQ(lhb_get_le32(hb + 40), 123456);
    CHECK_EQ((int16_t)lhb_get_le16(hb + 44 + 2 * 31), -1);
    CHECK_EQ(lhcap_header_unpack(hb, LHCAP_HEADER_LEN, &h2), LHB_OK);
    CHECK(memcmp(&h, &h2, sizeof h) == 0);
    CHECK_EQ(lhcap_header_unpack(hb, 107, &h2), -LHB_E_ARG);
    hb[0] = 'X';
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[0] = 'L';
    hb[4] = 2; /* version 2 needs its 128-byte header length */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[4] = 3;
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[4] = 1;
    hb[12] = 2; /* unknown flag */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[12] = 0;
    hb[44] = 0xFE; hb[45] = 0xFF; /* channel id -2 */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);

    /* version 2: the IMU fields at 108..127 */
    default_template(&h);
    h.version = LHCAP_VERSION_IMU;
    h.n_records = 9u;
    h.n_imu = 0x01020304u;
    h.imu_missed = 7u;
    h.imu_part = LHCAP_IMU_ICM42688P;
    h.imu_odr_hz = 1000u;
    h.imu_gyro_fs_dps = 2000u;
    h.imu_accel_fs_g = 16u;
    memset(hb, 0xAA, sizeof hb);
    lhcap_header_pack(&h, hb);
    CHECK_EQ(lhb_get_le16(hb + 4), 2);
    CHECK_EQ(lhb_get_le16(hb + 6), 128);
    CHECK_EQ(lhb_get_le32(hb + 40), 9);
    CHECK_EQ(lhb_get_le32(hb + 108), 0x01020304);
    CHECK_EQ(lhb_get_le32(hb + 112), 7);
    CHECK_EQ(lhb_get_le16(hb + 116), 1);
    CHECK_EQ(lhb_get_le16(hb + 118), 1000);
    CHECK_EQ(lhb_get_le16(hb + 120), 2000);
    CHECK_EQ(lhb_get_le16(hb + 122), 16);
    CHECK_EQ(lhb_get_le32(hb + 124), 0);
    CHECK_EQ(lhcap_header_len(1), 108);
    CHECK_EQ(lhcap_header_len(2), 128);
    CHECK_EQ(lhcap_header_len(3), 0);
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), LHB_OK);
    CHECK(memcmp(&h, &h2, sizeof h) == 0);
    CHECK_EQ(lhcap_header_unpack(hb, 127, &h2), -LHB_E_ARG); /* short for version 2 */
    hb[116] = 2; /* unknown IMU part */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[116] = 0; /* no IMU but IMU records */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[116] = 1;
    hb[124] = 1; /* reserved word not 0 */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[124] = 0;
    hb[120] = 0; hb[121] = 0; /* IMU records with a zero gyro full scale */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);
    hb[6] = 108; /* version 2 with a version-1 header length */
    CHECK_EQ(lhcap_header_unpack(hb, sizeof hb, &h2), -LHB_E_ARG);

    /* IMU log: little-endian words of the record, increasing indices, capacity */
    uint32_t imu_store[LHB_IMU_WORDS * 3];
    lhb_imu_log_t log;
    lhb_imu_log_init(&log, imu_store, 3);
    const int16_t raw[6] = {1, -2, 3, -32768, 32767, -1};
    CHECK(lhb_imu_log_add(&log, 10, raw));
    CHECK_EQ(imu_store[0], 10);
    CHECK_EQ(imu_store[1], 0xFFFE0001u);
    CHECK_EQ(imu_store[2], 0x80000003u);
    CHECK_EQ(imu_store[3], 0xFFFF7FFFu);
    CHECK(!lhb_imu_log_add(&log, 10, raw)); /* not increasing */
    CHECK(lhb_imu_log_add(&log, 20, raw));
    CHECK(lhb_imu_log_add(&log, 30, raw));
    CHECK(!lhb_imu_log_add(&log, 40, raw)); /* full */
    lhb_imu_log_miss(&log);
    CHECK_EQ(log.n, 3);
    CHECK_EQ(log.missed, 3);
    lhb_imu_log_trim(&log, 21);
    CHECK_EQ(log.n, 2);
    lhb_imu_log_trim(&log, 0);
    CHECK_EQ(log.n, 0);
    lhb_imu_log_t none;
    lhb_imu_log_init(&none, NULL, 5);
    CHECK(!lhb_imu_log_add(&none, 1, raw));
    CHECK_EQ(none.missed, 1);
    return check_result("edges");
}
