#include "lhb/proto.h"

#include <string.h>

#include "lhb/endian.h"
#include "lhb/errors.h"
#include "lhb/frame.h"

void lhb_proto_init(lhb_proto_t *p, lhb_capture_t *cap, uint32_t block_size, lhb_tx_fn tx,
                    void *tx_ctx)
{
    memset(p, 0, sizeof *p);
    p->cap = cap;
    if (block_size == 0u || block_size > LHB_BLOCK_SIZE_MAX) {
        block_size = LHB_BLOCK_SIZE_MAX;
    }
    p->block_size = block_size;
    p->max_records = cap->edges.cap;
    p->tx = tx;
    p->tx_ctx = tx_ctx;
    lhb_cobs_dec_init(&p->dec, p->rx_raw, sizeof p->rx_raw);
}

static void send(lhb_proto_t *p, uint8_t type, uint8_t seq, const uint8_t *p1, size_t n1,
                 const uint8_t *p2, size_t n2)
{
    size_t w = lhb_frame_encode(type, seq, p1, n1, p2, n2, p->wire, sizeof p->wire);
    if (w != 0u && p->tx != NULL) {
        p->tx(p->tx_ctx, p->wire, w);
    }
}

static void send_error(lhb_proto_t *p, uint8_t seq, uint8_t cmd, int code)
{
    uint8_t e[LHB_ERROR_LEN];
    e[0] = (uint8_t)code;
    e[1] = cmd;
    e[2] = (uint8_t)p->cap->state;
    e[3] = 0;
    send(p, LHB_RESP_ERROR, seq, e, sizeof e, NULL, 0);
}

static uint32_t block_count(const lhb_proto_t *p)
{
    const lhb_capture_t *c = p->cap;
    if (c->state != LHB_STATE_READY) {
        return 0;
    }
    return c->image_size / p->block_size + (c->image_size % p->block_size != 0u ? 1u : 0u);
}

static void send_status(lhb_proto_t *p, uint8_t type, uint8_t seq, uint32_t now_ms)
{
    const lhb_capture_t *c = p->cap;
    uint8_t s[LHB_STATUS_LEN];
    uint32_t state = c->state;
    bool ready = state == LHB_STATE_READY;
    s[0] = (uint8_t)state;
    s[1] = (uint8_t)(c->hw_error != 0u ? 1u : 0u);
    lhb_put_le16(s + 2, (uint16_t)((ready ? c->flags : 0u) |
                                   (c->edges.overflow ? LHCAP_FLAG_OVERFLOW : 0u)));
    lhb_put_le32(s + 4, c->duration_ms);
    lhb_put_le32(s + 8, lhb_capture_delay_left(c, now_ms));
    lhb_put_le32(s + 12, state == LHB_STATE_IDLE ? 0u : c->samples_done);
    lhb_put_le32(s + 16, state == LHB_STATE_IDLE ? 0u : c->target);
    lhb_put_le32(s + 20, state == LHB_STATE_IDLE ? 0u : c->edges.n);
    lhb_put_le32(s + 24, ready ? c->image_size : 0u);
    lhb_put_le32(s + 28, ready ? c->image_crc : 0u);
    lhb_put_le32(s + 32, p->block_size);
    lhb_put_le32(s + 36, block_count(p));
    /* health (docs/protocol.md): self-tests, fault record, run-time counters */
    static const lhb_diag_t none = {0};
    const lhb_diag_t *d = p->diag != NULL ? p->diag : &none;
    const uint32_t health[] = {
        d->selftest,     d->hse_khz,        d->fault_pc,          d->fault_lr,
        d->fault_cfsr,   d->fault_hfsr,     d->dma_overruns,      d->isr_cycles_max,
        d->isr_cycles_budget, p->frames_timed_out, d->tx_dropped, lhb_proto_blocks_unread(p),
        d->reset_cause,
    };
    _Static_assert(LHB_STATUS_LEN_V1 + 4u * (sizeof health / sizeof health[0]) ==
                       LHB_STATUS_LEN_HEALTH, "STATUS layout");
    for (size_t k = 0; k < sizeof health / sizeof health[0]; k++) {
        lhb_put_le32(s + LHB_STATUS_LEN_V1 + 4u * k, health[k]);
    }
    /* the IMU: part found at boot (in version-2 captures), records and misses so far */
    bool imu = c->tmpl.version == LHCAP_VERSION_IMU;
    lhb_put_le32(s + LHB_STATUS_LEN_HEALTH, imu ? c->tmpl.imu_part : 0u);
    lhb_put_le32(s + LHB_STATUS_LEN_HEALTH + 4, imu && state != LHB_STATE_IDLE ? c->imu.n : 0u);
    lhb_put_le32(s + LHB_STATUS_LEN_HEALTH + 8,
                 imu && state != LHB_STATE_IDLE ? c->imu.missed : 0u);
    send(p, type, seq, s, sizeof s, NULL, 0);
}

uint32_t lhb_proto_blocks_unread(const lhb_proto_t *p)
{
    uint32_t count = block_count(p);
    uint32_t tracked = count < LHB_READ_MAP_BITS ? count : LHB_READ_MAP_BITS;
    return tracked - p->blocks_read;
}

static void forget_reads(lhb_proto_t *p)
{
    memset(p->read_map, 0, sizeof p->read_map);
    p->blocks_read = 0;
}

static void handle_info(lhb_proto_t *p, uint8_t seq)
{
    const lhb_capture_t *c = p->cap;
    uint8_t s[LHB_INFO_LEN];
    lhb_put_le16(s + 0, (uint16_t)LHB_PROTOCOL_VERSION);
    lhb_put_le16(s + 2, (uint16_t)p->block_size);
    lhb_put_le32(s + 4, c->tmpl.fw_version);
    lhb_put_le32(s + 8, c->tmpl.board_id);
    lhb_put_le32(s + 12, c->tmpl.sample_rate);
    lhb_put_le32(s + 16, LHB_MAX_DURATION_MS);
    lhb_put_le32(s + 20, LHB_MAX_DELAY_MS);
    lhb_put_le32(s + 24, p->max_records);
    send(p, LHB_CMD_INFO | LHB_RESP_FLAG, seq, s, sizeof s, NULL, 0);
}

static void handle_read(lhb_proto_t *p, uint8_t seq, uint32_t index)
{
    const lhb_capture_t *c = p->cap;
    if (c->state != LHB_STATE_READY) {
        send_error(p, seq, LHB_CMD_READ, LHB_E_STATE);
        return;
    }
    uint32_t count = block_count(p);
    if (index >= count) {
        send_error(p, seq, LHB_CMD_READ, LHB_E_RANGE);
        return;
    }
    uint32_t offset = index * p->block_size;
    uint32_t len = c->image_size - offset;
    if (len > p->block_size) {
        len = p->block_size;
    }
    lhb_put_le32(p->payload, index);
    if (lhb_capture_read(c, offset, p->payload + 4, len) != LHB_OK) {
        send_error(p, seq, LHB_CMD_READ, LHB_E_RANGE);
        return;
    }
    send(p, LHB_CMD_READ | LHB_RESP_FLAG, seq, p->payload, 4u + len, NULL, 0);
    p->blocks_sent++;
    if (index < LHB_READ_MAP_BITS && (p->read_map[index >> 3] & (1u << (index & 7u))) == 0u) {
        p->read_map[index >> 3] |= (uint8_t)(1u << (index & 7u));
        p->blocks_read++;
    }
}

/* Exact payload length each command takes. */
static int expected_len(uint8_t type)
{
    switch (type) {
    case LHB_CMD_INFO:
    case LHB_CMD_STATUS:
    case LHB_CMD_ABORT:
        return 0;
    case LHB_CMD_ARM:
        return (int)LHB_ARM_LEN; /* or LHB_ARM_LEN_FLAGS: see lhb_proto_handle */
    case LHB_CMD_READ:
        return (int)LHB_READ_REQ_LEN;
    default:
        return -1;
    }
}

void lhb_proto_handle(lhb_proto_t *p, const uint8_t *raw, size_t n, uint32_t now_ms)
{
    lhb_frame_t f;
    int r = lhb_frame_parse(raw, n, &f);
    if (r != LHB_OK) {
        p->frames_bad++;
        /* after a CRC error nothing in the frame can be trusted: seq 0, cmd 0 */
        bool trusted = r == -LHB_E_LENGTH;
        send_error(p, trusted ? raw[1] : 0u, trusted ? raw[0] : 0u, -r);
        return;
    }
    if ((f.type & LHB_RESP_FLAG) != 0u) {
        p->frames_bad++;
        return; /* a response looped back: never answer it (no ping-pong) */
    }
    int want = expected_len(f.type);
    if (want < 0) {
        p->frames_bad++;
        send_error(p, f.seq, f.type, LHB_E_UNKNOWN_CMD);
        return;
    }
    bool arm_flags = f.type == LHB_CMD_ARM && f.len == LHB_ARM_LEN_FLAGS;
    if ((int)f.len != want && !arm_flags) {
        p->frames_bad++;
        send_error(p, f.seq, f.type, LHB_E_LENGTH);
        return;
    }
    p->frames_ok++;
    lhb_capture_t *c = p->cap;
    switch (f.type) {
    case LHB_CMD_INFO:
        handle_info(p, f.seq);
        break;
    case LHB_CMD_STATUS:
        lhb_capture_poll(c, now_ms);
        send_status(p, LHB_CMD_STATUS | LHB_RESP_FLAG, f.seq, now_ms);
        break;
    case LHB_CMD_ARM: {
        uint32_t duration = lhb_get_le32(f.payload);
        uint32_t delay = lhb_get_le32(f.payload + 4);
        uint64_t host_us = lhb_get_le64(f.payload + 8);
        uint32_t flags = arm_flags ? lhb_get_le32(f.payload + 16) : 0u;
        if (c->state == LHB_STATE_READY && lhb_proto_blocks_unread(p) != 0u &&
            (flags & LHB_ARM_DISCARD) == 0u) {
            send_error(p, f.seq, f.type, LHB_E_UNREAD); /* never drop a capture unasked */
            break;
        }
        r = lhb_capture_arm(c, duration, delay, host_us, now_ms);
        if (r != LHB_OK) {
            send_error(p, f.seq, f.type, -r);
            break;
        }
        forget_reads(p);
        lhb_capture_poll(c, now_ms); /* a zero delay starts at once */
        send_status(p, LHB_CMD_ARM | LHB_RESP_FLAG, f.seq, now_ms);
        break;
    }
    case LHB_CMD_ABORT:
        lhb_capture_abort(c);
        forget_reads(p);
        send_status(p, LHB_CMD_ABORT | LHB_RESP_FLAG, f.seq, now_ms);
        break;
    case LHB_CMD_READ:
        handle_read(p, f.seq, lhb_get_le32(f.payload));
        break;
    default:
        break;
    }
}

void lhb_proto_rx(lhb_proto_t *p, const uint8_t *data, size_t n, uint32_t now_ms)
{
    for (size_t i = 0; i < n; i++) {
        bool partial = p->dec.n != 0u || p->dec.code != 0u || p->dec.err != 0u;
        if (partial && now_ms - p->last_rx_ms > LHB_FRAME_TIMEOUT_MS) {
            lhb_cobs_dec_init(&p->dec, p->rx_raw, sizeof p->rx_raw); /* stale: drop it */
            p->frames_timed_out++;
        }
        p->last_rx_ms = now_ms;
        long r = lhb_cobs_dec_push(&p->dec, data[i]);
        if (r > 0) {
            lhb_proto_handle(p, p->rx_raw, (size_t)(r - 1), now_ms);
        } else if (r < 0) {
            p->frames_bad++;
            send_error(p, 0u, 0u, (int)-r);
        }
    }
}
