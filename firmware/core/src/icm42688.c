#include "lhb/icm42688.h"

#include <string.h>

#include "lhb/errors.h"

static const struct {
    uint16_t hz;
    uint8_t code;
} ODR[] = {{8000u, 3u}, {4000u, 4u}, {2000u, 5u}, {1000u, 6u}, {500u, 15u},
           {200u, 7u},  {100u, 8u},  {50u, 9u},   {25u, 10u}};

uint8_t lhb_icm42688_odr_code(uint16_t odr_hz)
{
    for (size_t i = 0; i < sizeof ODR / sizeof ODR[0]; i++) {
        if (ODR[i].hz == odr_hz) {
            return ODR[i].code;
        }
    }
    return 0u;
}

static int write_reg(const lhb_spi_t *spi, uint8_t reg, uint8_t value)
{
    uint8_t tx[2] = {reg, value};
    uint8_t rx[2];
    return spi->xfer(spi->ctx, tx, rx, 2) == 0 ? LHB_OK : -LHB_E_HW;
}

static int read_regs(const lhb_spi_t *spi, uint8_t reg, uint8_t *out, size_t n)
{
    uint8_t tx[13] = {0};
    uint8_t rx[13];
    if (n + 1u > sizeof tx) {
        return -LHB_E_ARG;
    }
    tx[0] = (uint8_t)(reg | ICM42688_READ);
    if (spi->xfer(spi->ctx, tx, rx, n + 1u) != 0) {
        return -LHB_E_HW;
    }
    memcpy(out, rx + 1, n);
    return LHB_OK;
}

static int read_reg(const lhb_spi_t *spi, uint8_t reg, uint8_t *value)
{
    return read_regs(spi, reg, value, 1u);
}

int lhb_icm42688_init(lhb_icm42688_t *d, const lhb_spi_t *spi, uint16_t odr_hz)
{
    d->spi = *spi;
    d->odr_hz = 0;
    uint8_t odr = lhb_icm42688_odr_code(odr_hz);
    if (odr == 0u) {
        return -LHB_E_ARG;
    }
    uint8_t who = 0;
    if (write_reg(spi, ICM42688_REG_BANK_SEL, 0u) != LHB_OK ||
        read_reg(spi, ICM42688_WHO_AM_I, &who) != LHB_OK || who != ICM42688_WHO_AM_I_VALUE) {
        return -LHB_E_HW;
    }
    if (write_reg(spi, ICM42688_DEVICE_CONFIG, 0x01u) != LHB_OK) {
        return -LHB_E_HW;
    }
    spi->delay_us(spi->ctx, ICM42688_RESET_US);
    uint8_t status = 0;
    const uint8_t gyro = (uint8_t)((0u << 5) | odr);  /* +-2000 dps */
    const uint8_t accel = (uint8_t)((0u << 5) | odr); /* +-16 g */
    const uint8_t pwr = 0x0Fu;                        /* gyro and accel low-noise */
    /* 100 us pulses and de-assert time below 4 kHz; 8 us and none from 4 kHz (datasheet) */
    const uint8_t int1 = odr_hz >= ICM42688_FAST_ODR_HZ ? 0x60u : 0x00u;
    if (read_reg(spi, ICM42688_INT_STATUS, &status) != LHB_OK || (status & 0x10u) == 0u ||
        write_reg(spi, ICM42688_INT_CONFIG, 0x03u) != LHB_OK ||
        write_reg(spi, ICM42688_INT_CONFIG1, int1) != LHB_OK ||
        write_reg(spi, ICM42688_INT_SOURCE0, 0x08u) != LHB_OK ||
        write_reg(spi, ICM42688_GYRO_CONFIG0, gyro) != LHB_OK ||
        write_reg(spi, ICM42688_ACCEL_CONFIG0, accel) != LHB_OK ||
        write_reg(spi, ICM42688_PWR_MGMT0, pwr) != LHB_OK) {
        return -LHB_E_HW;
    }
    spi->delay_us(spi->ctx, ICM42688_PWR_US);
    uint8_t back[3];
    if (read_regs(spi, ICM42688_PWR_MGMT0, back, 3u) != LHB_OK || back[0] != pwr ||
        back[1] != gyro || back[2] != accel) {
        return -LHB_E_HW;
    }
    spi->delay_us(spi->ctx, ICM42688_GYRO_START_US);
    d->odr_hz = odr_hz;
    return LHB_OK;
}

int lhb_icm42688_read(const lhb_icm42688_t *d, int16_t raw[6])
{
    if (d->odr_hz == 0u) {
        return -LHB_E_STATE;
    }
    uint8_t b[12];
    if (read_regs(&d->spi, ICM42688_ACCEL_DATA_X1, b, sizeof b) != LHB_OK) {
        return -LHB_E_HW;
    }
    for (unsigned k = 0; k < 6; k++) {
        raw[k] = (int16_t)(uint16_t)((b[2 * k] << 8) | b[2 * k + 1]);
    }
    for (unsigned s = 0; s < 2; s++) {
        if (raw[3 * s] == INT16_MIN && raw[3 * s + 1] == INT16_MIN && raw[3 * s + 2] == INT16_MIN) {
            return -LHB_E_STATE;
        }
    }
    return LHB_OK;
}

void lhb_icm42688_describe(const lhb_icm42688_t *d, lhcap_header_t *h)
{
    bool ok = d->odr_hz != 0u;
    h->imu_part = ok ? LHCAP_IMU_ICM42688P : LHCAP_IMU_NONE;
    h->imu_odr_hz = ok ? d->odr_hz : 0u;
    h->imu_gyro_fs_dps = ok ? ICM42688_GYRO_FS_DPS : 0u;
    h->imu_accel_fs_g = ok ? ICM42688_ACCEL_FS_G : 0u;
}
