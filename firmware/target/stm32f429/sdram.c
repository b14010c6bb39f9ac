/* FMC set-up for the IS42S16320F (64 MB, 16-bit) on SDRAM bank 1, SDCLK = 90 MHz, and the
 * SDRAM self-tests run at boot.
 *
 * Read path (FMC_SDCR1, RM0090 37.7.3): CAS latency 3, RBURST off, RPIPE = 1 HCLK: ST's
 * reference settings for the F429 at this SDCLK.
 * Timings (FMC_SDTR1, RM0090 37.7.4), in SDCLK cycles of 11.1 ns. The nanosecond figures
 * are the -7 speed-grade minima this firmware has assumed; they were not re-read from the
 * IS42S16320F datasheet (not at hand): check them against its AC table for the fitted grade
 * before bring-up (firmware/README.md, "Unverified on hardware"). tMRD 2 CLK; tXSR 70 ns -> 7;
 * tRAS 42 ns -> 4; tRC 60 ns -> 6 minimum, 7 used (ST's reference value, 77.8 ns);
 * tWR 2 CLK minimum, 3 used because RM0090 requires TWR >= TRC - TRCD - TRP (7 - 2 - 2);
 * tRP 15 ns -> 2; tRCD 15 ns -> 2.
 * Refresh (FMC_SDRTR, RM0090 37.7.6): 8192 rows every 64 ms -> 7.8125 us per row =
 * 703 SDCLK at 90 MHz; COUNT = 703 - 20 (the margin RM0090 asks for) = 683.
 *
 * Self-tests (core memtest.c): data-bus walking ones/zeros, address-bus walking ones over
 * all 24 word-address lines, March C- over the first 1 MiB (512 rows of bank 0), and a
 * retention test: one word in every row of every bank (stride 2 KiB = one row) written,
 * left 100 ms (> the 64 ms refresh period) with the FMC refreshing, read back. */
#include "board.h"
#include "hw.h"
#include "lhb/memtest.h"
#include "regs.h"

#define SDRAM_WORDS (BOARD_SDRAM_SIZE / 4u)
#define MARCH_WORDS (1024u * 1024u / 4u)
#define ROW_WORDS (2048u / 4u) /* 1024 columns x 16 bit */
#define RETENTION_MS 100u
#define FMC_TIMEOUT_CYCLES (BOARD_SYSCLK_HZ / 1000u) /* 1 ms; commands take < 1 us */

typedef struct {
    uint8_t port;
    uint8_t pin;
} pin_t;

/* FMC signals, all alternate function 12 */
static const pin_t fmc_pins[] = {
    /* D0..D15 */
    {PORT_D, 14}, {PORT_D, 15}, {PORT_D, 0}, {PORT_D, 1}, {PORT_E, 7}, {PORT_E, 8},
    {PORT_E, 9}, {PORT_E, 10}, {PORT_E, 11}, {PORT_E, 12}, {PORT_E, 13}, {PORT_E, 14},
    {PORT_E, 15}, {PORT_D, 8}, {PORT_D, 9}, {PORT_D, 10},
    /* A0..A12 */
    {PORT_F, 0}, {PORT_F, 1}, {PORT_F, 2}, {PORT_F, 3}, {PORT_F, 4}, {PORT_F, 5},
    {PORT_F, 12}, {PORT_F, 13}, {PORT_F, 14}, {PORT_F, 15}, {PORT_G, 0}, {PORT_G, 1},
    {PORT_G, 2},
    /* BA0, BA1, SDCLK, SDNCAS, SDNRAS, SDNWE, SDCKE0, SDNE0, NBL0, NBL1 */
    {PORT_G, 4}, {PORT_G, 5}, {PORT_G, 8}, {PORT_G, 15}, {PORT_F, 11}, {PORT_H, 5},
    {PORT_H, 2}, {PORT_H, 3}, {PORT_E, 0}, {PORT_E, 1},
};

static void pin_af(const pin_t *p, uint32_t af)
{
    gpio_t *g = GPIO(p->port);
    uint32_t n = p->pin;
    g->MODER = (g->MODER & ~(3u << (2u * n))) | (2u << (2u * n));
    g->OSPEEDR |= 3u << (2u * n); /* very high speed */
    g->OTYPER &= ~(1u << n);
    g->PUPDR &= ~(3u << (2u * n));
    g->AFR[n >> 3] = (g->AFR[n >> 3] & ~(0xFu << (4u * (n & 7u)))) | (af << (4u * (n & 7u)));
}

static bool sdram_cmd(uint32_t mode, uint32_t auto_refresh, uint32_t mrd)
{
    if (!wait_reg(&FMC_SDRAM->SDSR, FMC_SDSR_BUSY, 0u, FMC_TIMEOUT_CYCLES)) {
        return false;
    }
    /* CTB1 (bit 4): command for bank 1 */
    FMC_SDRAM->SDCMR = mode | (1u << 4) | ((auto_refresh - 1u) << 5) | (mrd << 9);
    return wait_reg(&FMC_SDRAM->SDSR, FMC_SDSR_BUSY, 0u, FMC_TIMEOUT_CYCLES);
}

static uint32_t mem_rd(void *ctx, uint32_t word)
{
    (void)ctx;
    return ((volatile uint32_t *)BOARD_SDRAM_BASE)[word];
}

static void mem_wr(void *ctx, uint32_t word, uint32_t value)
{
    (void)ctx;
    ((volatile uint32_t *)BOARD_SDRAM_BASE)[word] = value;
}

static void self_test(void)
{
    const lhb_mem_t m = {mem_rd, mem_wr, NULL};
    if (lhb_mem_data_bus(&m, 0u) >= 0 || lhb_mem_address_bus(&m, SDRAM_WORDS) >= 0) {
        g_diag.selftest |= LHB_ST_SDRAM_BUS;
        return; /* the other tests cannot mean anything */
    }
    watchdog_refresh();
    if (lhb_mem_march_c_minus(&m, 0u, MARCH_WORDS, 0x00000000u) >= 0) {
        g_diag.selftest |= LHB_ST_SDRAM_MARCH;
    }
    watchdog_refresh();
    lhb_mem_retention_write(&m, SDRAM_WORDS, ROW_WORDS, 0x5EED1234u);
    uint32_t t0 = millis();
    while (millis() - t0 <= RETENTION_MS) {
        watchdog_refresh(); /* the FMC keeps refreshing meanwhile */
    }
    if (lhb_mem_retention_check(&m, SDRAM_WORDS, ROW_WORDS, 0x5EED1234u) >= 0) {
        g_diag.selftest |= LHB_ST_SDRAM_RETENTION;
    }
}

bool sdram_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIO(PORT_D) | RCC_AHB1ENR_GPIO(PORT_E) | RCC_AHB1ENR_GPIO(PORT_F) |
                    RCC_AHB1ENR_GPIO(PORT_G) | RCC_AHB1ENR_GPIO(PORT_H);
    RCC->AHB3ENR |= RCC_AHB3ENR_FMCEN;
    (void)RCC->AHB3ENR;
    for (unsigned i = 0; i < sizeof fmc_pins / sizeof fmc_pins[0]; i++) {
        pin_af(&fmc_pins[i], 12u);
    }
    /* SDCR1: 10 column bits (NC=2), 13 row bits (NR=2), 16-bit (MWID=1),
     * 4 banks (NB=1), CAS 3, SDCLK = HCLK/2 (SDCLK=2), RBURST 0, RPIPE 1 */
    FMC_SDRAM->SDCR[0] = 2u | (2u << 2) | (1u << 4) | (1u << 6) | (3u << 7) | (2u << 10) |
                         (0u << 12) | (1u << 13);
    /* SDTR1 (values minus one): TMRD 2, TXSR 7, TRAS 4, TRC 7, TWR 3, TRP 2, TRCD 2 */
    FMC_SDRAM->SDTR[0] = (2u - 1u) | ((7u - 1u) << 4) | ((4u - 1u) << 8) | ((7u - 1u) << 12) |
                         ((3u - 1u) << 16) | ((2u - 1u) << 20) | ((2u - 1u) << 24);
    bool ok = sdram_cmd(1u, 1u, 0u);                /* clock configuration enable */
    delay_cycles(BOARD_SYSCLK_HZ / 10000u);         /* >= 100 us power-up delay */
    ok = ok && sdram_cmd(2u, 1u, 0u);               /* precharge all */
    ok = ok && sdram_cmd(3u, 8u, 0u);               /* 8 auto-refresh cycles */
    /* mode register: burst length 1, sequential, CAS 3, single-location write burst */
    ok = ok && sdram_cmd(4u, 1u, 0x0230u);
    if (!ok) {
        g_diag.selftest |= LHB_ST_SDRAM_TIMEOUT;
        return false;
    }
    FMC_SDRAM->SDRTR = 683u << 1; /* refresh count, see the top of this file */
    self_test();
    return (g_diag.selftest & (LHB_ST_SDRAM_BUS | LHB_ST_SDRAM_MARCH | LHB_ST_SDRAM_RETENTION)) ==
           0u;
}
