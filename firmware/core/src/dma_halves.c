#include "lhb/dma_halves.h"

void lhb_halves_init(lhb_halves_t *h)
{
    h->processed = 0;
    h->overruns = 0;
}

int lhb_halves_begin(lhb_halves_t *h, uint32_t ct)
{
    uint32_t half = h->processed & 1u; /* the DMA fills half 0 (M0AR) first */
    if ((ct & 1u) == half) {
        h->overruns++; /* it completed the other half too and is overwriting this one */
        return -1;
    }
    return (int)half;
}

bool lhb_halves_end(lhb_halves_t *h, bool tc_again)
{
    if (tc_again) {
        h->overruns++;
        return false;
    }
    h->processed++;
    return true;
}
