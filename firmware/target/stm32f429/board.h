/* Board wiring and clock assumptions (the schematic is not in the repository: change these
 * here, or through the CMake settings named below, if the board differs).
 *
 * - MCU: STM32F429BET6 (LQFP208, 512 KB flash, 256 KB RAM of which 64 KB CCM). The ordering
 *   code (DS9405 "Ordering information") reads: B = 208 pins, E = 512 KB flash, T = LQFP,
 *   6 = -40..85 C. Only the 208/216-pin packages bond out all of ports I (PI0..PI15), J and K;
 *   the LQFP176/UFBGA176 parts stop at PI11 and have no port J, the LQFP144 part has no
 *   ports H (beyond PH0/PH1), I, J. Sampling 32 lines from GPIOI and GPIOJ, and the FMC's
 *   SDNE0/SDCKE0/SDNWE on PH3/PH2/PH5, therefore need this 208-pin part.
 * - HSE crystal: BOARD_HSE_HZ (CMake LHB_HSE_HZ, default 8 MHz). The PLL is derived from it
 *   and range-checked at compile time (clock_config.h): input 2 MHz (or 1 MHz), VCO 360 MHz,
 *   /P=2 -> SYSCLK = HCLK = 180 MHz (over-drive on, VOS scale 1, 5 flash wait states);
 *   APB1 = 45 MHz, APB2 = 90 MHz, APB2 timers = 180 MHz; /Q=8 (45 MHz, unused). At boot the
 *   HSE is measured against the HSI (TIM11, STATUS byte 44); if it does not start the board
 *   runs from the HSI (timing within ~1 %) and says so in STATUS.
 * - Photodiodes: channels 0..15 on GPIOI 0..15, channels 16..31 on GPIOJ 0..15 (the two
 *   16-bit ports free of the SDRAM and USART pins). A line is high while its diode sees light
 *   (BOARD_INPUT_INVERT flips bits otherwise).
 * - Sampling: TIM8 at 2 MHz. Its update event drives DMA2 stream 1 (channel 7) reading
 *   GPIOI->IDR; its CC1 event (CCR1 = 1, one 5.6 ns timer tick later) drives DMA2 stream 2
 *   (channel 7) reading GPIOJ->IDR. Both streams run in double-buffer mode.
 * - Link: USART1, PA9 TX, PA10 RX, PA11 CTS, PA12 RTS (AF7), 6 Mbaud exactly
 *   (APB2 90 MHz, OVER8 = 1, USARTDIV = 1.875), to an FT232H with RTS/CTS.
 * - SDRAM: IS42S16320F (4 banks x 8192 rows x 1024 columns x 16 bit = 64 MB) on FMC SDRAM
 *   bank 1 (SDNE0 = PH3, SDCKE0 = PH2, SDNWE = PH5), at 0xC0000000, SDCLK = HCLK/2 = 90 MHz.
 * - IMU: ICM-42688-P on SPI1 (PA5 SCK, PA6 MISO, PA7 MOSI, AF5; chip select PA4), INT1 on
 *   PA0 = TIM5_CH1 (AF2); output data rate BOARD_IMU_ODR_HZ (CMake LHB_IMU_ODR_HZ, default
 *   1000). Its axes are taken as the board frame's (docs/formats/lhcap.md); a board that
 *   mounts it otherwise states the rotation in its board TOML or lets the solve estimate it.
 * - Status LED: BOARD_LED_PORT / BOARD_LED_PIN (CMake LHB_LED_PORT, LHB_LED_PIN,
 *   LHB_LED_ACTIVE_LOW; default PG13, active high), push-pull output. Patterns: see health.c.
 */
#ifndef LHB_BOARD_H
#define LHB_BOARD_H

#ifndef BOARD_HSE_HZ
#define BOARD_HSE_HZ 8000000u
#endif
#define BOARD_SYSCLK_HZ 180000000u
#define BOARD_PCLK2_HZ 90000000u
#define BOARD_TIM8_CLK_HZ 180000000u
#define BOARD_SDRAM_BASE 0xC0000000u
#define BOARD_SDRAM_SIZE (64u * 1024u * 1024u)
#define BOARD_INPUT_INVERT 0x00000000u
#define BOARD_UART_BAUD 6000000u
#ifndef BOARD_IMU_ODR_HZ
#define BOARD_IMU_ODR_HZ 1000u
#endif
#ifndef BOARD_LED_PORT
#define BOARD_LED_PORT PORT_G
#endif
#ifndef BOARD_LED_PIN
#define BOARD_LED_PIN 13u
#endif
#ifndef BOARD_LED_ACTIVE_LOW
#define BOARD_LED_ACTIVE_LOW 0
#endif

#endif
