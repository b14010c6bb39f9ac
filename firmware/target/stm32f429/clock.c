/* 180 MHz from the HSE (clock_config.h has the PLL and its checks), and the 1 ms SysTick.
 *
 * Every wait on the clock tree is bounded (DWT cycle counter). If the HSE does not become
 * ready within 100 ms (start-up is ~2 ms typical, DS9405), the PLL runs from the HSI
 * instead: the board still answers, but sample timing and baud rate are only as good as
 * the HSI (+-1 % at 25 C), and STATUS says so (LHB_ST_HSE_FAILED). A running HSE is also
 * measured against the HSI before the switch: TIM11's input 1 can take HSE_RTC = HSE /
 * RTCPRE (1 MHz; RM0090 18.5.11 TIM11_OR), and capturing every 8th edge for 64 intervals on
 * the 16 MHz HSI clock gives its frequency to ~0.02 % (plus the HSI's own error). A crystal
 * other than the configured one (e.g. 25 MHz fitted, 8 MHz built) is flagged
 * LHB_ST_HSE_MISMATCH, with the measured value in STATUS. */
#include "board.h"
#include "clock_config.h"
#include "hw.h"
#include "regs.h"

#define HSE_TIMEOUT_CYCLES (HSI_HZ / 10u) /* 100 ms on the HSI */
#define PLL_TIMEOUT_CYCLES (HSI_HZ / 100u) /* 10 ms */
#define MEASURE_INTERVALS 64u
#define MEASURE_EDGES_PER_CAPTURE 8u   /* IC1PSC = /8 */
#define HSE_TOLERANCE_PERCENT 5u       /* HSI factory trim over temperature, with margin */

/* HSE frequency in kHz from TIM11 input captures of HSE_RTC; 0 if no edges arrived. */
static uint32_t measure_hse_khz(void)
{
    RCC->CFGR = (RCC->CFGR & ~RCC_CFGR_RTCPRE(31u)) | RCC_CFGR_RTCPRE(HSE_RTCPRE);
    RCC->APB2ENR |= RCC_APB2ENR_TIM11EN;
    (void)RCC->APB2ENR;
    TIM11->CR1 = 0;
    TIM11->OR = TIM11_OR_TI1_HSE_RTC;
    TIM11->PSC = 0; /* counts SYSCLK = HSI (APB2 /1 until the switch) */
    TIM11->ARR = 0xFFFFu;
    TIM11->CCMR1 = 1u | (3u << 2); /* CC1S = 01 (input TI1), IC1PSC = /8 */
    TIM11->CCER = 1u;              /* CC1E */
    TIM11->EGR = TIM_EGR_UG;
    TIM11->SR = 0;
    TIM11->CR1 = TIM_CR1_CEN;
    uint32_t total = 0;
    uint32_t last = 0;
    bool ok = true;
    for (uint32_t k = 0; k <= MEASURE_INTERVALS && ok; k++) {
        ok = wait_reg(&TIM11->SR, TIM_SR_CC1IF, TIM_SR_CC1IF, HSI_HZ / 1000u);
        uint32_t c = TIM11->CCR1; /* reading clears CC1IF */
        if (k > 0u) {
            total += (c - last) & 0xFFFFu;
        }
        last = c;
    }
    TIM11->CR1 = 0;
    TIM11->CCER = 0;
    TIM11->OR = 0;
    RCC->APB2ENR &= ~RCC_APB2ENR_TIM11EN;
    if (!ok || total == 0u) {
        return 0;
    }
    /* f_rtc = intervals * edges * f_hsi / ticks; HSE = f_rtc * RTCPRE */
    uint64_t hz = (uint64_t)MEASURE_INTERVALS * MEASURE_EDGES_PER_CAPTURE * HSI_HZ * HSE_RTCPRE /
                  total;
    return (uint32_t)(hz / 1000u);
}

static bool hse_matches(uint32_t khz)
{
    uint32_t want = BOARD_HSE_HZ / 1000u;
    uint32_t tol = want * HSE_TOLERANCE_PERCENT / 100u;
    return khz + tol >= want && khz <= want + tol;
}

void clock_init(void)
{
    RCC->CR |= RCC_CR_HSEON;
    bool hse = wait_reg(&RCC->CR, RCC_CR_HSERDY, RCC_CR_HSERDY, HSE_TIMEOUT_CYCLES);
    if (hse) {
        g_diag.hse_khz = measure_hse_khz();
        if (!hse_matches(g_diag.hse_khz)) {
            g_diag.selftest |= LHB_ST_HSE_MISMATCH;
        }
    } else {
        RCC->CR &= ~RCC_CR_HSEON;
        g_diag.selftest |= LHB_ST_HSE_FAILED;
    }
    /* voltage scale 1 must be chosen while the PLL is off */
    RCC->APB1ENR |= RCC_APB1ENR_PWREN;
    (void)RCC->APB1ENR;
    PWR->CR |= PWR_CR_VOS_SCALE1;

    uint32_t src = hse ? RCC_PLLCFGR_SRC_HSE | BOARD_PLL_M : PLL_HSI_M;
    RCC->PLLCFGR = src | (PLL_N << 6) | ((PLL_P / 2u - 1u) << 16) | (PLL_Q << 24);
    RCC->CR |= RCC_CR_PLLON;
    bool ok = wait_reg(&RCC->CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY, PLL_TIMEOUT_CYCLES);
    /* over-drive: needed above 168 MHz */
    PWR->CR |= PWR_CR_ODEN;
    ok = ok && wait_reg(&PWR->CSR, PWR_CSR_ODRDY, PWR_CSR_ODRDY, PLL_TIMEOUT_CYCLES);
    PWR->CR |= PWR_CR_ODSWEN;
    ok = ok && wait_reg(&PWR->CSR, PWR_CSR_ODSWRDY, PWR_CSR_ODSWRDY, PLL_TIMEOUT_CYCLES);
    if (!ok) {
        g_diag.selftest |= LHB_ST_CLOCK_TIMEOUT; /* stay on the HSI: the LED shows it */
        return;
    }
    FLASH->ACR = FLASH_ACR_LATENCY_5WS | FLASH_ACR_PRFTEN | FLASH_ACR_ICEN | FLASH_ACR_DCEN;
    if (!wait_reg(&FLASH->ACR, 0xFu, FLASH_ACR_LATENCY_5WS, PLL_TIMEOUT_CYCLES)) {
        g_diag.selftest |= LHB_ST_CLOCK_TIMEOUT;
        return;
    }
    /* AHB /1, APB1 /4 (45 MHz), APB2 /2 (90 MHz), then switch to the PLL */
    RCC->CFGR = (RCC->CFGR & RCC_CFGR_RTCPRE(31u)) | RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
    RCC->CFGR |= RCC_CFGR_SW_PLL;
    if (!wait_reg(&RCC->CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL, PLL_TIMEOUT_CYCLES)) {
        g_diag.selftest |= LHB_ST_CLOCK_TIMEOUT;
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
