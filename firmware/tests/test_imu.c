/* ICM-42688-P driver against a model of the part's SPI register file (auto-incrementing
 * reads, soft reset to the datasheet's reset values, timing rules checked). */
#include <string.h>

#include "check.h"
#include "lhb/errors.h"
#include "lhb/icm42688.h"

/* The part as the datasheet (TDK DS-000347, user bank 0) gives it, written out here rather
 * than taken from the driver's header, so that a wrong address or wait in the driver
 * cannot pass by being wrong in the model too. */
#define DS_DEVICE_CONFIG 0x11u
#define DS_INT_CONFIG 0x14u
#define DS_ACCEL_DATA_X1 0x1Fu
#define DS_INT_STATUS 0x2Du
#define DS_PWR_MGMT0 0x4Eu
#define DS_GYRO_CONFIG0 0x4Fu
#define DS_ACCEL_CONFIG0 0x50u
#define DS_INT_CONFIG1 0x64u
#define DS_INT_SOURCE0 0x65u
#define DS_WHO_AM_I 0x75u
#define DS_REG_BANK_SEL 0x76u
#define DS_WHO_AM_I_VALUE 0x47u
#define DS_READ 0x80u
#define DS_RESET_US 1000u
#define DS_PWR_US 200u
#define DS_GYRO_START_US 45000u

typedef struct {
    uint8_t reg[128];
    uint64_t now_us;
    uint64_t reset_at_us;   /* last soft reset */
    uint64_t pwr_at_us;     /* last PWR_MGMT0 write */
    uint64_t pwr_on_us;     /* when the gyro was turned on (low-noise) */
    int violations;         /* accesses breaking the datasheet's waits */
    int fail_xfer;          /* fail the transfer with this number (1 = first), 0 = never */
    int xfers;
    uint8_t who_am_i;
    int no_reset_done;      /* the reset never reports RESET_DONE */
    int pwr_stuck;          /* PWR_MGMT0 writes are lost */
} fake_icm_t;

static void fake_reset(fake_icm_t *f)
{
    memset(f->reg, 0, sizeof f->reg);
    for (unsigned a = DS_ACCEL_DATA_X1; a <= DS_ACCEL_DATA_X1 + 11u; a += 2u) {
        f->reg[a] = 0x80u; /* sensors off: -32768 */
    }
    f->reg[DS_INT_STATUS] = f->no_reset_done ? 0u : 0x10u; /* RESET_DONE */
    f->reg[DS_GYRO_CONFIG0] = 0x06u;
    f->reg[DS_ACCEL_CONFIG0] = 0x06u;
    f->reg[DS_INT_CONFIG1] = 0x10u;
    f->reg[DS_INT_SOURCE0] = 0x10u;
    f->reg[DS_WHO_AM_I] = f->who_am_i;
}

static int fake_xfer(void *ctx, const uint8_t *tx, uint8_t *rx, size_t n)
{
    fake_icm_t *f = ctx;
    if (++f->xfers == f->fail_xfer) {
        return -1;
    }
    if (f->now_us < f->reset_at_us + DS_RESET_US) {
        f->violations++;
    }
    uint8_t addr = tx[0] & 0x7Fu;
    rx[0] = 0xFFu;
    if (tx[0] & DS_READ) {
        for (size_t i = 1; i < n; i++) {
            uint8_t a = (uint8_t)((addr + i - 1u) & 0x7Fu);
            rx[i] = f->reg[a];
            if (a == DS_INT_STATUS) {
                f->reg[a] = 0; /* read clears */
            }
        }
        return 0;
    }
    if (f->now_us < f->pwr_at_us + DS_PWR_US) {
        f->violations++;
    }
    for (size_t i = 1; i < n; i++) {
        uint8_t a = (uint8_t)((addr + i - 1u) & 0x7Fu);
        if (a == DS_DEVICE_CONFIG && (tx[i] & 1u)) {
            fake_reset(f);
            f->reset_at_us = f->now_us;
            continue;
        }
        if (a == DS_WHO_AM_I || a == DS_INT_STATUS ||
            (a == DS_PWR_MGMT0 && f->pwr_stuck)) {
            continue; /* read-only, or a write the part loses */
        }
        f->reg[a] = tx[i];
        if (a == DS_PWR_MGMT0) {
            f->pwr_at_us = f->now_us;
            f->pwr_on_us = f->now_us;
        }
    }
    return 0;
}

static void fake_delay(void *ctx, uint32_t us)
{
    ((fake_icm_t *)ctx)->now_us += us;
}

static void fake_init(fake_icm_t *f)
{
    memset(f, 0, sizeof *f);
    f->who_am_i = DS_WHO_AM_I_VALUE;
    fake_reset(f);
    f->reg[DS_GYRO_CONFIG0] = 0x2Bu; /* a state left over before the soft reset */
    f->reset_at_us = 0;
    f->now_us = 5000;
    f->pwr_at_us = 0;
}

static void set_sample(fake_icm_t *f, const int16_t v[6])
{
    for (unsigned k = 0; k < 6; k++) {
        f->reg[DS_ACCEL_DATA_X1 + 2 * k] = (uint8_t)((uint16_t)v[k] >> 8);
        f->reg[DS_ACCEL_DATA_X1 + 2 * k + 1] = (uint8_t)v[k];
    }
}

int main(void)
{
    CHECK_EQ(lhb_icm42688_odr_code(1000), 6);
    CHECK_EQ(lhb_icm42688_odr_code(500), 15);
    CHECK_EQ(lhb_icm42688_odr_code(8000), 3);
    CHECK_EQ(lhb_icm42688_odr_code(25), 10);
    CHECK_EQ(lhb_icm42688_odr_code(999), 0);

    fake_icm_t f;
    fake_init(&f);
    lhb_spi_t spi = {fake_xfer, fake_delay, &f};
    lhb_icm42688_t d;
    int16_t raw[6];
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1234), -LHB_E_ARG);
    CHECK_EQ(d.odr_hz, 0);
    CHECK_EQ(lhb_icm42688_read(&d, raw), -LHB_E_STATE);

    /* a good part: configured as documented, waits respected, gyro started */
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), LHB_OK);
    CHECK_EQ(f.violations, 0);
    CHECK_EQ(f.reg[DS_REG_BANK_SEL], 0);
    CHECK_EQ(f.reg[DS_PWR_MGMT0], 0x0F);
    CHECK_EQ(f.reg[DS_GYRO_CONFIG0], 0x06);  /* 2000 dps, 1 kHz */
    CHECK_EQ(f.reg[DS_ACCEL_CONFIG0], 0x06); /* 16 g, 1 kHz */
    CHECK_EQ(f.reg[DS_INT_CONFIG], 0x03);    /* pulsed, push-pull, active high */
    CHECK_EQ(f.reg[DS_INT_CONFIG1], 0x00);   /* INT_ASYNC_RESET cleared */
    CHECK_EQ(f.reg[DS_INT_SOURCE0], 0x08);   /* data ready on INT1 */
    CHECK(f.now_us >= f.pwr_on_us + DS_GYRO_START_US);
    CHECK_EQ(d.odr_hz, 1000);
    lhcap_header_t h = {0};
    lhb_icm42688_describe(&d, &h);
    CHECK_EQ(h.imu_part, LHCAP_IMU_ICM42688P);
    CHECK_EQ(h.imu_odr_hz, 1000);
    CHECK_EQ(h.imu_gyro_fs_dps, 2000);
    CHECK_EQ(h.imu_accel_fs_g, 16);

    /* samples: big-endian registers ax ay az gx gy gz, one burst */
    const int16_t v[6] = {2048, -2048, 16384, -1, 32767, -32768};
    set_sample(&f, v);
    int before = f.xfers;
    CHECK_EQ(lhb_icm42688_read(&d, raw), LHB_OK);
    CHECK_EQ(f.xfers, before + 1);
    for (unsigned k = 0; k < 6; k++) {
        CHECK_EQ(raw[k], v[k]);
    }
    const int16_t off[6] = {1, 2, 3, -32768, -32768, -32768}; /* gyro not ready */
    set_sample(&f, off);
    CHECK_EQ(lhb_icm42688_read(&d, raw), -LHB_E_STATE);
    f.fail_xfer = f.xfers + 1;
    CHECK_EQ(lhb_icm42688_read(&d, raw), -LHB_E_HW);

    /* another part, no part (MISO high), failed transfers, a configuration that does not
     * stick: -LHB_E_HW and the header says no IMU */
    fake_init(&f);
    f.who_am_i = 0x6Fu;
    fake_reset(&f);
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), -LHB_E_HW);
    lhb_icm42688_describe(&d, &h);
    CHECK_EQ(h.imu_part, LHCAP_IMU_NONE);
    CHECK_EQ(h.imu_odr_hz, 0);
    fake_init(&f);
    f.who_am_i = 0xFFu;
    fake_reset(&f);
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), -LHB_E_HW);
    for (int fail = 1; fail <= 11; fail++) {
        fake_init(&f);
        f.fail_xfer = fail;
        CHECK_EQ(lhb_icm42688_init(&d, &spi, 200), -LHB_E_HW);
        CHECK_EQ(d.odr_hz, 0);
    }
    fake_init(&f);
    f.fail_xfer = 12; /* 11 transfers in all: a 12th never comes */
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 200), LHB_OK);
    CHECK_EQ(f.reg[DS_GYRO_CONFIG0], 0x07);
    CHECK_EQ(f.reg[0x64], 0x00); /* 100 us pulses below 4 kHz */
    /* from 4 kHz the datasheet needs 8 us pulses without de-assert time (INT_CONFIG1) */
    fake_init(&f);
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 8000), LHB_OK);
    CHECK_EQ(f.reg[0x64], 0x60);
    CHECK_EQ(f.reg[0x4F], 0x03);
    /* a part that never reports RESET_DONE, and one whose configuration does not stick */
    fake_init(&f);
    f.no_reset_done = 1;
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), -LHB_E_HW);
    fake_init(&f);
    f.pwr_stuck = 1;
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), -LHB_E_HW);
    CHECK_EQ(d.odr_hz, 0);
    /* accelerometer data flagged not valid (all -32768) is refused too */
    fake_init(&f);
    CHECK_EQ(lhb_icm42688_init(&d, &spi, 1000), LHB_OK);
    const int16_t acc_off[6] = {-32768, -32768, -32768, 1, 2, 3};
    set_sample(&f, acc_off);
    CHECK_EQ(lhb_icm42688_read(&d, raw), -LHB_E_STATE);
    return check_result("imu");
}
