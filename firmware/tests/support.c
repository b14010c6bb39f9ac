#include "support.h"

#include <string.h>

#include "check.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"

int check_failures = 0;
int check_count = 0;

int check_result(const char *name)
{
    printf("%s: %d checks, %d failed\n", name, check_count, check_failures);
    return check_failures == 0 ? 0 : 1;
}

static int fake_start(void *ctx, uint32_t n)
{
    fake_hw_t *hw = ctx;
    hw->starts++;
    hw->requested = n;
    return hw->fail_start ? -1 : 0;
}

static void fake_stop(void *ctx)
{
    fake_hw_t *hw = ctx;
    hw->stops++;
}

lhb_hw_t fake_hw_hooks(fake_hw_t *hw)
{
    memset(hw, 0, sizeof *hw);
    lhb_hw_t h = {fake_start, fake_stop, hw};
    return h;
}

void default_template(lhcap_header_t *t)
{
    memset(t, 0, sizeof *t);
    t->version = LHCAP_VERSION;
    t->sample_rate = 2000000u;
    t->board_id = 0x12345678u;
    t->fw_version = 0x000100u;
    for (int k = 0; k < 32; k++) {
        t->channel_map[k] = (int16_t)(k < 30 ? k : -1);
    }
}

void sink_init(sink_t *s)
{
    memset(s, 0, sizeof *s);
    lhb_cobs_dec_init(&s->dec, s->buf, sizeof s->buf);
}

void sink_tx(void *ctx, const uint8_t *data, size_t n)
{
    sink_t *s = ctx;
    for (size_t i = 0; i < n; i++) {
        long r = lhb_cobs_dec_push(&s->dec, data[i]);
        if (r > 0) {
            if (s->count < SINK_MAX_FRAMES && (size_t)(r - 1) <= LHB_RESP_RAW_MAX) {
                memcpy(s->frames[s->count], s->buf, (size_t)(r - 1));
                s->lens[s->count] = (size_t)(r - 1);
                s->count++;
            } else {
                s->bad++;
            }
        } else if (r < 0) {
            s->bad++;
        }
    }
}

int sink_frame(const sink_t *s, int i, lhb_frame_t *f)
{
    if (i < 0 || i >= s->count) {
        return -1;
    }
    return lhb_frame_parse(s->frames[i], s->lens[i], f) == 0 ? 0 : -1;
}

void send_request(lhb_proto_t *p, uint8_t type, uint8_t seq, const uint8_t *payload,
                  size_t n, uint32_t now_ms)
{
    uint8_t wire[256];
    size_t w = lhb_frame_encode(type, seq, payload, n, NULL, 0, wire, sizeof wire);
    CHECK(w > 0);
    lhb_proto_rx(p, wire, w, now_ms);
}

uint32_t test_rand(uint32_t *state)
{
    uint32_t x = *state;
    x ^= x << 13;
    x ^= x >> 17;
    x ^= x << 5;
    *state = x;
    return x;
}

size_t reference_image(const lhcap_header_t *tmpl, const uint32_t *samples, size_t n,
                       uint8_t *out)
{
    size_t pos = 108;
    uint32_t records = 0;
    for (size_t i = 0; i < n; i++) {
        if (i == 0 || samples[i] != samples[i - 1]) {
            lhb_put_le32(out + pos, (uint32_t)i);
            lhb_put_le32(out + pos + 4, samples[i]);
            pos += 8;
            records++;
        }
    }
    memcpy(out, "LHCP", 4);
    lhb_put_le16(out + 4, 1);
    lhb_put_le16(out + 6, 108);
    lhb_put_le32(out + 8, tmpl->sample_rate);
    lhb_put_le32(out + 12, tmpl->flags);
    lhb_put_le32(out + 16, tmpl->board_id);
    lhb_put_le32(out + 20, tmpl->fw_version);
    lhb_put_le64(out + 24, tmpl->start_time_us);
    lhb_put_le64(out + 32, (uint64_t)n);
    lhb_put_le32(out + 40, records);
    for (int k = 0; k < 32; k++) {
        lhb_put_le16(out + 44 + 2 * k, (uint16_t)tmpl->channel_map[k]);
    }
    lhb_put_le32(out + pos, lhb_crc32(out, pos));
    return pos + 4;
}

void test_fill_samples(uint32_t *samples, size_t n, uint32_t seed, uint32_t start,
                       uint32_t one_in)
{
    uint32_t rng = seed;
    uint32_t w = start;
    for (size_t i = 0; i < n; i++) {
        if (test_rand(&rng) % one_in == 0) {
            w ^= 1u << (test_rand(&rng) % 32);
        }
        samples[i] = w;
    }
}
