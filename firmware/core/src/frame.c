#include "lhb/frame.h"

#include "lhb/config.h"
#include "lhb/crc32.h"
#include "lhb/endian.h"
#include "lhb/errors.h"

int lhb_frame_parse(const uint8_t *raw, size_t n, lhb_frame_t *out)
{
    if (raw == NULL || out == NULL || n < LHB_FRAME_OVERHEAD) {
        return -LHB_E_FRAMING;
    }
    uint32_t want = lhb_get_le32(raw + n - LHB_FRAME_CRC_LEN);
    if (lhb_crc32(raw, n - LHB_FRAME_CRC_LEN) != want) {
        return -LHB_E_CRC;
    }
    uint16_t len = lhb_get_le16(raw + 2);
    if ((size_t)len != n - LHB_FRAME_OVERHEAD) {
        return -LHB_E_LENGTH;
    }
    out->type = raw[0];
    out->seq = raw[1];
    out->len = len;
    out->payload = raw + LHB_FRAME_HDR_LEN;
    return LHB_OK;
}

size_t lhb_frame_encode(uint8_t type, uint8_t seq, const uint8_t *p1, size_t n1,
                        const uint8_t *p2, size_t n2, uint8_t *out, size_t cap)
{
    if ((p1 == NULL && n1 != 0) || (p2 == NULL && n2 != 0) || n1 > 0xFFFFu ||
        n2 > 0xFFFFu - n1 || out == NULL) {
        return 0;
    }
    uint8_t hdr[LHB_FRAME_HDR_LEN];
    hdr[0] = type;
    hdr[1] = seq;
    lhb_put_le16(hdr + 2, (uint16_t)(n1 + n2));
    uint32_t crc = lhb_crc32(hdr, sizeof hdr);
    crc = lhb_crc32_update(crc, p1, n1);
    crc = lhb_crc32_update(crc, p2, n2);
    uint8_t tail[LHB_FRAME_CRC_LEN];
    lhb_put_le32(tail, crc);

    lhb_cobs_enc_t e;
    lhb_cobs_enc_begin(&e, out, cap);
    lhb_cobs_enc_write(&e, hdr, sizeof hdr);
    lhb_cobs_enc_write(&e, p1, n1);
    lhb_cobs_enc_write(&e, p2, n2);
    lhb_cobs_enc_write(&e, tail, sizeof tail);
    return lhb_cobs_enc_end(&e, true);
}
