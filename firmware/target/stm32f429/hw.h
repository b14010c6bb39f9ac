/* Target drivers (clock, SDRAM, sampler, UART, millisecond tick) and board health. */
#ifndef LHB_HW_H
#define LHB_HW_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "lhb/capture.h"
#include "lhb/diag.h"
#include "lhb/txring.h"

/* Board health reported in STATUS (health.c). */
extern lhb_diag_t g_diag;

/* Cycle counter (DWT CYCCNT) and bounded waits: every wait on a hardware flag gives up
 * after `cycles` CPU cycles and returns false; the caller records the failure in g_diag. */
void cycles_init(void);
uint32_t cycles_now(void);
bool wait_reg(const volatile uint32_t *reg, uint32_t mask, uint32_t value, uint32_t cycles);
void delay_cycles(uint32_t cycles);

/* Reset cause and fault record of the previous run into g_diag; the watchdog; the LED. */
void health_boot(void);
void watchdog_start(void);
void watchdog_refresh(void);
void led_init(void);
void led_update(uint32_t now_ms);

/* 180 MHz from the HSE (or the HSI if the HSE does not start); results in g_diag. */
void clock_init(void);
void systick_init(void);
uint32_t millis(void);

/* Brings the SDRAM up and runs its self-tests (results in g_diag); false if any fails. */
bool sdram_init(void);

void sampler_init(lhb_capture_t *cap);
int sampler_start(void *ctx, uint32_t n_samples);
void sampler_stop(void *ctx);

/* The IMU (imu.c): probes and configures it, fills the template's IMU fields (part NONE
 * when it does not answer); false if there is no working IMU. imu_capture_begin resets the
 * sample-index counter and enables the data-ready interrupt (called by sampler_start just
 * before the sampler runs), imu_capture_end disables it. */
bool imu_init(lhb_capture_t *cap, lhcap_header_t *tmpl);
void imu_capture_begin(void);
void imu_capture_end(void);

void uart_init(void);
bool uart_rx_pop(uint8_t *b);
void uart_tx(void *ctx, const uint8_t *data, size_t n);
const lhb_txring_t *uart_tx_ring(void);

#endif
