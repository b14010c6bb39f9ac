/* Driver of the TDK InvenSense ICM-42688-P 6-axis IMU over SPI (datasheet DS-000347), with no
 * hardware access of its own: the target gives the SPI transfer and a microsecond delay.
 *
 * Configuration: user bank 0; gyro +-2000 deg/s and accelerometer +-16 g, both low-noise
 * mode at the same output data rate; INT1 push-pull, active high, pulsed (100 us) on every
 * new sample (UI data ready). The target time-stamps the INT1 edge on the capture's clock
 * and reads the sample with lhb_icm42688_read() before the next one (1/ODR). */
#ifndef LHB_ICM42688_H
#define LHB_ICM42688_H

#include <stddef.h>
#include <stdint.h>

#include "lhb/lhcap.h"

/* Registers (user bank 0) and values used. */
#define ICM42688_DEVICE_CONFIG 0x11u  /* bit 0: soft reset */
#define ICM42688_INT_CONFIG 0x14u     /* bit 2 INT1 latched, bit 1 push-pull, bit 0 active high */
#define ICM42688_ACCEL_DATA_X1 0x1Fu  /* ax ay az gx gy gz: 12 bytes, big-endian */
#define ICM42688_INT_STATUS 0x2Du     /* read clears; bit 4 RESET_DONE */
#define ICM42688_PWR_MGMT0 0x4Eu      /* bits 3:2 gyro mode, 1:0 accel mode (3 = low noise) */
#define ICM42688_GYRO_CONFIG0 0x4Fu   /* bits 7:5 full scale (0 = 2000 dps), 3:0 ODR */
#define ICM42688_ACCEL_CONFIG0 0x50u  /* bits 7:5 full scale (0 = 16 g), 3:0 ODR */
#define ICM42688_INT_CONFIG1 0x64u    /* bit 6 8 us pulse, bit 5 no de-assert time (both needed
                                       * at >= 4 kHz), bit 4 INT_ASYNC_RESET: must be cleared */
#define ICM42688_FAST_ODR_HZ 4000u    /* from this rate the short pulse is required */
#define ICM42688_INT_SOURCE0 0x65u    /* bit 3 UI_DRDY_INT1_EN */
#define ICM42688_WHO_AM_I 0x75u
#define ICM42688_REG_BANK_SEL 0x76u
#define ICM42688_WHO_AM_I_VALUE 0x47u
#define ICM42688_READ 0x80u           /* first SPI byte: address | this to read */
#define ICM42688_GYRO_FS_DPS 2000u
#define ICM42688_ACCEL_FS_G 16u
#define ICM42688_RESET_US 1000u       /* after a soft reset, before any access */
#define ICM42688_PWR_US 200u          /* after a PWR_MGMT0 write, before any register write */
#define ICM42688_GYRO_START_US 45000u /* gyro start-up before its data are valid */

typedef struct {
    /* one SPI transaction: n bytes out of tx, n bytes into rx, chip select low throughout;
     * returns 0 on success */
    int (*xfer)(void *ctx, const uint8_t *tx, uint8_t *rx, size_t n);
    void (*delay_us)(void *ctx, uint32_t us);
    void *ctx;
} lhb_spi_t;

typedef struct {
    lhb_spi_t spi;
    uint16_t odr_hz; /* 0 until lhb_icm42688_init succeeded */
} lhb_icm42688_t;

/* ODR code of GYRO_CONFIG0/ACCEL_CONFIG0 for a rate (25 Hz .. 8 kHz), 0 if unsupported. */
uint8_t lhb_icm42688_odr_code(uint16_t odr_hz);
/* Checks WHO_AM_I, soft-resets and configures the part, reads the configuration back and
 * waits for the gyro to start. Returns LHB_OK, -LHB_E_ARG (rate not supported) or
 * -LHB_E_HW (no answer, another part, or the configuration did not stick). */
int lhb_icm42688_init(lhb_icm42688_t *d, const lhb_spi_t *spi, uint16_t odr_hz);
/* Reads the latest sample into raw = ax ay az gx gy gz (counts). Returns LHB_OK, -LHB_E_HW
 * (transfer failed) or -LHB_E_STATE (not initialised, or the part flags a sensor's data as
 * not valid: all three axes -32768). */
int lhb_icm42688_read(const lhb_icm42688_t *d, int16_t raw[6]);
/* The .lhcap version-2 IMU fields of an initialised part (imu_part NONE otherwise). */
void lhb_icm42688_describe(const lhb_icm42688_t *d, lhcap_header_t *h);

#endif
