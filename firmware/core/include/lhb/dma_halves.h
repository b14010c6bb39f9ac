/* Bookkeeping of a double-buffered DMA stream: which half the interrupt must read, and
 * whether it was late enough to lose one. The half to read follows from a count of the
 * halves processed, not from the DMA's CT bit; CT is used as a check: on entry it must name
 * the other half (the DMA completed exactly one half since the last interrupt), and after
 * the half has been copied, no new transfer-complete may have arrived (the DMA would then
 * be writing into the half being copied). Either failure counts as an overrun. */
#ifndef LHB_DMA_HALVES_H
#define LHB_DMA_HALVES_H

#include <stdbool.h>
#include <stdint.h>

typedef struct {
    uint32_t processed; /* halves handed to the extractor */
    uint32_t overruns;  /* halves lost (interrupt late by a whole half, or copy overtaken) */
} lhb_halves_t;

void lhb_halves_init(lhb_halves_t *h);
/* On a transfer-complete interrupt. ct = the half the DMA is filling now (CT bit).
 * Returns the half (0/1) to copy, or -1 if the DMA is already past it (counted). */
int lhb_halves_begin(lhb_halves_t *h, uint32_t ct);
/* After copying the half returned by begin: tc_again = a new transfer-complete flag is set.
 * Returns true if the copy is intact (the half is counted as processed), false if the DMA
 * overtook it (counted as an overrun). */
bool lhb_halves_end(lhb_halves_t *h, bool tc_again);

#endif
