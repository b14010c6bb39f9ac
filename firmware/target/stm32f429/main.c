/* Board main loop: link bytes -> protocol core; capture state machine steps; watchdog and
 * status LED. Boot order: cycle counter (for the bounded waits), reset cause and fault
 * record, clock (HSE checked), tick, LED, watchdog, SDRAM and its self-tests, link. */
#include <stdint.h>

#include "board.h"
#include "hw.h"
#include "lhb/config.h"
#include "lhb/crc32.h"
#include "lhb/proto.h"
#include "lhb/txring.h"
#include "regs.h"

#define IMU_STORE_BYTES (2u * 1024u * 1024u) /* 131072 IMU records: 131 s at 1 kHz */
#define MAX_IMU_RECORDS (IMU_STORE_BYTES / LHCAP_IMU_RECORD_LEN)
#define MAX_RECORDS ((BOARD_SDRAM_SIZE - IMU_STORE_BYTES) / 8u)

/* the SDRAM: edge records (2 words each), then IMU records (4 words each) */
static uint32_t record_store[2u * MAX_RECORDS] __attribute__((section(".sdram")));
static uint32_t imu_store[LHB_IMU_WORDS * MAX_IMU_RECORDS] __attribute__((section(".sdram")));
static lhb_capture_t capture;
static lhb_proto_t proto;

static uint32_t board_id(void)
{
    uint32_t uid[3] = {UID_BASE[0], UID_BASE[1], UID_BASE[2]};
    return lhb_crc32(uid, sizeof uid); /* 96-bit unique device ID folded to 32 bits */
}

int main(void)
{
    cycles_init();
    health_boot();
    clock_init();
    systick_init();
    led_init();
    watchdog_start();
    bool sdram_ok = sdram_init();
    uart_init();
    sampler_init(&capture);

    lhcap_header_t t = {0};
    t.version = LHCAP_VERSION_IMU;
    (void)imu_init(&capture, &t); /* no IMU: the header's imu_part says so */
    t.sample_rate = LHB_SAMPLE_RATE_HZ;
    t.board_id = board_id();
    t.fw_version = LHB_FW_VERSION;
    for (int k = 0; k < 32; k++) {
        t.channel_map[k] = (int16_t)k;
    }
    lhb_hw_t hw = {sampler_start, sampler_stop, NULL};
    lhb_capture_init(&capture, &hw, sdram_ok ? record_store : 0, sdram_ok ? MAX_RECORDS : 0u, &t);
    lhb_capture_set_imu(&capture, sdram_ok ? imu_store : 0, sdram_ok ? MAX_IMU_RECORDS : 0u);
    lhb_proto_init(&proto, &capture, LHB_BLOCK_SIZE_DEFAULT, uart_tx, NULL);
    proto.diag = &g_diag;

    for (;;) {
        uint32_t now = millis();
        lhb_link_service(&proto, uart_tx_ring(), uart_rx_pop, now);
        lhb_capture_poll(&capture, now);
        led_update(now);
        watchdog_refresh();
    }
}
