/* 180 MHz from the 8 MHz HSE (see board.h for the tree), and the 1 ms SysTick. */
#include "board.h"
#include "hw.h"
#include "regs.h"

#define PLL_M 4u
#define PLL_N 180u
#define PLL_P_DIV2 0u /* PLLP field 0 = /2 */
#define PLL_Q 8u

_Static_assert(BOARD_HSE_HZ / PLL_M * PLL_N / 2u == BOARD_SYSCLK_HZ, "PLL does not give SYSCLK");

void clock_init(void)
{
    RCC->CR |= RCC_CR_HSEON;
    while ((RCC->CR & RCC_CR_HSERDY) == 0u) {
    }
    /* voltage scale 1 must be chosen while the PLL is off */
    RCC->APB1ENR |= RCC_APB1ENR_PWREN;
    (void)RCC->APB1ENR;
    PWR->CR |= PWR_CR_VOS_SCALE1;

    RCC->PLLCFGR = PLL_M | (PLL_N << 6) | (PLL_P_DIV2 << 16) | RCC_PLLCFGR_SRC_HSE | (PLL_Q << 24);
    RCC->CR |= RCC_CR_PLLON;
    while ((RCC->CR & RCC_CR_PLLRDY) == 0u) {
    }
    /* over-drive: needed above 168 MHz */
    PWR->CR |= PWR_CR_ODEN;
    while ((PWR->CSR & PWR_CSR_ODRDY) == 0u) {
    }
    PWR->CR |= PWR_CR_ODSWEN;
    while ((PWR->CSR & PWR_CSR_ODSWRDY) == 0u) {
    }
    FLASH->ACR = FLASH_ACR_LATENCY_5WS | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    while ((FLASH->ACR & 0xFu) != FLASH_ACR_LATENCY_5WS) {
    }
    /* AHB /1, APB1 /4 (45 MHz), APB2 /2 (90 MHz), then switch to the PLL */
    RCC->CFGR = RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    while ((RCC->CFGR & RCC_CFGR_SWS_MASK) != RCC_CFGR_SWS_PLL) {
    }
}

static volatile uint32_t g_ms;

void SysTick_Handler(void);
void SysTick_Handler(void)
{
    g_ms++;
}

void systick_init(void)
{
    SYSTICK->LOAD = BOARD_SYSCLK_HZ / 1000u - 1u;
    SYSTICK->VAL = 0;
    SYSTICK->CTRL = 7u; /* processor clock, interrupt, enable */
}

uint32_t millis(void)
{
    return g_ms;
}
