#include <string.h>

#include "check.h"
#include "lhb/config.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"
#include "lhb/frame.h"

static long decode_wire(const uint8_t *wire, size_t w, uint8_t *raw, size_t cap)
{
    if (w == 0 || wire[w - 1] != 0) {
        return -1;
    }
    return lhb_cobs_decode(wire, w - 1, raw, cap);
}

int main(void)
{
    uint8_t wire[LHB_WIRE_MAX(LHB_RESP_RAW_MAX)];
    uint8_t raw[LHB_RESP_RAW_MAX];
    lhb_frame_t f;

    /* round trip with a split payload */
    const uint8_t a[] = {1, 2, 0, 3};
    const uint8_t b[] = {0, 0, 9};
    size_t w = lhb_frame_encode(0x84, 7, a, sizeof a, b, sizeof b, wire, sizeof wire);
    CHECK(w > 0);
    CHECK(memchr(wire, 0, w - 1) == NULL);
    CHECK_EQ(wire[w - 1], 0);
    long n = decode_wire(wire, w, raw, sizeof raw);
    CHECK_EQ(n, 8 + 7);
    CHECK_EQ(lhb_frame_parse(raw, (size_t)n, &f), LHB_OK);
    CHECK_EQ(f.type, 0x84);
    CHECK_EQ(f.seq, 7);
    CHECK_EQ(f.len, 7);
    CHECK(memcmp(f.payload, a, 4) == 0 && memcmp(f.payload + 4, b, 3) == 0);
    /* byte layout: type seq len crc(type..payload) */
    CHECK_EQ(raw[0], 0x84);
    CHECK_EQ(lhb_get_le16(raw + 2), 7);
    CHECK_EQ(lhb_get_le32(raw + 11), lhb_crc32(raw, 11));

    /* empty payload */
    w = lhb_frame_encode(0x01, 0, NULL, 0, NULL, 0, wire, sizeof wire);
    n = decode_wire(wire, w, raw, sizeof raw);
    CHECK_EQ(n, 8);
    CHECK_EQ(lhb_frame_parse(raw, (size_t)n, &f), LHB_OK);
    CHECK_EQ(f.len, 0);

    /* every single-bit flip is caught */
    w = lhb_frame_encode(0x83, 200, a, sizeof a, NULL, 0, wire, sizeof wire);
    n = decode_wire(wire, w, raw, sizeof raw);
    for (long bit = 0; bit < n * 8; bit++) {
        uint8_t c[32];
        memcpy(c, raw, (size_t)n);
        c[bit / 8] ^= (uint8_t)(1u << (bit % 8));
        CHECK(lhb_frame_parse(c, (size_t)n, &f) != LHB_OK);
    }
    /* short frames */
    for (size_t k = 0; k < LHB_FRAME_OVERHEAD; k++) {
        CHECK_EQ(lhb_frame_parse(raw, k, &f), -LHB_E_FRAMING);
    }
    /* a length field that disagrees with the size but a valid CRC */
    {
        uint8_t c[16] = {0x02, 1, 5, 0, 0xAA};
        lhb_put_le32(c + 5, lhb_crc32(c, 5));
        CHECK_EQ(lhb_frame_parse(c, 9, &f), -LHB_E_LENGTH);
    }
    /* the largest response fits the wire buffer; one byte more does not encode */
    static uint8_t big[LHB_RESP_PAYLOAD_MAX + 1];
    memset(big, 0xA5, sizeof big);
    CHECK(lhb_frame_encode(0x84, 1, big, LHB_RESP_PAYLOAD_MAX, NULL, 0, wire, sizeof wire) > 0);
    CHECK_EQ(lhb_frame_encode(0x84, 1, big, sizeof big, NULL, 0, wire, LHB_WIRE_MAX(LHB_RESP_RAW_MAX) - 1), 0);
    /* payload length limit and NULL arguments */
    CHECK_EQ(lhb_frame_encode(1, 0, big, 0x10000, NULL, 0, wire, sizeof wire), 0);
    CHECK_EQ(lhb_frame_encode(1, 0, NULL, 3, NULL, 0, wire, sizeof wire), 0);
    CHECK_EQ(lhb_frame_encode(1, 0, NULL, 0, NULL, 0, NULL, 10), 0);
    CHECK_EQ(lhb_frame_parse(NULL, 10, &f), -LHB_E_FRAMING);
    return check_result("frame");
}
