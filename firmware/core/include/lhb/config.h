/* Build-time constants shared by the board core, the target and the host tools. */
#ifndef LHB_CONFIG_H
#define LHB_CONFIG_H

#define LHB_PROTOCOL_VERSION 1u
/* firmware version: major << 16 | minor << 8 | patch */
#define LHB_FW_VERSION ((0u << 16) | (1u << 8) | 0u)
#define LHB_SAMPLE_RATE_HZ 2000000u

/* Largest READ block the core serves (the block size in use is reported by INFO/STATUS). */
#define LHB_BLOCK_SIZE_MAX 4096u
#define LHB_BLOCK_SIZE_DEFAULT 4096u
/* ARM limits: capture duration (ms) and start delay (ms). 60 s at 2 MHz = 1.2e8 samples,
 * well inside the u32 sample index of the .lhcap records. */
#define LHB_MAX_DURATION_MS 60000u
#define LHB_MAX_DELAY_MS 60000u

/* Frame = type u8, seq u8, payload length u16, payload, CRC-32 u32; then COBS + 0x00. */
#define LHB_FRAME_HDR_LEN 4u
#define LHB_FRAME_CRC_LEN 4u
#define LHB_FRAME_OVERHEAD (LHB_FRAME_HDR_LEN + LHB_FRAME_CRC_LEN)
/* Requests carry at most 16 payload bytes (ARM); the board accepts up to 32. */
#define LHB_REQ_PAYLOAD_MAX 32u
#define LHB_REQ_RAW_MAX (LHB_REQ_PAYLOAD_MAX + LHB_FRAME_OVERHEAD)
/* Largest response: READ = u32 index + one block. */
#define LHB_RESP_PAYLOAD_MAX (4u + LHB_BLOCK_SIZE_MAX)
#define LHB_RESP_RAW_MAX (LHB_RESP_PAYLOAD_MAX + LHB_FRAME_OVERHEAD)

/* Worst-case COBS size of n bytes, not counting the 0x00 delimiter. */
#define LHB_COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)
#define LHB_WIRE_MAX(raw) (LHB_COBS_MAX_ENCODED(raw) + 1u)

#endif
