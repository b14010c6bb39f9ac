/* The board's IMU: an ICM-42688-P on SPI1, its data-ready line time-stamped on the capture's
 * clock.
 *
 * Wiring (board.h): SPI1 PA5 SCK, PA6 MISO, PA7 MOSI (AF5), chip select PA4 (output), the
 * IMU's INT1 on PA0 = TIM5_CH1 (AF2). SPI mode 3 at 90 MHz / 8 = 11.25 MHz (the part allows
 * 24 MHz).
 *
 * Time stamps: TIM8 (the 2 MHz sampler) puts its update event on TRGO; TIM5 counts those
 * events (external clock mode 1 on ITR3), so TIM5's counter is the sample index. It is reset
 * to 0 between TIM8's UG and its enable (imu_capture_begin, from sampler_start). INT1's
 * rising edge latches the counter in TIM5_CCR1: the index of the first sample taken after
 * the IMU's data-ready, the same convention as an edge record. The capture interrupt (below
 * the DMA interrupt's priority, so it can wait for it: the part keeps a sample for 1/ODR)
 * reads the sample in one 13-byte SPI burst (~10 us) and appends it to the capture; an
 * over-capture (an edge while the last was not served), a failed transfer or a sample the
 * part flags as not valid is counted as missed (the file's imu_missed). */
#include <stdint.h>

#include "board.h"
#include "hw.h"
#include "lhb/errors.h"
#include "lhb/icm42688.h"
#include "regs.h"

#define CS_PIN 4u
#define SPI_WAIT_CYCLES (BOARD_SYSCLK_HZ / 100000u) /* 10 us per byte at most */

static lhb_capture_t *g_cap;
static lhb_icm42688_t g_icm;

static void pin_af(uint32_t n, uint32_t af)
{
    gpio_t *g = GPIO(PORT_A);
    g->MODER = (g->MODER & ~(3u << (2u * n))) | (2u << (2u * n));
    g->OSPEEDR |= 3u << (2u * n);
    g->AFR[n >> 3] = (g->AFR[n >> 3] & ~(0xFu << (4u * (n & 7u)))) | (af << (4u * (n & 7u)));
}

static int spi_xfer(void *ctx, const uint8_t *tx, uint8_t *rx, size_t n)
{
    (void)ctx;
    int rc = 0;
    GPIO(PORT_A)->BSRR = 1u << (CS_PIN + 16u); /* select */
    for (size_t i = 0; i < n && rc == 0; i++) {
        if (!wait_reg(&SPI1->SR, SPI_SR_TXE, SPI_SR_TXE, SPI_WAIT_CYCLES)) {
            rc = -1;
            break;
        }
        SPI1->DR = tx[i];
        if (!wait_reg(&SPI1->SR, SPI_SR_RXNE, SPI_SR_RXNE, SPI_WAIT_CYCLES)) {
            rc = -1;
            break;
        }
        rx[i] = (uint8_t)SPI1->DR;
    }
    if (!wait_reg(&SPI1->SR, SPI_SR_BSY, 0u, SPI_WAIT_CYCLES)) {
        rc = -1;
    }
    GPIO(PORT_A)->BSRR = 1u << CS_PIN; /* deselect */
    (void)SPI1->DR;                    /* drop a byte left by a failed transfer */
    if (rc != 0) {
        g_diag.selftest |= LHB_ST_PERIPH_TIMEOUT;
    }
    return rc;
}

static void spi_delay_us(void *ctx, uint32_t us)
{
    (void)ctx;
    delay_cycles(us * (BOARD_SYSCLK_HZ / 1000000u));
}

bool imu_init(lhb_capture_t *cap, lhcap_header_t *tmpl)
{
    g_cap = cap;
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIO(PORT_A);
    RCC->APB1ENR |= RCC_APB1ENR_TIM5EN;
    RCC->APB2ENR |= RCC_APB2ENR_SPI1EN;
    (void)RCC->APB2ENR;
    gpio_t *a = GPIO(PORT_A);
    a->BSRR = 1u << CS_PIN; /* chip select high before it becomes an output */
    a->MODER = (a->MODER & ~(3u << (2u * CS_PIN))) | (1u << (2u * CS_PIN));
    a->OSPEEDR |= 3u << (2u * CS_PIN);
    pin_af(5u, 5u);
    pin_af(6u, 5u);
    pin_af(7u, 5u);
    pin_af(0u, 2u);
    SPI1->CR1 = SPI_CR1_MSTR | SPI_CR1_SSM | SPI_CR1_SSI | SPI_CR1_BR_DIV8 | SPI_CR1_CPOL |
                SPI_CR1_CPHA;
    SPI1->CR2 = 0;
    SPI1->CR1 |= SPI_CR1_SPE;

    /* TIM5 counts the sampler's updates; CH1 captures INT1's rising edge */
    TIM5->CR1 = 0;
    TIM5->SMCR = TIM_SMCR_TS_ITR3; /* TS first, then the slave mode (RM0090 18.3.14) */
    TIM5->SMCR = TIM_SMCR_TS_ITR3 | TIM_SMCR_SMS_EXT1;
    TIM5->PSC = 0;
    TIM5->ARR = 0xFFFFFFFFu;
    TIM5->CCMR1 = TIM_CCMR1_CC1S_TI1;
    TIM5->CCER = TIM_CCER_CC1E;
    TIM5->EGR = TIM_EGR_UG;
    TIM5->SR = 0;
    TIM5->CR1 = TIM_CR1_CEN; /* counts only while TIM8 runs */

    lhb_spi_t spi = {spi_xfer, spi_delay_us, NULL};
    int rc = lhb_icm42688_init(&g_icm, &spi, BOARD_IMU_ODR_HZ);
    lhb_icm42688_describe(&g_icm, tmpl);
    return rc == LHB_OK;
}

void imu_capture_begin(void)
{
    TIM5->CNT = 0;
    TIM5->SR = 0;
    if (g_icm.odr_hz != 0u) {
        TIM5->DIER = TIM_DIER_CC1IE;
        nvic_enable(IRQ_TIM5, 2u); /* below the DMA interrupt (1) */
    }
}

void imu_capture_end(void)
{
    TIM5->DIER = 0;
    nvic_disable(IRQ_TIM5);
    /* TIM5 must have counted every sampler update (TRGO is one 180 MHz tick wide, TIM5
     * samples it at 90 MHz: RM0090 does not promise it never misses one); if it counted
     * fewer than the samples taken, the stamps are wrong: say so (STATUS self-test bit)
     * rather than record them silently. (More is normal: the sampler runs on until its
     * interrupt stops it.) */
    uint32_t counted = TIM5->CNT;
    uint32_t taken = g_cap != NULL ? g_cap->samples_done : 0u;
    if (g_cap != NULL && g_icm.odr_hz != 0u && counted + 1u < taken) {
        g_diag.selftest |= LHB_ST_IMU_CLOCK;
    }
}

void TIM5_IRQHandler(void);
void TIM5_IRQHandler(void)
{
    uint32_t sr = TIM5->SR;
    uint32_t index = TIM5->CCR1; /* reading CCR1 clears CC1IF */
    TIM5->SR = ~(sr & TIM_SR_CC1OF);
    if ((sr & TIM_SR_CC1OF) != 0u) {
        lhb_capture_imu_missed(g_cap); /* an edge came before the last one was served */
    }
    int16_t raw[6];
    if (lhb_icm42688_read(&g_icm, raw) != LHB_OK) {
        lhb_capture_imu_missed(g_cap);
        return;
    }
    /* a new data-ready while reading (the DMA interrupt may pre-empt this one): the bytes
     * read may be the next sample's, not this stamp's; drop them (the next edge's interrupt
     * is pending and reads it) */
    if ((TIM5->SR & (TIM_SR_CC1IF | TIM_SR_CC1OF)) != 0u) {
        lhb_capture_imu_missed(g_cap);
        return;
    }
    (void)lhb_capture_add_imu(g_cap, index, raw); /* not capturing: ignored */
}
