#include "lhb/txring.h"

#include "lhb/config.h"

void lhb_txring_init(lhb_txring_t *r, volatile uint8_t *buf, uint32_t size,
                     volatile uint32_t *dropped)
{
    r->buf = buf;
    r->size = size;
    r->head = 0;
    r->tail = 0;
    r->dropped = dropped;
}

uint32_t lhb_txring_room(const lhb_txring_t *r)
{
    return (r->tail - r->head - 1u) & (r->size - 1u);
}

bool lhb_txring_put(lhb_txring_t *r, const uint8_t *data, size_t n)
{
    if (n > lhb_txring_room(r)) {
        if (r->dropped != NULL) {
            (*r->dropped)++;
        }
        return false;
    }
    uint32_t h = r->head;
    for (size_t i = 0; i < n; i++) {
        r->buf[h] = data[i];
        h = (h + 1u) & (r->size - 1u);
    }
    r->head = h; /* published after the bytes */
    return true;
}

bool lhb_txring_pop(lhb_txring_t *r, uint8_t *b)
{
    uint32_t t = r->tail;
    if (t == r->head) {
        return false;
    }
    *b = r->buf[t];
    r->tail = (t + 1u) & (r->size - 1u);
    return true;
}

size_t lhb_link_service(lhb_proto_t *p, const lhb_txring_t *r, bool (*pop)(uint8_t *b),
                        uint32_t now_ms)
{
    size_t handled = 0;
    uint8_t b;
    while (lhb_txring_room(r) >= LHB_WIRE_MAX(LHB_RESP_RAW_MAX) && pop(&b)) {
        lhb_proto_rx(p, &b, 1, now_ms);
        handled++;
    }
    return handled;
}
