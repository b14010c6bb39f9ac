/* Target drivers (clock, SDRAM, sampler, UART, millisecond tick). */
#ifndef LHB_HW_H
#define LHB_HW_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "lhb/capture.h"

void clock_init(void);
void systick_init(void);
uint32_t millis(void);

/* Brings the SDRAM up and runs a short pattern test; false if it fails. */
bool sdram_init(void);

void sampler_init(lhb_capture_t *cap);
int sampler_start(void *ctx, uint32_t n_samples);
void sampler_stop(void *ctx);

void uart_init(void);
bool uart_rx_pop(uint8_t *b);
void uart_tx(void *ctx, const uint8_t *data, size_t n);

#endif
