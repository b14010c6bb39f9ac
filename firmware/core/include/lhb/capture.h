/* Capture state machine: IDLE -> (ARM) -> ARMED -> (start delay over) -> CAPTURING ->
 * (all samples taken, or storage full) -> finalising -> READY. ABORT returns to IDLE from any
 * state; ARM is also accepted in READY (the old capture is dropped).
 *
 * Threading on the target: lhb_capture_feed() runs in the DMA interrupt, lhb_capture_add_imu()
 * in the IMU's data-ready interrupt, everything else in the main loop (the lowest priority,
 * so an interrupt's append is complete before the main loop finalises). The fields the
 * interrupts write are 32-bit and read atomically.
 *
 * A template of version 2 (LHCAP_VERSION_IMU) makes a version-2 image: the edge records,
 * then the IMU records added while capturing (lhb_capture_set_imu gives their store). */
#ifndef LHB_CAPTURE_H
#define LHB_CAPTURE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "lhb/lhcap.h"

typedef enum {
    LHB_STATE_IDLE = 0,
    LHB_STATE_ARMED = 1,
    LHB_STATE_CAPTURING = 2,
    LHB_STATE_READY = 3,
} lhb_state_t;

/* Hardware hooks. start: begin sampling (samples then arrive through lhb_capture_feed);
 * returns 0 on success. stop: stop sampling (idempotent, also called after an abort). */
typedef struct {
    int (*start)(void *ctx, uint32_t n_samples);
    void (*stop)(void *ctx);
    void *ctx;
} lhb_hw_t;

typedef struct {
    lhb_hw_t hw;
    lhcap_header_t tmpl;      /* sample rate, board id, fw version, channel map, extra flags */
    uint32_t fixed_samples;   /* != 0: capture exactly this many samples (virtual board) */
    bool fixed_start_time;    /* true: keep tmpl.start_time_us (virtual board) */
    uint32_t finalise_step;   /* records to CRC per poll while finalising (init: LHB_FINALISE_STEP;
                                 tests set it small to hand the CRC across many polls) */

    volatile uint32_t state;  /* lhb_state_t */
    uint32_t duration_ms;
    uint32_t delay_ms;
    uint32_t arm_ms;          /* millisecond tick when ARM arrived */
    uint64_t host_time_us;    /* host clock at ARM (0 = unknown) */
    uint32_t target;          /* samples to capture */
    volatile uint32_t samples_done;
    volatile uint32_t done;   /* set by feed when the capture is complete */
    uint32_t hw_error;        /* hw.start failed: back to IDLE with this set */
    lhb_edges_t edges;
    lhb_imu_log_t imu;

    /* finalising: header, then CRC over the edge records and then the IMU records in steps */
    uint8_t header[LHCAP_HEADER_LEN_IMU];
    uint32_t header_len;      /* of the current image */
    uint32_t crc;
    uint32_t crc_next;        /* next record to add to the CRC: edges, then IMU records */
    bool finalising;
    uint32_t image_size;      /* valid in READY */
    uint32_t image_crc;       /* valid in READY: the trailer value */
    uint32_t flags;           /* lhcap flags of the current capture */
} lhb_capture_t;

/* Records to CRC per lhb_capture_poll() call while finalising (the default of
 * lhb_capture_t.finalise_step). */
#define LHB_FINALISE_STEP 8192u

void lhb_capture_init(lhb_capture_t *c, const lhb_hw_t *hw, uint32_t *storage,
                      uint32_t storage_records, const lhcap_header_t *tmpl);
/* The IMU record store (LHB_IMU_WORDS words per record); without one, IMU samples are
 * counted as missed. Call after init, before ARM. */
void lhb_capture_set_imu(lhb_capture_t *c, uint32_t *storage, uint32_t storage_records);
/* Returns LHB_OK, -LHB_E_ARG (duration/delay out of range) or -LHB_E_STATE (busy). */
int lhb_capture_arm(lhb_capture_t *c, uint32_t duration_ms, uint32_t delay_ms,
                    uint64_t host_time_us, uint32_t now_ms);
void lhb_capture_abort(lhb_capture_t *c);
/* Feeds consecutive port words; returns true once no more samples are wanted. */
bool lhb_capture_feed(lhb_capture_t *c, const uint32_t *samples, size_t n);
/* One IMU sample (raw = ax ay az gx gy gz counts) whose data-ready came at `sample_index`;
 * kept while capturing (also after the last sample was taken, until finalising) and when
 * before the capture's end (records past the samples taken are dropped at finalising). Returns LHB_OK, -LHB_E_STATE
 * (not capturing: ignored) or -LHB_E_RANGE (not recorded: counted as missed). */
int lhb_capture_add_imu(lhb_capture_t *c, uint32_t sample_index, const int16_t raw[6]);
/* The IMU driver lost a sample while capturing (counted in the header's imu_missed). */
void lhb_capture_imu_missed(lhb_capture_t *c);
/* Main-loop step: starts the capture when the delay is over, finalises when done. */
void lhb_capture_poll(lhb_capture_t *c, uint32_t now_ms);
/* ms left before sampling starts (ARMED), else 0. */
uint32_t lhb_capture_delay_left(const lhb_capture_t *c, uint32_t now_ms);
/* Copies image bytes [offset, offset+len) (header, records, CRC trailer) in READY.
 * Returns LHB_OK, -LHB_E_STATE or -LHB_E_RANGE. */
int lhb_capture_read(const lhb_capture_t *c, uint32_t offset, uint8_t *dst, uint32_t len);

#endif
