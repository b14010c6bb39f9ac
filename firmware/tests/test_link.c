/* The link's robustness rules: a send ring that never blocks (CTS never asserted), requests
 * deferred while it is full, stale partial frames timed out, ARM refusing to drop a capture
 * that was not downloaded unless asked, and the health fields of STATUS. */
#include <string.h>

#include "check.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "lhb/txring.h"
#include "support.h"

#define NS 3000u

static uint32_t samples[NS];
static uint32_t storage[2 * NS];
static sink_t sink;

/* received bytes waiting for the main loop (the UART receive ring) */
static uint8_t rx_q[4096];
static size_t rx_n, rx_pos;
static bool rx_pop(uint8_t *b)
{
    if (rx_pos == rx_n) {
        return false;
    }
    *b = rx_q[rx_pos++];
    return true;
}

static void queue_request(uint8_t type, uint8_t seq, const uint8_t *payload, size_t n)
{
    rx_n += lhb_frame_encode(type, seq, payload, n, NULL, 0, rx_q + rx_n, sizeof rx_q - rx_n);
}

/* tx hook putting the board's answers into the ring (as uart_tx does on the target) */
static lhb_txring_t ring;
static void ring_tx(void *ctx, const uint8_t *d, size_t n)
{
    (void)ctx;
    (void)lhb_txring_put(&ring, d, n);
}

static const uint8_t *last(uint8_t type)
{
    static lhb_frame_t f;
    CHECK(sink.count > 0);
    CHECK_EQ(sink_frame(&sink, sink.count - 1, &f), 0);
    CHECK_EQ(f.type, type);
    return f.payload;
}

static void arm(lhb_proto_t *p, uint8_t seq, uint32_t flags, size_t len, uint32_t now)
{
    uint8_t req[LHB_ARM_LEN_FLAGS];
    lhb_put_le32(req, 1);
    lhb_put_le32(req + 4, 0);
    lhb_put_le64(req + 8, 0);
    lhb_put_le32(req + 16, flags);
    send_request(p, LHB_CMD_ARM, seq, req, len, now);
}

static void capture_to_ready(lhb_proto_t *p, lhb_capture_t *cap, uint32_t now)
{
    lhb_capture_feed(cap, samples, NS);
    for (int i = 0; i < 4; i++) {
        send_request(p, LHB_CMD_STATUS, 2, NULL, 0, now);
    }
    CHECK_EQ(last(LHB_CMD_STATUS | LHB_RESP_FLAG)[0], LHB_STATE_READY);
}

static void test_ring_never_blocks(void)
{
    static volatile uint8_t buf[256];
    static volatile uint32_t dropped;
    uint8_t frame[100];
    memset(frame, 0x5A, sizeof frame);
    lhb_txring_init(&ring, buf, sizeof buf, &dropped);
    CHECK_EQ(lhb_txring_room(&ring), 255);
    CHECK(lhb_txring_put(&ring, frame, 100));
    CHECK(lhb_txring_put(&ring, frame, 100));
    CHECK(!lhb_txring_put(&ring, frame, 100)); /* nobody drains: refused whole, at once */
    CHECK_EQ(dropped, 1);
    CHECK_EQ(lhb_txring_room(&ring), 55);
    uint8_t b;
    int popped = 0;
    while (lhb_txring_pop(&ring, &b)) {
        popped++;
    }
    CHECK_EQ(popped, 200);
    CHECK(lhb_txring_put(&ring, frame, 100)); /* drained: fits again (wraps) */
}

/* CTS never asserted: the ring is never emptied. The main loop keeps running (capture
 * started and finalised), requests wait instead of answers being half written. */
static void test_cts_never_asserted(void)
{
    static volatile uint8_t buf[8192];
    static volatile uint32_t dropped;
    fake_hw_t fake;
    lhb_hw_t hw = fake_hw_hooks(&fake);
    lhcap_header_t t;
    default_template(&t);
    static lhb_capture_t cap;
    static lhb_proto_t proto;
    lhb_capture_init(&cap, &hw, storage, NS, &t);
    cap.fixed_samples = NS;
    lhb_txring_init(&ring, buf, sizeof buf, &dropped);
    lhb_proto_init(&proto, &cap, 4096, ring_tx, NULL);
    CHECK_EQ(lhb_capture_arm(&cap, 1, 5, 0, 0), LHB_OK);
    rx_n = rx_pos = 0;
    for (uint8_t s = 1; s <= 100; s++) {
        queue_request(LHB_CMD_STATUS, s, NULL, 0);
    }
    uint32_t now = 0;
    for (int step = 0; step < 1000; step++, now++) {
        lhb_link_service(&proto, &ring, rx_pop, now);
        lhb_capture_poll(&cap, now);
        if (cap.state == LHB_STATE_CAPTURING && fake.starts == 1 && cap.samples_done == 0) {
            lhb_capture_feed(&cap, samples, NS);
        }
    }
    CHECK_EQ(fake.starts, 1);                /* the delay ran out and sampling started */
    CHECK_EQ(cap.state, LHB_STATE_READY);    /* finalised although nothing was sent */
    CHECK(rx_pos < rx_n);                    /* requests deferred, not answered into a full ring */
    CHECK(lhb_txring_room(&ring) < LHB_WIRE_MAX(LHB_RESP_RAW_MAX));
    CHECK_EQ(dropped, 0);
    uint32_t answered = proto.frames_ok;
    /* CTS comes back: the ring drains, the waiting requests are answered */
    uint8_t b;
    while (lhb_txring_pop(&ring, &b)) {
    }
    lhb_link_service(&proto, &ring, rx_pop, now);
    CHECK(proto.frames_ok > answered);
}

static void test_partial_frame_timeout(lhb_proto_t *p)
{
    uint8_t wire[64];
    size_t n = lhb_frame_encode(LHB_CMD_STATUS, 9, NULL, 0, NULL, 0, wire, sizeof wire);
    int before = sink.count;
    lhb_proto_rx(p, wire, 3, 1000); /* half a frame, then silence */
    lhb_proto_rx(p, wire, n, 1000 + LHB_FRAME_TIMEOUT_MS + 1);
    CHECK_EQ(p->frames_timed_out, 1);
    CHECK_EQ(sink.count, before + 1); /* the whole new frame answered, no FRAMING error */
    CHECK_EQ(sink_frame(&sink, sink.count - 1, &(lhb_frame_t){0}), 0);
    last(LHB_CMD_STATUS | LHB_RESP_FLAG);
    CHECK_EQ(lhb_get_le32(last(LHB_CMD_STATUS | LHB_RESP_FLAG) + 76), 1);
    /* within the timeout the frame is still joined (slow host, bytes in pieces) */
    lhb_proto_rx(p, wire, 3, 2000);
    lhb_proto_rx(p, wire + 3, n - 3, 2000 + LHB_FRAME_TIMEOUT_MS);
    CHECK_EQ(p->frames_timed_out, 1);
    CHECK_EQ(sink.count, before + 2);
    last(LHB_CMD_STATUS | LHB_RESP_FLAG);
}

static void test_arm_keeps_undownloaded(void)
{
    fake_hw_t fake;
    lhb_hw_t hw = fake_hw_hooks(&fake);
    lhcap_header_t t;
    default_template(&t);
    static lhb_capture_t cap;
    static lhb_proto_t proto;
    lhb_capture_init(&cap, &hw, storage, NS, &t);
    cap.fixed_samples = NS;
    sink_init(&sink);
    lhb_proto_init(&proto, &cap, 1000, sink_tx, &sink);
    lhb_diag_t diag = {0};
    diag.selftest = LHB_ST_SDRAM_RETENTION;
    diag.hse_khz = 8001;
    diag.fault_pc = 0x08001234u;
    diag.dma_overruns = 2;
    diag.isr_cycles_max = 51000;
    diag.isr_cycles_budget = 184320;
    proto.diag = &diag;

    arm(&proto, 1, 0, LHB_ARM_LEN, 0);
    last(LHB_CMD_ARM | LHB_RESP_FLAG);
    capture_to_ready(&proto, &cap, 1);
    const uint8_t *s = last(LHB_CMD_STATUS | LHB_RESP_FLAG);
    uint32_t blocks = lhb_get_le32(s + 36);
    CHECK(blocks > 2);
    CHECK_EQ(lhb_get_le32(s + 84), blocks); /* nothing read yet */
    CHECK_EQ(lhb_get_le32(s + 40), LHB_ST_SDRAM_RETENTION);
    CHECK_EQ(lhb_get_le32(s + 44), 8001);
    CHECK_EQ(lhb_get_le32(s + 48), 0x08001234u);
    CHECK_EQ(lhb_get_le32(s + 64), 2);
    CHECK_EQ(lhb_get_le32(s + 68), 51000);
    CHECK_EQ(lhb_get_le32(s + 72), 184320);

    /* ARM in READY with the capture unread: refused, the capture stays */
    arm(&proto, 3, 0, LHB_ARM_LEN, 2);
    CHECK_EQ(last(LHB_RESP_ERROR)[0], LHB_E_UNREAD);
    CHECK_EQ(cap.state, LHB_STATE_READY);
    arm(&proto, 4, 0, LHB_ARM_LEN_FLAGS, 2); /* flags present but no discard bit */
    CHECK_EQ(last(LHB_RESP_ERROR)[0], LHB_E_UNREAD);
    arm(&proto, 4, 0, 18, 2);
    CHECK_EQ(last(LHB_RESP_ERROR)[0], LHB_E_LENGTH);

    /* read every block but the last (twice the first): still unread */
    uint8_t idx[4];
    for (uint32_t b = 0; b + 1u < blocks; b++) {
        lhb_put_le32(idx, b);
        send_request(&proto, LHB_CMD_READ, 5, idx, 4, 3);
    }
    lhb_put_le32(idx, 0);
    send_request(&proto, LHB_CMD_READ, 5, idx, 4, 3);
    CHECK_EQ(lhb_proto_blocks_unread(&proto), 1);
    arm(&proto, 6, 0, LHB_ARM_LEN, 4);
    CHECK_EQ(last(LHB_RESP_ERROR)[0], LHB_E_UNREAD);
    lhb_put_le32(idx, blocks - 1u);
    send_request(&proto, LHB_CMD_READ, 7, idx, 4, 4);
    CHECK_EQ(lhb_proto_blocks_unread(&proto), 0);
    /* downloaded: a plain ARM is accepted again */
    arm(&proto, 8, 0, LHB_ARM_LEN, 5);
    CHECK_EQ(last(LHB_CMD_ARM | LHB_RESP_FLAG)[0], LHB_STATE_CAPTURING);
    capture_to_ready(&proto, &cap, 6);
    CHECK_EQ(lhb_proto_blocks_unread(&proto), blocks);
    /* the discard flag drops the unread capture on purpose */
    arm(&proto, 9, LHB_ARM_DISCARD, LHB_ARM_LEN_FLAGS, 7);
    CHECK_EQ(last(LHB_CMD_ARM | LHB_RESP_FLAG)[0], LHB_STATE_CAPTURING);
    CHECK_EQ(lhb_proto_blocks_unread(&proto), 0);

    test_partial_frame_timeout(&proto);
}

int main(void)
{
    test_fill_samples(samples, NS, 5, 0x0F, 8);
    test_ring_never_blocks();
    test_cts_never_asserted();
    test_arm_keeps_undownloaded();
    return check_result("link");
}
