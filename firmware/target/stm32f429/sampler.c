/* 2 MHz sampling of the 32 photodiode lines: TIM8 -> DMA2 (double-buffer) -> edge extractor.
 *
 * TIM8 runs at 180 MHz / 90 = 2 MHz. Each update event makes DMA2 stream 1 copy GPIOI->IDR
 * (channels 0..15) and each CC1 event (one tick later) makes stream 2 copy GPIOJ->IDR
 * (channels 16..31), as half-words, into two pairs of SRAM buffers (double-buffer mode:
 * the DMA fills one half while the CPU reads the other). Stream 2 finishes a half last, so
 * its transfer-complete interrupt hands the finished half to the core, which turns it into
 * edge records in SDRAM. The half to read follows from the count of halves processed
 * (core dma_halves.c), with the CT bit as a check on entry and the TC flag and CT again
 * after the copy: an interrupt a whole half late, or overtaken by the DMA while copying,
 * is counted in g_diag.dma_overruns (STATUS) and stops the capture marked as overflowed;
 * so does a DMA error. The interrupt's cost is measured with the cycle counter
 * (g_diag.isr_cycles_max) against the budget of one half (2048 samples = 184 320 cycles). */
#include <stdint.h>

#include "board.h"
#include "hw.h"
#include "lhb/dma_halves.h"
#include "regs.h"

#define CHUNK 2048u /* samples per half = 1.024 ms */
#define TIM8_ARR (BOARD_TIM8_CLK_HZ / 2000000u - 1u)

_Static_assert(BOARD_TIM8_CLK_HZ % 2000000u == 0u, "timer clock is not a multiple of 2 MHz");

static uint16_t buf_lo[2][CHUNK] __attribute__((aligned(4)));
static uint16_t buf_hi[2][CHUNK] __attribute__((aligned(4)));
static uint32_t words[CHUNK] __attribute__((section(".ccm")));
static lhb_capture_t *g_cap;
static lhb_halves_t g_halves;

#define S_LO 1 /* DMA2 stream 1, channel 7: TIM8_UP */
#define S_HI 2 /* DMA2 stream 2, channel 7: TIM8_CH1 */

void sampler_init(lhb_capture_t *cap)
{
    g_cap = cap;
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIO(PORT_I) | RCC_AHB1ENR_GPIO(PORT_J) | RCC_AHB1ENR_DMA2EN;
    RCC->APB2ENR |= RCC_APB2ENR_TIM8EN;
    (void)RCC->APB2ENR;
    /* all 32 lines: inputs, no pull (the amplifiers drive them) */
    GPIO(PORT_I)->MODER = 0;
    GPIO(PORT_I)->PUPDR = 0;
    GPIO(PORT_J)->MODER = 0;
    GPIO(PORT_J)->PUPDR = 0;
    g_diag.isr_cycles_budget = CHUNK * (BOARD_SYSCLK_HZ / 2000000u);
}

static void stream_off(int s)
{
    DMA2->S[s].CR &= ~DMA_CR_EN;
    /* EN clears once the current transfer is over (one half-word, well under 1 us) */
    if (!wait_reg(&DMA2->S[s].CR, DMA_CR_EN, 0u, BOARD_SYSCLK_HZ / 10000u)) {
        g_diag.selftest |= LHB_ST_PERIPH_TIMEOUT;
    }
    DMA2->LIFCR = DMA_FLAGS_ALL << DMA_LISR_SHIFT(s);
}

static void stream_setup(int s, volatile uint32_t *src, uint16_t (*dst)[CHUNK], uint32_t irqs)
{
    stream_off(s);
    DMA2->S[s].PAR = (uint32_t)(uintptr_t)src;
    DMA2->S[s].M0AR = (uint32_t)(uintptr_t)dst[0];
    DMA2->S[s].M1AR = (uint32_t)(uintptr_t)dst[1];
    DMA2->S[s].NDTR = CHUNK;
    DMA2->S[s].FCR = 0; /* direct mode */
    DMA2->S[s].CR = DMA_CR_CHSEL(7) | DMA_CR_DBM | DMA_CR_PL_VERY_HIGH | DMA_CR_MSIZE_16 |
                    DMA_CR_PSIZE_16 | DMA_CR_MINC | DMA_CR_DIR_P2M | irqs;
}

int sampler_start(void *ctx, uint32_t n_samples)
{
    (void)ctx;
    if (g_cap == NULL || g_cap->edges.storage == NULL || n_samples == 0u) {
        return -1; /* SDRAM failed its test at boot */
    }
    sampler_stop(NULL);
    lhb_halves_init(&g_halves);
    TIM8->CR1 = TIM_CR1_URS;
    TIM8->CR2 = TIM_CR2_MMS_UPDATE; /* TRGO: TIM5 counts samples for the IMU's stamps */
    TIM8->PSC = 0;
    TIM8->ARR = TIM8_ARR;
    TIM8->CCMR1 = 0; /* CC1 as frozen output compare: only its event is used */
    TIM8->CCR1 = 1;
    TIM8->EGR = TIM_EGR_UG; /* load PSC/ARR before the DMA requests are enabled */
    TIM8->SR = 0;
    /* start past CCR1: the first event is then an update (port I, sample 0) followed by
     * CC1 (port J, sample 0), keeping the two halves of every word from the same period */
    TIM8->CNT = 2;
    stream_setup(S_LO, &GPIO(PORT_I)->IDR, buf_lo, 0u);
    stream_setup(S_HI, &GPIO(PORT_J)->IDR, buf_hi, DMA_CR_TCIE | DMA_CR_TEIE | DMA_CR_DMEIE);
    DMA2->S[S_LO].CR |= DMA_CR_EN;
    DMA2->S[S_HI].CR |= DMA_CR_EN;
    nvic_enable(IRQ_DMA2_STREAM2, 1u);
    TIM8->DIER = TIM_DIER_UDE | TIM_DIER_CC1DE;
    imu_capture_begin(); /* after UG (which TIM5 would count), before the first sample */
    TIM8->CR1 |= TIM_CR1_CEN;
    return 0;
}

void sampler_stop(void *ctx)
{
    (void)ctx;
    TIM8->CR1 &= ~TIM_CR1_CEN;
    TIM8->DIER = 0;
    imu_capture_end();
    nvic_disable(IRQ_DMA2_STREAM2);
    stream_off(S_LO);
    stream_off(S_HI);
}

static void overrun(void)
{
    TIM8->CR1 &= ~TIM_CR1_CEN;
    g_cap->edges.overflow = true;
    g_cap->done = 1u;
}

static uint32_t ct_hi(void)
{
    return (DMA2->S[S_HI].CR & DMA_CR_CT) != 0u ? 1u : 0u;
}

static void isr_body(void)
{
    uint32_t isr = DMA2->LISR;
    uint32_t hi_flags = (isr >> DMA_LISR_SHIFT(S_HI)) & DMA_FLAGS_ALL;
    uint32_t lo_flags = (isr >> DMA_LISR_SHIFT(S_LO)) & DMA_FLAGS_ALL;
    DMA2->LIFCR = (hi_flags << DMA_LISR_SHIFT(S_HI)) | (lo_flags << DMA_LISR_SHIFT(S_LO));
    if (((hi_flags | lo_flags) & (DMA_FLAG_TE | DMA_FLAG_DME)) != 0u) {
        overrun();
        return;
    }
    if ((hi_flags & DMA_FLAG_TC) == 0u) {
        return;
    }
    int half = lhb_halves_begin(&g_halves, ct_hi());
    if (half < 0) {
        g_diag.dma_overruns++;
        overrun();
        return;
    }
    const uint16_t *lo = buf_lo[half];
    const uint16_t *hi = buf_hi[half];
    for (uint32_t i = 0; i < CHUNK; i++) {
        words[i] = ((uint32_t)lo[i] | ((uint32_t)hi[i] << 16)) ^ BOARD_INPUT_INVERT;
    }
    /* a new transfer-complete (or CT back on this half) means the DMA overtook the copy */
    bool again = ((DMA2->LISR >> DMA_LISR_SHIFT(S_HI)) & DMA_FLAG_TC) != 0u ||
                 ct_hi() == (uint32_t)half;
    if (!lhb_halves_end(&g_halves, again)) {
        g_diag.dma_overruns++;
        overrun();
        return;
    }
    if (lhb_capture_feed(g_cap, words, CHUNK)) {
        TIM8->CR1 &= ~TIM_CR1_CEN; /* the main loop calls sampler_stop via the core */
    }
}

void DMA2_Stream2_IRQHandler(void);
void DMA2_Stream2_IRQHandler(void)
{
    uint32_t t0 = cycles_now();
    isr_body();
    uint32_t spent = cycles_now() - t0;
    if (spent > g_diag.isr_cycles_max) {
        g_diag.isr_cycles_max = spent;
    }
}
