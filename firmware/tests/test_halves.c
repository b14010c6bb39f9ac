/* Double-buffer bookkeeping: the half to read follows a count, CT is a check, and a late
 * interrupt (a whole half late, or overtaken while copying) is counted, never silent. */
#include "check.h"
#include "lhb/dma_halves.h"

/* A model of the DMA in double-buffer mode: completes halves 0, 1, 0, ...; ct = the half it
 * fills now; tc = transfer-complete flag (set on each completion, cleared by the ISR). */
typedef struct {
    uint32_t completed;
    int tc;
} dma_model_t;

static uint32_t ct(const dma_model_t *d) { return d->completed & 1u; }
static void complete(dma_model_t *d)
{
    d->completed++;
    d->tc = 1;
}

int main(void)
{
    lhb_halves_t h;
    dma_model_t d = {0, 0};

    /* on time: every interrupt reads the half just completed, in order 0, 1, 0, 1 */
    lhb_halves_init(&h);
    for (int k = 0; k < 6; k++) {
        complete(&d);
        d.tc = 0; /* ISR entry clears the flag */
        int half = lhb_halves_begin(&h, ct(&d));
        CHECK_EQ(half, k & 1);
        CHECK(lhb_halves_end(&h, d.tc != 0));
    }
    CHECK_EQ(h.processed, 6);
    CHECK_EQ(h.overruns, 0);

    /* a whole half late: two completions before the interrupt runs. Choosing the half from
     * CT alone would read half 0 (the one being overwritten) and lose half 1 silently. */
    lhb_halves_init(&h);
    d.completed = 0;
    complete(&d);
    complete(&d);
    d.tc = 0;
    CHECK_EQ(lhb_halves_begin(&h, ct(&d)), -1);
    CHECK_EQ(h.overruns, 1);

    /* overtaken while copying: a new completion arrives before the copy ends */
    lhb_halves_init(&h);
    d.completed = 0;
    complete(&d);
    d.tc = 0;
    CHECK_EQ(lhb_halves_begin(&h, ct(&d)), 0);
    complete(&d); /* the DMA moves on into half 0 during the copy */
    CHECK(!lhb_halves_end(&h, d.tc != 0));
    CHECK_EQ(h.overruns, 1);
    CHECK_EQ(h.processed, 0);

    /* a completion during the slow part (after the copy) is the next interrupt's half */
    lhb_halves_init(&h);
    d.completed = 0;
    complete(&d);
    d.tc = 0;
    CHECK_EQ(lhb_halves_begin(&h, ct(&d)), 0);
    CHECK(lhb_halves_end(&h, d.tc != 0));
    complete(&d); /* during feeding: interrupt pending again */
    d.tc = 0;
    CHECK_EQ(lhb_halves_begin(&h, ct(&d)), 1);
    CHECK(lhb_halves_end(&h, false));
    CHECK_EQ(h.overruns, 0);
    return check_result("halves");
}
