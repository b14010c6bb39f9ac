/* Fuzz target for the board's request parser (COBS decoder, frame parser, command handler).
 * Built with libFuzzer (fuzz/run_fuzz.sh) or as a corpus replayer for ctest and, under
 * ASan/UBSan, for firmware/ci.sh.
 *
 * Input byte 0: bit 0 = a finished capture is ready, bit 1 = the capture is running, bit 2 =
 * frame mode; it also sets the block size (64 + byte 0). The rest is
 * - raw mode: link bytes fed to the board as received;
 * - frame mode: records `ctl type seq n payload[n]`, each sent as a frame with a valid CRC
 *   (so the fuzzer reaches the command handlers instead of stopping at the CRC check).
 *   ctl bits 0-1: time gap before the frame (0, 1, 60, 150 ms: the partial-frame timeout is
 *   100 ms), bit 2: length field off by one, bit 3: CRC broken, bit 4: only the first half
 *   of the frame is sent, bit 5: 500 samples arrive (while capturing).
 * Every byte the board sends back must decode to a valid answer frame: anything else
 * aborts. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lhb/capture.h"
#include "lhb/cobs.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/frame.h"
#include "lhb/proto.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

static uint8_t out_buf[LHB_RESP_RAW_MAX + 16];
static lhb_cobs_dec_t out_dec;

static void check_tx(void *ctx, const uint8_t *d, size_t n)
{
    (void)ctx;
    for (size_t i = 0; i < n; i++) {
        long r = lhb_cobs_dec_push(&out_dec, d[i]);
        if (r < 0) {
            abort(); /* the board produced an undecodable frame */
        }
        if (r > 0) {
            lhb_frame_t f;
            if (lhb_frame_parse(out_buf, (size_t)(r - 1), &f) != 0 ||
                (f.type & LHB_RESP_FLAG) == 0u) {
                abort();
            }
        }
    }
}

static int hw_start(void *ctx, uint32_t n)
{
    (void)ctx;
    (void)n;
    return 0;
}

static void hw_stop(void *ctx)
{
    (void)ctx;
}

static lhb_capture_t cap;
static lhb_proto_t proto;
static uint32_t samples[3000];

/* Frame mode: wraps each record into a frame with a computed CRC. */
static void feed_frames(const uint8_t *d, size_t size, uint32_t now)
{
    static const uint32_t gaps[4] = {0u, 1u, 60u, 150u};
    size_t i = 0;
    while (i + 4u <= size) {
        uint8_t ctl = d[i];
        uint8_t raw[LHB_REQ_RAW_MAX + 8];
        size_t n = d[i + 3];
        i += 4u;
        if (n > size - i) {
            n = size - i;
        }
        if (n > LHB_REQ_PAYLOAD_MAX + 4u) {
            n = LHB_REQ_PAYLOAD_MAX + 4u; /* a little over the limit: TOO_LONG stays reachable */
        }
        raw[0] = d[i - 3u];
        raw[1] = d[i - 2u];
        lhb_put_le16(raw + 2, (uint16_t)(n + ((ctl & 4u) != 0u ? 1u : 0u)));
        memcpy(raw + 4, d + i, n);
        i += n;
        uint32_t crc = lhb_crc32(raw, 4u + n) ^ ((ctl & 8u) != 0u ? 1u : 0u);
        lhb_put_le32(raw + 4u + n, crc);
        uint8_t wire[LHB_WIRE_MAX(sizeof raw)];
        size_t w = lhb_cobs_encode(raw, 8u + n, wire, sizeof wire);
        wire[w++] = 0u;
        now += gaps[ctl & 3u];
        if ((ctl & 16u) != 0u) {
            w = w / 2u;
        }
        lhb_proto_rx(&proto, wire, w, now);
        if ((ctl & 32u) != 0u) {
            lhb_capture_feed(&cap, samples, 500);
        }
        lhb_capture_poll(&cap, now);
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint32_t storage[2 * 256];
    if (size == 0) {
        return 0;
    }
    lhb_hw_t hw = {hw_start, hw_stop, NULL};
    lhcap_header_t t;
    memset(&t, 0, sizeof t);
    t.sample_rate = 2000000u;
    t.board_id = 1;
    lhb_capture_init(&cap, &hw, storage, 256, &t);
    lhb_proto_init(&proto, &cap, 64u + data[0], check_tx, NULL);
    lhb_cobs_dec_init(&out_dec, out_buf, sizeof out_buf);
    if ((data[0] & 3u) != 0u) {
        for (uint32_t i = 0; i < 3000u; i++) {
            samples[i] = (i / 37u) * 0x01010101u;
        }
        lhb_capture_arm(&cap, 1, 0, 0, 0);
        lhb_capture_poll(&cap, 0);
        if ((data[0] & 1u) != 0u) {
            lhb_capture_feed(&cap, samples, 2000);
            for (int i = 0; i < 4; i++) {
                lhb_capture_poll(&cap, 0);
            }
        }
    }
    if ((data[0] & 4u) != 0u) {
        feed_frames(data + 1, size - 1, 0);
        return 0;
    }
    uint32_t now = 0;
    for (size_t i = 1; i < size; i++) {
        lhb_proto_rx(&proto, data + i, 1, now);
        now += data[i] & 3u;
        if ((data[0] & 2u) != 0u && data[i] == 0x5Au) {
            lhb_capture_feed(&cap, samples, 500);
        }
    }
    /* also exercise the one-shot decoder and the frame parser directly */
    uint8_t dec[96];
    long r = lhb_cobs_decode(data + 1, size - 1, dec, sizeof dec);
    if (r > 0) {
        lhb_frame_t f;
        (void)lhb_frame_parse(dec, (size_t)r, &f);
    }
    return 0;
}
