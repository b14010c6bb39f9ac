/* Board health as STATUS reports it (docs/protocol.md, "STATUS answer, bytes 40.."): boot
 * self-test results, the fault record kept over a reset, and run-time counters. The target
 * fills it; the protocol core only reads it (NULL = nothing to report, e.g. unit tests). */
#ifndef LHB_DIAG_H
#define LHB_DIAG_H

#include <stdint.h>

/* Self-test bits (STATUS u32 at byte 40). */
#define LHB_ST_HSE_FAILED 0x001u      /* HSE did not start: running from HSI (timing +-1 %) */
#define LHB_ST_HSE_MISMATCH 0x002u    /* HSE measured against HSI is not the configured value */
#define LHB_ST_SDRAM_BUS 0x004u       /* SDRAM data- or address-bus walking-ones test failed */
#define LHB_ST_SDRAM_MARCH 0x008u     /* SDRAM March C- test failed */
#define LHB_ST_SDRAM_RETENTION 0x010u /* SDRAM lost data over the retention wait */
#define LHB_ST_FAULT_RECORD 0x020u    /* the last reset followed a fault (record in bytes 48..) */
#define LHB_ST_WATCHDOG_RESET 0x040u  /* the last reset was caused by the independent watchdog */
#define LHB_ST_CLOCK_TIMEOUT 0x080u   /* a clock-tree wait (PLL, over-drive, switch) timed out */
#define LHB_ST_NOT_RUN 0x100u         /* no hardware self-test (virtual board) */
#define LHB_ST_SDRAM_TIMEOUT 0x200u   /* the FMC stayed busy: SDRAM not initialised */
#define LHB_ST_PERIPH_TIMEOUT 0x400u  /* a DMA stream or the watchdog did not answer in time */
#define LHB_ST_IMU_CLOCK 0x800u       /* the IMU stamps' counter missed sampler updates */

typedef struct {
    uint32_t selftest;          /* LHB_ST_* bits */
    uint32_t hse_khz;           /* HSE measured against HSI, kHz (0 = not measured) */
    uint32_t fault_pc;          /* fault record: stacked PC, LR, CFSR, HFSR (0 = none) */
    uint32_t fault_lr;
    uint32_t fault_cfsr;
    uint32_t fault_hfsr;
    uint32_t reset_cause;       /* RCC_CSR bits 31..24 at boot (RM0090 6.3.21) */
    volatile uint32_t dma_overruns;      /* half-buffers lost since boot */
    volatile uint32_t isr_cycles_max;    /* worst DMA interrupt, CPU cycles */
    uint32_t isr_cycles_budget;          /* one half-buffer period, CPU cycles */
    volatile uint32_t tx_dropped;        /* answers dropped because the send ring was full */
} lhb_diag_t;

#endif
