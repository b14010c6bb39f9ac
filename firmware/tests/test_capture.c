#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "support.h"

#define NS 4000u /* 2 ms at 2 MHz */

static uint32_t samples[NS];
static uint32_t storage[2 * 1000];
#define NI 8u /* IMU samples in the version-2 test */

static uint8_t want[128 + 8 * NS + 16 * NI + 4];
static uint8_t got[128 + 8 * NS + 16 * NI + 4];
static uint8_t v1[108 + 8 * NS + 4];
static uint32_t imu_storage[LHB_IMU_WORDS * NI];

/* Polls until READY (at most 100000 times); returns the polls made. */
static uint32_t run_poll_until_ready(lhb_capture_t *c, uint32_t now)
{
    uint32_t i = 0;
    for (; i < 100000u && c->state != LHB_STATE_READY; i++) {
        lhb_capture_poll(c, now);
    }
    return i;
}

/* The version-2 capture of main(): IMU samples added between feeds (as the data-ready
 * interrupt does), one late and one after the last feed; the CRC computed `step` records
 * per poll. Returns the polls it took to be READY. */
static uint32_t capture_v2(lhb_capture_t *c, const lhb_hw_t *hw, const lhcap_header_t *t2,
                           uint32_t step)
{
    lhb_capture_init(c, hw, storage, 1000, t2);
    int16_t raw[6] = {0};
    CHECK_EQ(lhb_capture_add_imu(c, 0, raw), -LHB_E_STATE); /* not capturing: ignored */
    lhb_capture_set_imu(c, imu_storage, NI);
    c->fixed_start_time = true;
    CHECK_EQ(lhb_capture_arm(c, 2, 0, 0, 0), LHB_OK);
    lhb_capture_poll(c, 0);
    uint32_t kept = 0;
    for (uint32_t i = 0; i < NS / 500u; i++) {
        if (i > 0) {
            lhb_capture_feed(c, samples + 500u * (i - 1u), 500u);
        }
        for (int a = 0; a < 6; a++) {
            raw[a] = (int16_t)(a % 2 ? -(int)(1000 * i + (uint32_t)a) : (int)(1000 * i) + a);
        }
        if (i == 3) {
            CHECK_EQ(lhb_capture_add_imu(c, 500u * i - 500u, raw), -LHB_E_RANGE); /* late */
            lhb_capture_imu_missed(c);
            continue;
        }
        if (lhb_capture_add_imu(c, 500u * i + 17u, raw) == LHB_OK) {
            kept++;
        }
    }
    CHECK_EQ(kept, 7);
    CHECK_EQ(c->imu.n, 7);
    CHECK_EQ(lhb_capture_add_imu(c, NS, raw), -LHB_E_STATE); /* past the last sample */
    CHECK(lhb_capture_feed(c, samples + NS - 500u, 500u));
    /* done, not yet finalising: a late data-ready interrupt's sample is still kept */
    for (int a = 0; a < 6; a++) {
        raw[a] = (int16_t)(a - 3);
    }
    CHECK_EQ(lhb_capture_add_imu(c, NS - 1u, raw), LHB_OK);
    c->finalise_step = step;
    uint32_t polls = run_poll_until_ready(c, 1);
    CHECK_EQ(c->state, LHB_STATE_READY);
    CHECK_EQ(c->imu.n, 8);
    CHECK_EQ(lhb_capture_add_imu(c, NS - 1u, raw), -LHB_E_STATE); /* ready: ignored */
    return polls;
}

int main(void)
{
    test_fill_samples(samples, NS, 3, 0, 20);
    fake_hw_t fake;
    lhb_hw_t hw = fake_hw_hooks(&fake);
    lhcap_header_t t;
    default_template(&t);
    lhb_capture_t c;
    lhb_capture_init(&c, &hw, storage, 1000, &t);
    CHECK_EQ(c.state, LHB_STATE_IDLE);

    /* argument checks */
    CHECK_EQ(lhb_capture_arm(&c, 0, 0, 0, 0), -LHB_E_ARG);
    CHECK_EQ(lhb_capture_arm(&c, 60001, 0, 0, 0), -LHB_E_ARG);
    CHECK_EQ(lhb_capture_arm(&c, 2, 60001, 0, 0), -LHB_E_ARG);
    CHECK_EQ(lhb_capture_arm(&c, 2, 1, UINT64_MAX - 999u, 0), -LHB_E_ARG);
    CHECK_EQ(lhb_capture_arm(&c, 2, 1, UINT64_MAX - 1000u, 0), LHB_OK);
    lhb_capture_abort(&c);
    CHECK_EQ(c.state, LHB_STATE_IDLE);
    /* read before ready */
    uint8_t tmp[8];
    CHECK_EQ(lhb_capture_read(&c, 0, tmp, 8), -LHB_E_STATE);

    /* arm with a 10 ms delay; host time 1e15 us */
    CHECK_EQ(lhb_capture_arm(&c, 2, 10, 1000000000000000ull, 1000), LHB_OK);
    CHECK_EQ(c.state, LHB_STATE_ARMED);
    CHECK_EQ(c.target, NS);
    CHECK_EQ(lhb_capture_arm(&c, 2, 0, 0, 1000), -LHB_E_STATE); /* busy */
    lhb_capture_poll(&c, 1005);
    CHECK_EQ(c.state, LHB_STATE_ARMED);
    CHECK_EQ(lhb_capture_delay_left(&c, 1005), 5);
    CHECK_EQ(fake.starts, 0);
    /* feed before capturing is ignored */
    CHECK(lhb_capture_feed(&c, samples, 10));
    CHECK_EQ(c.samples_done, 0);
    lhb_capture_poll(&c, 1010);
    CHECK_EQ(c.state, LHB_STATE_CAPTURING);
    CHECK_EQ(fake.starts, 1);
    CHECK_EQ(fake.requested, NS);
    CHECK_EQ(lhb_capture_arm(&c, 2, 0, 0, 1000), -LHB_E_STATE); /* busy */
    /* feed in chunks, more than wanted */
    CHECK(!lhb_capture_feed(&c, samples, 1000));
    CHECK(!lhb_capture_feed(&c, samples + 1000, 2000));
    lhb_capture_poll(&c, 1011);
    CHECK_EQ(c.state, LHB_STATE_CAPTURING); /* not done yet */
    CHECK(lhb_capture_feed(&c, samples + 3000, 5000)); /* more than needed */
    CHECK_EQ(c.samples_done, NS);
    run_poll_until_ready(&c, 1012);
    CHECK_EQ(c.state, LHB_STATE_READY);
    CHECK(fake.stops >= 1);

    t.start_time_us = 1000000000000000ull + 10000u; /* host time + delay */
    size_t n = reference_image(&t, samples, NS, want);
    CHECK_EQ(c.image_size, n);
    CHECK_EQ(c.image_crc, lhb_get_le32(want + n - 4));
    CHECK_EQ(lhb_capture_read(&c, 0, got, (uint32_t)n), LHB_OK);
    CHECK(memcmp(got, want, n) == 0);
    CHECK_EQ(lhb_crc32(got, n - 4), lhb_get_le32(got + n - 4));
    /* reads at odd offsets and lengths */
    int ok = 1;
    for (uint32_t off = 0; off < n; off += 1 + off / 3) {
        uint32_t len = (uint32_t)(n - off < 13 ? n - off : 13);
        memset(tmp, 0, sizeof tmp);
        uint8_t part[13];
        if (lhb_capture_read(&c, off, part, len) != LHB_OK || memcmp(part, want + off, len) != 0) {
            ok = 0;
        }
    }
    CHECK(ok);
    CHECK_EQ(lhb_capture_read(&c, (uint32_t)n, got, 0), LHB_OK);
    CHECK_EQ(lhb_capture_read(&c, (uint32_t)n, got, 1), -LHB_E_RANGE);
    CHECK_EQ(lhb_capture_read(&c, 0, got, (uint32_t)n + 1), -LHB_E_RANGE);
    CHECK_EQ(lhb_capture_read(&c, 0xFFFFFFFFu, got, 2), -LHB_E_RANGE);
    CHECK_EQ(lhb_capture_read(&c, 0, NULL, 2), -LHB_E_RANGE);

    /* re-arm from READY is allowed, abort goes back to IDLE */
    CHECK_EQ(lhb_capture_arm(&c, 1, 0, 0, 2000), LHB_OK);
    lhb_capture_poll(&c, 2000);
    CHECK_EQ(c.state, LHB_STATE_CAPTURING);
    lhb_capture_abort(&c);
    CHECK_EQ(c.state, LHB_STATE_IDLE);
    CHECK(lhb_capture_feed(&c, samples, 10)); /* late feed ignored */
    CHECK_EQ(lhb_capture_read(&c, 0, tmp, 1), -LHB_E_STATE);

    /* overflow: storage of 5 records stops early and sets the flag */
    lhb_capture_init(&c, &hw, storage, 5, &t);
    CHECK_EQ(lhb_capture_arm(&c, 2, 0, 0, 0), LHB_OK);
    lhb_capture_poll(&c, 0);
    CHECK(lhb_capture_feed(&c, samples, NS));
    run_poll_until_ready(&c, 1);
    CHECK_EQ(c.state, LHB_STATE_READY);
    CHECK_EQ(c.edges.n, 5);
    CHECK(c.samples_done < NS);
    CHECK_EQ(c.flags & LHCAP_FLAG_OVERFLOW, 1);
    CHECK_EQ(lhb_capture_read(&c, 0, got, c.image_size), LHB_OK);
    CHECK_EQ(lhb_get_le32(got + 12), 1);
    CHECK_EQ(lhb_get_le64(got + 32), c.samples_done);
    CHECK_EQ(lhb_crc32(got, c.image_size - 4), lhb_get_le32(got + c.image_size - 4));
    /* start time unknown when the host sent 0 */
    CHECK_EQ(lhb_get_le64(got + 24), 0);

    /* hardware start failure: back to IDLE with hw_error */
    lhb_capture_init(&c, &hw, storage, 1000, &t);
    fake.fail_start = 1;
    CHECK_EQ(lhb_capture_arm(&c, 2, 0, 0, 0), LHB_OK);
    lhb_capture_poll(&c, 0);
    CHECK_EQ(c.state, LHB_STATE_IDLE);
    CHECK_EQ(c.hw_error, 1);
    fake.fail_start = 0;

    /* fixed sample count and start time (virtual board) */
    lhb_capture_init(&c, &hw, storage, 1000, &t);
    c.fixed_samples = 100;
    c.fixed_start_time = true;
    CHECK_EQ(lhb_capture_arm(&c, 5000, 0, 42, 0), LHB_OK);
    CHECK_EQ(c.target, 100);
    lhb_capture_poll(&c, 0);
    CHECK(lhb_capture_feed(&c, samples, 100));
    run_poll_until_ready(&c, 0);
    CHECK_EQ(c.state, LHB_STATE_READY);
    n = reference_image(&t, samples, 100, want);
    CHECK_EQ(c.image_size, n);
    CHECK_EQ(lhb_capture_read(&c, 0, got, (uint32_t)n), LHB_OK);
    CHECK(memcmp(got, want, n) == 0);

    /* version 2: IMU samples added between feeds (as the data-ready interrupt does) come
     * after the edge records; the image is the version-1 one with the longer header, the
     * IMU records and the CRC over all of it */
    lhcap_header_t t2 = t;
    t2.version = LHCAP_VERSION_IMU;
    t2.imu_part = LHCAP_IMU_ICM42688P;
    t2.imu_odr_hz = 1000u;
    t2.imu_gyro_fs_dps = 2000u;
    t2.imu_accel_fs_g = 16u;
    CHECK_EQ(capture_v2(&c, &hw, &t2, LHB_FINALISE_STEP), 1);
    size_t n1 = reference_image(&t, samples, NS, v1);
    uint32_t edges = lhb_get_le32(v1 + 40);
    memcpy(want, v1, 108);
    lhb_put_le16(want + 4, 2);
    lhb_put_le16(want + 6, 128);
    lhb_put_le32(want + 108, 8);   /* IMU records */
    lhb_put_le32(want + 112, 2);   /* missed: the late one and the driver's */
    lhb_put_le16(want + 116, 1);
    lhb_put_le16(want + 118, 1000);
    lhb_put_le16(want + 120, 2000);
    lhb_put_le16(want + 122, 16);
    lhb_put_le32(want + 124, 0);
    memcpy(want + 128, v1 + 108, 8u * edges);
    size_t pos = 128 + 8u * edges;
    for (uint32_t i = 0; i < NS / 500u; i++) {
        if (i == 3) {
            continue;
        }
        lhb_put_le32(want + pos, 500u * i + 17u);
        for (int a = 0; a < 6; a++) {
            int v = a % 2 ? -(int)(1000 * i + (uint32_t)a) : (int)(1000 * i) + a;
            lhb_put_le16(want + pos + 4 + 2 * a, (uint16_t)(int16_t)v);
        }
        pos += 16;
    }
    lhb_put_le32(want + pos, NS - 1u); /* the late one */
    for (int a = 0; a < 6; a++) {
        lhb_put_le16(want + pos + 4 + 2 * a, (uint16_t)(int16_t)(a - 3));
    }
    pos += 16;
    lhb_put_le32(want + pos, lhb_crc32(want, pos));
    n = pos + 4;
    CHECK_EQ(n, n1 + 20 + 16 * 8);
    CHECK_EQ(c.image_size, n);
    CHECK_EQ(lhb_capture_read(&c, 0, got, (uint32_t)n), LHB_OK);
    CHECK(memcmp(got, want, n) == 0);
    ok = 1;
    for (uint32_t off = 0; off < n; off += 1 + off / 5) { /* odd offsets across the regions */
        uint32_t len = (uint32_t)(n - off < 7 ? n - off : 7);
        uint8_t part[7];
        if (lhb_capture_read(&c, off, part, len) != LHB_OK || memcmp(part, want + off, len) != 0) {
            ok = 0;
        }
    }
    CHECK(ok);
    /* the CRC handed from poll to poll, edge records to IMU records included, gives the
     * same image: steps of one record, a few, ending just before, at and after the last
     * edge record, and all but the last record */
    uint32_t records = edges + 8u;
    uint32_t steps[] = {1u, 3u, edges - 1u, edges, edges + 1u, records - 1u};
    for (size_t k = 0; k < sizeof steps / sizeof steps[0]; k++) {
        uint32_t polls = capture_v2(&c, &hw, &t2, steps[k]);
        CHECK_EQ(polls, (records + steps[k] - 1u) / steps[k]);
        CHECK_EQ(c.image_size, n);
        CHECK_EQ(c.image_crc, lhb_get_le32(want + n - 4));
        CHECK_EQ(lhb_capture_read(&c, 0, got, (uint32_t)n), LHB_OK);
        CHECK(memcmp(got, want, n) == 0);
    }
    /* a capture that stops early drops the IMU records past its last sample */
    int16_t raw[6] = {0};
    lhb_capture_init(&c, &hw, storage, 5, &t2);
    lhb_capture_set_imu(&c, imu_storage, NI);
    CHECK_EQ(lhb_capture_arm(&c, 2, 0, 0, 0), LHB_OK);
    lhb_capture_poll(&c, 0);
    CHECK_EQ(lhb_capture_add_imu(&c, 3000, raw), LHB_OK); /* stamped ahead of the feed */
    CHECK(lhb_capture_feed(&c, samples, NS));              /* overflows before 3000 */
    run_poll_until_ready(&c, 1);
    CHECK(c.samples_done < 3000);
    CHECK_EQ(c.imu.n, 0);
    CHECK_EQ(lhb_capture_read(&c, 0, got, c.image_size), LHB_OK);
    CHECK_EQ(lhb_get_le32(got + 108), 0);
    CHECK_EQ(c.image_size, 128 + 8 * 5 + 4);
    return check_result("capture");
}
