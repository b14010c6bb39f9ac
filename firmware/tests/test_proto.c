#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "support.h"

#define NS 6000u /* 3 ms */

static uint32_t samples[NS];
static uint32_t storage[2 * NS];
static uint8_t want[108 + 8 * NS + 4];
static uint8_t got[108 + 8 * NS + 4];
static sink_t sink;
static lhb_proto_t proto;

/* Checks that the last response is an ERROR with `code` (and cmd/seq when given). */
static void expect_error(int code, int cmd, int seq)
{
    lhb_frame_t f;
    CHECK(sink.count > 0);
    CHECK_EQ(sink_frame(&sink, sink.count - 1, &f), 0);
    CHECK_EQ(f.type, LHB_RESP_ERROR);
    CHECK_EQ(f.len, LHB_ERROR_LEN);
    CHECK_EQ(f.payload[0], code);
    if (cmd >= 0) {
        CHECK_EQ(f.payload[1], cmd);
    }
    if (seq >= 0) {
        CHECK_EQ(f.seq, seq);
    }
}

static const uint8_t *last_ok(uint8_t type, uint8_t seq, uint16_t len)
{
    static lhb_frame_t f;
    CHECK(sink.count > 0);
    CHECK_EQ(sink_frame(&sink, sink.count - 1, &f), 0);
    CHECK_EQ(f.type, type | LHB_RESP_FLAG);
    CHECK_EQ(f.seq, seq);
    CHECK_EQ(f.len, len);
    return f.payload;
}

static void arm_req(uint8_t *p, uint32_t dur, uint32_t delay, uint64_t host)
{
    lhb_put_le32(p, dur);
    lhb_put_le32(p + 4, delay);
    lhb_put_le64(p + 8, host);
}

int main(void)
{
    test_fill_samples(samples, NS, 11, 0xF0, 10);
    fake_hw_t fake;
    lhb_hw_t hw = fake_hw_hooks(&fake);
    lhcap_header_t t;
    default_template(&t);
    lhb_capture_t cap;
    lhb_capture_init(&cap, &hw, storage, NS, &t);
    sink_init(&sink);
    lhb_proto_init(&proto, &cap, 1000, sink_tx, &sink);
    uint8_t req[64];
    const uint8_t *p;

    /* INFO */
    send_request(&proto, LHB_CMD_INFO, 1, NULL, 0, 0);
    p = last_ok(LHB_CMD_INFO, 1, LHB_INFO_LEN);
    CHECK_EQ(lhb_get_le16(p), LHB_PROTOCOL_VERSION);
    CHECK_EQ(lhb_get_le16(p + 2), 1000);
    CHECK_EQ(lhb_get_le32(p + 4), 0x000100);
    CHECK_EQ(lhb_get_le32(p + 8), 0x12345678);
    CHECK_EQ(lhb_get_le32(p + 12), 2000000);
    CHECK_EQ(lhb_get_le32(p + 16), LHB_MAX_DURATION_MS);
    CHECK_EQ(lhb_get_le32(p + 20), LHB_MAX_DELAY_MS);
    CHECK_EQ(lhb_get_le32(p + 24), NS);
    /* INFO with a payload: LENGTH error echoing seq and cmd */
    send_request(&proto, LHB_CMD_INFO, 2, req, 1, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_INFO, 2);

    /* STATUS in IDLE */
    send_request(&proto, LHB_CMD_STATUS, 3, NULL, 0, 0);
    p = last_ok(LHB_CMD_STATUS, 3, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_IDLE);
    CHECK_EQ(lhb_get_le32(p + 24), 0);
    CHECK_EQ(lhb_get_le32(p + 32), 1000);
    CHECK_EQ(lhb_get_le32(p + 36), 0);
    CHECK_EQ(lhb_get_le32(p + 92), 0); /* a version-1 capture: no IMU */
    CHECK_EQ(lhb_get_le32(p + 96), 0);
    CHECK_EQ(lhb_get_le32(p + 100), 0);
    send_request(&proto, LHB_CMD_STATUS, 4, req, 3, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_STATUS, 4);

    /* READ in IDLE */
    lhb_put_le32(req, 0);
    send_request(&proto, LHB_CMD_READ, 5, req, 4, 0);
    expect_error(LHB_E_STATE, LHB_CMD_READ, 5);
    send_request(&proto, LHB_CMD_READ, 6, req, 3, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_READ, 6);
    send_request(&proto, LHB_CMD_READ, 6, req, 5, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_READ, 6);

    /* ARM: wrong length, bad arguments, then good with a delay */
    arm_req(req, 3, 0, 0);
    send_request(&proto, LHB_CMD_ARM, 7, req, 15, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_ARM, 7);
    send_request(&proto, LHB_CMD_ARM, 7, req, 17, 0);
    expect_error(LHB_E_LENGTH, LHB_CMD_ARM, 7);
    arm_req(req, 0, 0, 0);
    send_request(&proto, LHB_CMD_ARM, 8, req, 16, 0);
    expect_error(LHB_E_ARG, LHB_CMD_ARM, 8);
    arm_req(req, 0xFFFFFFFFu, 0, 0);
    send_request(&proto, LHB_CMD_ARM, 8, req, 16, 0);
    expect_error(LHB_E_ARG, LHB_CMD_ARM, 8);
    arm_req(req, 3, 0xFFFFFFFFu, 0);
    send_request(&proto, LHB_CMD_ARM, 8, req, 16, 0);
    expect_error(LHB_E_ARG, LHB_CMD_ARM, 8);
    arm_req(req, 3, 20, 5000000);
    send_request(&proto, LHB_CMD_ARM, 9, req, 16, 100);
    p = last_ok(LHB_CMD_ARM, 9, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_ARMED);
    CHECK_EQ(lhb_get_le32(p + 4), 3);
    CHECK_EQ(lhb_get_le32(p + 8), 20);
    CHECK_EQ(lhb_get_le32(p + 16), NS);
    send_request(&proto, LHB_CMD_ARM, 10, req, 16, 101);
    expect_error(LHB_E_STATE, LHB_CMD_ARM, 10);
    CHECK_EQ(sink.frames[sink.count - 1][0], LHB_RESP_ERROR);
    /* STATUS after the delay: capturing */
    send_request(&proto, LHB_CMD_STATUS, 11, NULL, 0, 120);
    p = last_ok(LHB_CMD_STATUS, 11, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_CAPTURING);
    CHECK_EQ(fake.starts, 1);
    lhb_put_le32(req, 0);
    send_request(&proto, LHB_CMD_READ, 12, req, 4, 120);
    expect_error(LHB_E_STATE, LHB_CMD_READ, 12);
    lhb_capture_feed(&cap, samples, 2500);
    send_request(&proto, LHB_CMD_STATUS, 13, NULL, 0, 121);
    p = last_ok(LHB_CMD_STATUS, 13, LHB_STATUS_LEN);
    CHECK_EQ(lhb_get_le32(p + 12), 2500);
    lhb_capture_feed(&cap, samples + 2500, NS - 2500);
    for (int i = 0; i < 5; i++) {
        send_request(&proto, LHB_CMD_STATUS, 14, NULL, 0, 122);
    }
    p = last_ok(LHB_CMD_STATUS, 14, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_READY);
    t.start_time_us = 5000000 + 20000;
    size_t n = reference_image(&t, samples, NS, want);
    CHECK_EQ(lhb_get_le32(p + 24), n);
    CHECK_EQ(lhb_get_le32(p + 28), lhb_get_le32(want + n - 4));
    uint32_t blocks = lhb_get_le32(p + 36);
    CHECK_EQ(blocks, (n + 999) / 1000);

    /* READ every block, in reverse order */
    for (uint32_t b = blocks; b-- > 0;) {
        lhb_put_le32(req, b);
        send_request(&proto, LHB_CMD_READ, (uint8_t)b, req, 4, 130);
        uint32_t len = (uint32_t)(b + 1 == blocks ? n - 1000u * b : 1000u);
        p = last_ok(LHB_CMD_READ, (uint8_t)b, (uint16_t)(4 + len));
        CHECK_EQ(lhb_get_le32(p), b);
        memcpy(got + 1000u * b, p + 4, len);
        sink.count = 0; /* keep the sink small */
    }
    CHECK(memcmp(got, want, n) == 0);
    CHECK_EQ(proto.blocks_sent, blocks);
    lhb_put_le32(req, blocks);
    send_request(&proto, LHB_CMD_READ, 40, req, 4, 130);
    expect_error(LHB_E_RANGE, LHB_CMD_READ, 40);
    lhb_put_le32(req, 0xFFFFFFFFu);
    send_request(&proto, LHB_CMD_READ, 41, req, 4, 130);
    expect_error(LHB_E_RANGE, LHB_CMD_READ, 41);

    /* unknown command, and a response type which must be ignored */
    send_request(&proto, 0x42, 50, NULL, 0, 130);
    expect_error(LHB_E_UNKNOWN_CMD, 0x42, 50);
    send_request(&proto, 0x00, 51, NULL, 0, 130);
    expect_error(LHB_E_UNKNOWN_CMD, 0x00, 51);
    int before = sink.count;
    send_request(&proto, LHB_CMD_STATUS | LHB_RESP_FLAG, 52, NULL, 0, 130);
    send_request(&proto, LHB_RESP_ERROR, 53, req, 4, 130);
    CHECK_EQ(sink.count, before);

    /* malformed frames */
    {
        uint8_t wire[128];
        size_t wl = lhb_frame_encode(LHB_CMD_STATUS, 60, NULL, 0, NULL, 0, wire, sizeof wire);
        /* a flipped bit in the CRC: error with seq 0 */
        uint8_t bad[128];
        memcpy(bad, wire, wl);
        bad[wl - 2] ^= 0x10;
        if (bad[wl - 2] == 0) {
            bad[wl - 2] = 0x11;
        }
        lhb_proto_rx(&proto, bad, wl, 130);
        expect_error(LHB_E_CRC, 0, 0);
        /* a dropped byte: framing or CRC error, never a reply to seq 60 */
        memcpy(bad, wire, 3);
        memcpy(bad + 3, wire + 4, wl - 4);
        lhb_proto_rx(&proto, bad, wl - 1, 130);
        lhb_frame_t f;
        CHECK_EQ(sink_frame(&sink, sink.count - 1, &f), 0);
        CHECK_EQ(f.type, LHB_RESP_ERROR);
        /* too short to be a frame */
        const uint8_t shortf[] = {0x03, 0x01, 0x02, 0x00};
        lhb_proto_rx(&proto, shortf, sizeof shortf, 130);
        expect_error(LHB_E_FRAMING, 0, 0);
        /* oversized frame: TOO_LONG once, then the board still answers */
        uint8_t big[300];
        memset(big, 0x41, sizeof big);
        big[0] = 0xFF;
        big[255] = 0x2C;
        big[sizeof big - 1] = 0;
        sink.count = 0;
        lhb_proto_rx(&proto, big, sizeof big, 130);
        CHECK_EQ(sink.count, 1);
        expect_error(LHB_E_TOO_LONG, 0, 0);
        /* a frame of just under the limit with a valid CRC but a wrong length field */
        uint8_t raw[LHB_REQ_RAW_MAX];
        memset(raw, 0x01, sizeof raw);
        raw[0] = LHB_CMD_STATUS;
        raw[1] = 61;
        lhb_put_le16(raw + 2, 1000);
        lhb_put_le32(raw + sizeof raw - 4, lhb_crc32(raw, sizeof raw - 4));
        uint8_t enc[LHB_WIRE_MAX(LHB_REQ_RAW_MAX)];
        size_t el = lhb_cobs_encode(raw, sizeof raw, enc, sizeof enc);
        enc[el++] = 0;
        lhb_proto_rx(&proto, enc, el, 130);
        expect_error(LHB_E_LENGTH, LHB_CMD_STATUS, 61);
        /* empty frames are ignored */
        before = sink.count;
        const uint8_t zeros[4] = {0};
        lhb_proto_rx(&proto, zeros, sizeof zeros, 130);
        CHECK_EQ(sink.count, before);
        /* garbage then a good request in the same buffer */
        uint8_t mix[160];
        memset(mix, 0x37, 20);
        mix[20] = 0;
        memcpy(mix + 21, wire, wl);
        sink.count = 0;
        lhb_proto_rx(&proto, mix, 21 + wl, 130);
        CHECK_EQ(sink.count, 2);
        p = last_ok(LHB_CMD_STATUS, 60, LHB_STATUS_LEN);
        CHECK_EQ(p[0], LHB_STATE_READY);
    }

    /* ABORT: back to IDLE, reads refused; ABORT in IDLE is fine too */
    send_request(&proto, LHB_CMD_ABORT, 70, req, 1, 130);
    expect_error(LHB_E_LENGTH, LHB_CMD_ABORT, 70);
    send_request(&proto, LHB_CMD_ABORT, 71, NULL, 0, 130);
    p = last_ok(LHB_CMD_ABORT, 71, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_IDLE);
    send_request(&proto, LHB_CMD_ABORT, 72, NULL, 0, 130);
    p = last_ok(LHB_CMD_ABORT, 72, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_IDLE);
    lhb_put_le32(req, 0);
    send_request(&proto, LHB_CMD_READ, 73, req, 4, 130);
    expect_error(LHB_E_STATE, LHB_CMD_READ, 73);
    /* ARM with no delay starts at once; ABORT while capturing stops the hardware */
    int stops = fake.stops;
    arm_req(req, 1, 0, 0);
    send_request(&proto, LHB_CMD_ARM, 74, req, 16, 200);
    p = last_ok(LHB_CMD_ARM, 74, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_CAPTURING);
    send_request(&proto, LHB_CMD_ABORT, 75, NULL, 0, 201);
    p = last_ok(LHB_CMD_ABORT, 75, LHB_STATUS_LEN);
    CHECK_EQ(p[0], LHB_STATE_IDLE);
    CHECK(fake.stops > stops);
    CHECK_EQ(sink.bad, 0);

    /* block sizes at the edges: the image as one block, an exact multiple, 1-byte blocks */
    {
        static uint32_t st2[2 * 64];
        lhb_capture_t c2;
        lhb_capture_init(&c2, &hw, st2, 64, &t);
        CHECK_EQ(lhb_capture_arm(&c2, 1, 0, 0, 0), LHB_OK);
        lhb_capture_poll(&c2, 0);
        lhb_capture_feed(&c2, samples, 2000);
        for (int i = 0; i < 4; i++) {
            lhb_capture_poll(&c2, 0);
        }
        CHECK_EQ(c2.state, LHB_STATE_READY);
        uint32_t size = c2.image_size;
        CHECK_EQ(size % 4u, 0u);
        const uint32_t sizes[] = {size, size / 4u, 1u, LHB_BLOCK_SIZE_MAX, 0u, 99999u};
        for (size_t k = 0; k < sizeof sizes / sizeof sizes[0]; k++) {
            lhb_proto_t p2;
            sink_init(&sink);
            lhb_proto_init(&p2, &c2, sizes[k], sink_tx, &sink);
            uint32_t bs = p2.block_size;
            CHECK(bs >= 1u && bs <= LHB_BLOCK_SIZE_MAX);
            send_request(&p2, LHB_CMD_STATUS, 1, NULL, 0, 0);
            p = last_ok(LHB_CMD_STATUS, 1, LHB_STATUS_LEN);
            uint32_t count = lhb_get_le32(p + 36);
            CHECK_EQ(count, (size + bs - 1u) / bs);
            lhb_put_le32(req, count - 1u);
            send_request(&p2, LHB_CMD_READ, 2, req, 4, 0);
            p = last_ok(LHB_CMD_READ, 2, (uint16_t)(4u + size - (count - 1u) * bs));
            lhb_put_le32(req, count);
            send_request(&p2, LHB_CMD_READ, 3, req, 4, 0);
            expect_error(LHB_E_RANGE, LHB_CMD_READ, 3);
        }
    }
    return check_result("proto");
}
