/* Fuzz target for the board's request parser (COBS decoder, frame parser, command handler).
 * Built with libFuzzer (fuzz/run_fuzz.sh) or as a corpus replayer for ctest.
 * Input byte 0 selects the starting state (bit 0: a finished capture is ready, bit 1: the
 * capture is running); the rest is fed to the board as received link bytes. Every byte the
 * board sends back must decode to a valid frame: anything else aborts. */
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "lhb/capture.h"
#include "lhb/cobs.h"
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

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static uint32_t storage[2 * 256];
    static lhb_capture_t cap;
    static lhb_proto_t proto;
    static uint32_t samples[3000];
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
