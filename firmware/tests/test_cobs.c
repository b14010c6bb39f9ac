#include <string.h>

#include "check.h"
#include "lhb/cobs.h"
#include "lhb/errors.h"
#include "support.h"

static void roundtrip(const uint8_t *src, size_t n)
{
    uint8_t enc[2048], dec[2048];
    size_t e = lhb_cobs_encode(src, n, enc, sizeof enc);
    CHECK(e > 0);
    CHECK(e <= LHB_COBS_MAX_ENCODED(n));
    CHECK(memchr(enc, 0, e) == NULL);
    long d = lhb_cobs_decode(enc, e, dec, sizeof dec);
    CHECK_EQ(d, (long)n);
    CHECK(d < 0 || memcmp(dec, src, n) == 0);
}

int main(void)
{
    /* known vectors */
    {
        const uint8_t in[] = {0x11, 0x00, 0x22};
        const uint8_t want[] = {0x02, 0x11, 0x02, 0x22};
        uint8_t out[8];
        CHECK_EQ(lhb_cobs_encode(in, 3, out, sizeof out), 4);
        CHECK(memcmp(out, want, 4) == 0);
        uint8_t e0[4];
        CHECK_EQ(lhb_cobs_encode(NULL, 0, e0, sizeof e0), 1);
        CHECK_EQ(e0[0], 1);
        const uint8_t z[] = {0};
        CHECK_EQ(lhb_cobs_encode(z, 1, out, sizeof out), 2);
        CHECK(out[0] == 1 && out[1] == 1);
    }
    /* lengths around the 254-byte group limit, with and without zeros */
    uint8_t buf[1100];
    uint32_t rng = 12345;
    size_t lens[] = {0, 1, 2, 253, 254, 255, 256, 507, 508, 509, 1000};
    for (size_t li = 0; li < sizeof lens / sizeof lens[0]; li++) {
        size_t n = lens[li];
        memset(buf, 0x55, n);
        roundtrip(buf, n);
        memset(buf, 0, n);
        roundtrip(buf, n);
        for (size_t i = 0; i < n; i++) {
            buf[i] = (uint8_t)(test_rand(&rng) % 4 == 0 ? 0 : test_rand(&rng));
        }
        roundtrip(buf, n);
    }
    /* encoder refuses a too small output buffer */
    memset(buf, 7, 300);
    uint8_t small[100];
    CHECK_EQ(lhb_cobs_encode(buf, 300, small, sizeof small), 0);
    /* decoder: zero inside, truncated group, empty input, output too small */
    {
        uint8_t out[16];
        const uint8_t zero_in[] = {0x03, 0x11, 0x00, 0x22};
        CHECK_EQ(lhb_cobs_decode(zero_in, 4, out, sizeof out), -LHB_E_FRAMING);
        const uint8_t trunc[] = {0x05, 0x11, 0x22};
        CHECK_EQ(lhb_cobs_decode(trunc, 3, out, sizeof out), -LHB_E_FRAMING);
        CHECK_EQ(lhb_cobs_decode(trunc, 0, out, sizeof out), -LHB_E_FRAMING);
        uint8_t big_enc[64];
        memset(buf, 9, 40);
        size_t e = lhb_cobs_encode(buf, 40, big_enc, sizeof big_enc);
        CHECK_EQ(lhb_cobs_decode(big_enc, e, out, sizeof out), -LHB_E_TOO_LONG);
    }
    /* streaming decoder: frames, empty frames, a bad frame, then recovery */
    {
        uint8_t dbuf[16];
        lhb_cobs_dec_t d;
        lhb_cobs_dec_init(&d, dbuf, sizeof dbuf);
        const uint8_t stream[] = {0x00, 0x00, 0x02, 0x11, 0x02, 0x22, 0x00, /* good */
                                  0x05, 0x11, 0x00,                         /* truncated */
                                  0x02, 0x33, 0x00};                        /* good */
        long results[sizeof stream];
        for (size_t i = 0; i < sizeof stream; i++) {
            results[i] = lhb_cobs_dec_push(&d, stream[i]);
        }
        CHECK_EQ(results[0], 0);
        CHECK_EQ(results[1], 0);
        CHECK_EQ(results[6], 4); /* 3 bytes + 1 */
        CHECK_EQ(results[9], -LHB_E_FRAMING);
        CHECK_EQ(results[12], 2);
        CHECK_EQ(dbuf[0], 0x33);
        /* oversize: reported once at the delimiter, then the decoder works again */
        for (int i = 0; i < 40; i++) {
            CHECK_EQ(lhb_cobs_dec_push(&d, i == 0 ? 0xFF : 0x41), 0);
        }
        CHECK_EQ(lhb_cobs_dec_push(&d, 0), -LHB_E_TOO_LONG);
        CHECK_EQ(lhb_cobs_dec_push(&d, 0x01), 0);
        CHECK_EQ(lhb_cobs_dec_push(&d, 0x00), 1); /* empty payload decodes to 0 bytes */
    }
    return check_result("cobs");
}
