/* SDRAM self-tests against a memory model with injected faults: each test passes on good
 * memory and finds the fault it is meant for. */
#include <string.h>

#include "check.h"
#include "lhb/memtest.h"

#define WORDS 4096u /* power of two: 12 word-address lines */

typedef struct {
    uint32_t cell[WORDS];
    uint32_t stuck_addr_mask; /* address lines forced low (stuck-at-0) */
    uint32_t short_addr;      /* address line shorted to the next one (wired AND), 0 = none */
    uint32_t stuck_data_hi;   /* data bits stuck at 1 */
    long coupled_aggr;        /* writing this cell also flips bit 0 of coupled_victim */
    long coupled_victim;
    long leaky;               /* cell that loses its content on a "wait" */
} model_t;

static uint32_t map(const model_t *m, uint32_t a)
{
    a &= ~m->stuck_addr_mask;
    uint32_t pair = m->short_addr | (m->short_addr << 1);
    if (m->short_addr != 0u && (a & pair) != pair) {
        a &= ~pair; /* both lines low unless both driven high */
    }
    return a & (WORDS - 1u);
}

static uint32_t rd(void *ctx, uint32_t w)
{
    model_t *m = ctx;
    return m->cell[map(m, w)] | m->stuck_data_hi;
}

static void wr(void *ctx, uint32_t w, uint32_t v)
{
    model_t *m = ctx;
    m->cell[map(m, w)] = v;
    if ((long)w == m->coupled_aggr) {
        m->cell[m->coupled_victim] ^= 1u;
    }
}

static void reset(model_t *m)
{
    memset(m, 0, sizeof *m);
    m->coupled_aggr = -1;
    m->coupled_victim = -1;
    m->leaky = -1;
}

int main(void)
{
    static model_t m;
    lhb_mem_t mem = {rd, wr, &m};

    reset(&m);
    CHECK_EQ(lhb_mem_data_bus(&mem, 5), -1);
    CHECK_EQ(lhb_mem_address_bus(&mem, WORDS), -1);
    CHECK_EQ(lhb_mem_march_c_minus(&mem, 0, WORDS, 0u), -1);
    CHECK_EQ(lhb_mem_march_c_minus(&mem, 100, 1000, 0x33333333u), -1);
    lhb_mem_retention_write(&mem, WORDS, 64, 7);
    CHECK_EQ(lhb_mem_retention_check(&mem, WORDS, 64, 7), -1);

    reset(&m);
    m.stuck_data_hi = 1u << 17;
    CHECK(lhb_mem_data_bus(&mem, 5) >= 0);
    CHECK(lhb_mem_march_c_minus(&mem, 0, WORDS, 0u) >= 0);

    reset(&m);
    m.stuck_addr_mask = 1u << 6; /* two halves of every 128 words alias */
    CHECK_EQ(lhb_mem_address_bus(&mem, WORDS), 64);
    CHECK(lhb_mem_march_c_minus(&mem, 0, WORDS, 0u) >= 0);

    reset(&m);
    m.short_addr = 1u << 3;
    CHECK(lhb_mem_address_bus(&mem, WORDS) >= 0);

    reset(&m);
    m.coupled_aggr = 300;
    m.coupled_victim = 301;
    CHECK(lhb_mem_march_c_minus(&mem, 0, WORDS, 0u) >= 0);
    CHECK_EQ(lhb_mem_data_bus(&mem, 5), -1); /* not a bus fault */

    reset(&m);
    lhb_mem_retention_write(&mem, WORDS, 64, 7);
    m.cell[64 * 9] ^= 0x80u; /* a bit decayed while waiting */
    CHECK_EQ(lhb_mem_retention_check(&mem, WORDS, 64, 7), 64 * 9);
    CHECK(lhb_mem_retention_check(&mem, WORDS, 64, 8) >= 0); /* the pattern depends on seed */
    return check_result("memtest");
}
