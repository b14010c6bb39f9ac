/* Board side of the link protocol (docs/protocol.md): decodes request frames, runs them
 * against the capture state machine and emits response frames through a callback. */
#ifndef LHB_PROTO_H
#define LHB_PROTO_H

#include <stddef.h>
#include <stdint.h>

#include "lhb/capture.h"
#include "lhb/cobs.h"
#include "lhb/config.h"
#include "lhb/diag.h"

typedef void (*lhb_tx_fn)(void *ctx, const uint8_t *data, size_t n);

/* Payload sizes of the fixed-size messages. */
#define LHB_INFO_LEN 28u
#define LHB_STATUS_LEN_V1 40u /* the first firmware's STATUS; the health fields follow */
#define LHB_STATUS_LEN_HEALTH 92u /* + the health fields; the IMU fields follow */
#define LHB_STATUS_LEN 104u
#define LHB_ARM_LEN 16u
#define LHB_ARM_LEN_FLAGS 20u /* ARM + u32 flags */
#define LHB_ARM_DISCARD 0x1u  /* ARM flag: drop a capture that was not downloaded */

/* A frame whose bytes stop arriving for this long is discarded (counted). At 6 Mbaud a
 * whole request takes < 0.1 ms; the margin covers USB scheduling on the PC. */
#define LHB_FRAME_TIMEOUT_MS 100u
/* Blocks whose first READ is tracked: a whole 64 MiB image at the default block size. */
#define LHB_READ_MAP_BITS 16392u
#define LHB_READ_REQ_LEN 4u
#define LHB_ERROR_LEN 4u

typedef struct {
    lhb_capture_t *cap;
    uint32_t block_size;
    uint32_t max_records;
    lhb_tx_fn tx;
    void *tx_ctx;
    lhb_cobs_dec_t dec;
    uint8_t rx_raw[LHB_REQ_RAW_MAX];
    uint8_t payload[LHB_RESP_PAYLOAD_MAX];
    uint8_t wire[LHB_WIRE_MAX(LHB_RESP_RAW_MAX)];
    const lhb_diag_t *diag; /* board health for STATUS (NULL: reported as zeros) */
    uint32_t last_rx_ms;    /* tick of the last received byte */
    /* blocks of the READY capture sent at least once (a capture is "downloaded" when every
     * block was; blocks past LHB_READ_MAP_BITS are not tracked) */
    uint8_t read_map[(LHB_READ_MAP_BITS + 7u) / 8u];
    uint32_t blocks_read;
    /* counters (diagnostics, and the virtual board's fault injection) */
    uint32_t frames_ok;
    uint32_t frames_bad;
    uint32_t blocks_sent;
    uint32_t frames_timed_out; /* partial frames discarded after LHB_FRAME_TIMEOUT_MS */
} lhb_proto_t;

/* block_size: 1..LHB_BLOCK_SIZE_MAX (clamped). */
void lhb_proto_init(lhb_proto_t *p, lhb_capture_t *cap, uint32_t block_size, lhb_tx_fn tx,
                    void *tx_ctx);
/* READY capture blocks no READ has been answered for yet (0 outside READY). */
uint32_t lhb_proto_blocks_unread(const lhb_proto_t *p);
/* Feeds received bytes; complete frames are handled at once (responses sent via tx). */
void lhb_proto_rx(lhb_proto_t *p, const uint8_t *data, size_t n, uint32_t now_ms);
/* Handles one decoded frame (exposed for tests and the fuzzer). */
void lhb_proto_handle(lhb_proto_t *p, const uint8_t *raw, size_t n, uint32_t now_ms);

#endif
