/* FMC set-up for the IS42S16320F (64 MB, 16-bit) on SDRAM bank 1, SDCLK = 90 MHz. */
#include "board.h"
#include "hw.h"
#include "regs.h"

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

static void delay_cycles(uint32_t n)
{
    for (volatile uint32_t i = 0; i < n; i++) {
    }
}

static void sdram_cmd(uint32_t mode, uint32_t auto_refresh, uint32_t mrd)
{
    while ((FMC_SDRAM->SDSR & FMC_SDSR_BUSY) != 0u) {
    }
    /* CTB1 (bit 4): command for bank 1 */
    FMC_SDRAM->SDCMR = mode | (1u << 4) | ((auto_refresh - 1u) << 5) | (mrd << 9);
    while ((FMC_SDRAM->SDSR & FMC_SDSR_BUSY) != 0u) {
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
    /* SDCR1: 10 column bits (NC=2), 13 row bits (NR=2), 16-bit (MWID=1), 4 banks (NB=1),
     * CAS 3, SDCLK = HCLK/2 (SDCLK=2), read burst on, no read pipe delay */
    FMC_SDRAM->SDCR[0] = 2u | (2u << 2) | (1u << 4) | (1u << 6) | (3u << 7) | (2u << 10) | (1u << 12);
    /* SDTR1 at 11.1 ns per clock (values minus one): tMRD 2, tXSR 70 ns -> 7, tRAS 42 ns -> 4,
     * tRC 60 ns -> 6, tWR 2, tRP 15 ns -> 2, tRCD 15 ns -> 2 */
    FMC_SDRAM->SDTR[0] = (2u - 1u) | ((7u - 1u) << 4) | ((4u - 1u) << 8) | ((6u - 1u) << 12) |
                         ((2u - 1u) << 16) | ((2u - 1u) << 20) | ((2u - 1u) << 24);
    sdram_cmd(1u, 1u, 0u);       /* clock configuration enable */
    delay_cycles(180000u / 4u);  /* >= 100 us power-up delay */
    sdram_cmd(2u, 1u, 0u);       /* precharge all */
    sdram_cmd(3u, 8u, 0u);       /* 8 auto-refresh cycles */
    /* mode register: burst length 1, sequential, CAS 3, single-location write burst */
    sdram_cmd(4u, 1u, 0x0230u);
    /* refresh: 64 ms / 8192 rows = 7.81 us -> 703 SDCLK, minus 20 margin */
    FMC_SDRAM->SDRTR = (683u << 1);

    /* pattern test across the whole range (a few words per MB) */
    volatile uint32_t *m = (volatile uint32_t *)BOARD_SDRAM_BASE;
    const uint32_t words = BOARD_SDRAM_SIZE / 4u;
    for (uint32_t i = 0; i < words; i += 65537u) {
        m[i] = i * 2654435761u;
    }
    for (uint32_t i = 0; i < words; i += 65537u) {
        if (m[i] != i * 2654435761u) {
            return false;
        }
    }
    return true;
}
