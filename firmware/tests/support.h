/* Test support: a fake hardware layer, a host-side decoder for response frames, and a
 * reference image builder that does not use the core's capture code. */
#ifndef LHB_TEST_SUPPORT_H
#define LHB_TEST_SUPPORT_H

#include <stddef.h>
#include <stdint.h>

#include "lhb/capture.h"
#include "lhb/cobs.h"
#include "lhb/frame.h"
#include "lhb/proto.h"

typedef struct {
    int starts;
    int stops;
    uint32_t requested;
    int fail_start;
} fake_hw_t;

lhb_hw_t fake_hw_hooks(fake_hw_t *hw);
void default_template(lhcap_header_t *t);

/* Collects responses written by lhb_proto_t. */
#define SINK_MAX_FRAMES 64
typedef struct {
    lhb_cobs_dec_t dec;
    uint8_t buf[LHB_RESP_RAW_MAX + 64];
    uint8_t frames[SINK_MAX_FRAMES][LHB_RESP_RAW_MAX];
    size_t lens[SINK_MAX_FRAMES];
    int count;
    int bad;
} sink_t;

void sink_init(sink_t *s);
void sink_tx(void *ctx, const uint8_t *data, size_t n);
/* Parses frame i of the sink (asserting a valid CRC). Returns 0 on success. */
int sink_frame(const sink_t *s, int i, lhb_frame_t *f);

/* Sends one request frame into the board. */
void send_request(lhb_proto_t *p, uint8_t type, uint8_t seq, const uint8_t *payload,
                  size_t n, uint32_t now_ms);

/* Pseudo-random generator for tests (xorshift32). */
uint32_t test_rand(uint32_t *state);

/* Fill n port words starting from `start`, flipping one random bit with probability
 * 1/one_in per sample (a reproducible stream of edges from `seed`). */
void test_fill_samples(uint32_t *samples, size_t n, uint32_t seed, uint32_t start,
                       uint32_t one_in);

/* Reference .lhcap image of the given samples (independent implementation). Returns its
 * size; out must hold 108 + 8 * n_samples + 4 bytes. */
size_t reference_image(const lhcap_header_t *tmpl, const uint32_t *samples, size_t n,
                       uint8_t *out);

#endif
