/* Send ring between the main loop (producer, whole frames) and the UART's TXE interrupt
 * (consumer, bytes). Never blocks: a frame that does not fit is refused whole and counted,
 * so a receiver that never asserts CTS cannot stall the main loop (and with it the
 * capture's start and finalising). lhb_link_service() only hands received bytes to the
 * protocol while the ring has room for the largest answer, so in practice answers are
 * deferred (the requests wait in the receive ring), not dropped. */
#ifndef LHB_TXRING_H
#define LHB_TXRING_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "lhb/proto.h"

typedef struct {
    volatile uint8_t *buf;
    uint32_t size;              /* power of two */
    volatile uint32_t head;     /* written by the producer */
    volatile uint32_t tail;     /* written by the consumer */
    volatile uint32_t *dropped; /* frames refused because they did not fit */
} lhb_txring_t;

void lhb_txring_init(lhb_txring_t *r, volatile uint8_t *buf, uint32_t size,
                     volatile uint32_t *dropped);
uint32_t lhb_txring_room(const lhb_txring_t *r);
/* Queues all n bytes, or none (returns false and counts the drop). */
bool lhb_txring_put(lhb_txring_t *r, const uint8_t *data, size_t n);
/* Consumer side: next byte to send; false when empty. */
bool lhb_txring_pop(lhb_txring_t *r, uint8_t *b);

/* Feeds received bytes (from `pop`) to the protocol while the ring can take the largest
 * answer; returns the number of bytes handled. Never waits. */
size_t lhb_link_service(lhb_proto_t *p, const lhb_txring_t *r, bool (*pop)(uint8_t *b),
                        uint32_t now_ms);

#endif
