/* Board wiring and clock assumptions (the schematic is not in the repository: change these
 * here if the board differs).
 *
 * - HSE crystal: 8 MHz (BOARD_HSE_HZ). PLL: /M=4 (2 MHz), xN=180 (360 MHz VCO), /P=2 ->
 *   SYSCLK = HCLK = 180 MHz (over-drive on, VOS scale 1, 5 flash wait states);
 *   APB1 = 45 MHz, APB2 = 90 MHz, APB2 timers = 180 MHz; /Q=8 (45 MHz, unused).
 * - Photodiodes: channels 0..15 on GPIOI 0..15, channels 16..31 on GPIOJ 0..15 (the two
 *   16-bit ports free of the SDRAM and USART pins on an LQFP176/BGA176 part). A line is high
 *   while its diode sees light (BOARD_INPUT_INVERT flips bits otherwise).
 * - Sampling: TIM8 at 2 MHz. Its update event drives DMA2 stream 1 (channel 7) reading
 *   GPIOI->IDR; its CC1 event (CCR1 = 1, one 5.6 ns timer tick later) drives DMA2 stream 2
 *   (channel 7) reading GPIOJ->IDR. Both streams run in double-buffer mode.
 * - Link: USART1, PA9 TX, PA10 RX, PA11 CTS, PA12 RTS (AF7), 6 Mbaud exactly
 *   (APB2 90 MHz, OVER8 = 1, USARTDIV = 1.875), to an FT232H with RTS/CTS.
 * - SDRAM: IS42S16320F (4 banks x 8192 rows x 1024 columns x 16 bit = 64 MB) on FMC SDRAM
 *   bank 1 (SDNE0 = PH3, SDCKE0 = PH2, SDNWE = PH5), at 0xC0000000, SDCLK = HCLK/2 = 90 MHz.
 */
#ifndef LHB_BOARD_H
#define LHB_BOARD_H

#define BOARD_HSE_HZ 8000000u
#define BOARD_SYSCLK_HZ 180000000u
#define BOARD_PCLK2_HZ 90000000u
#define BOARD_TIM8_CLK_HZ 180000000u
#define BOARD_SDRAM_BASE 0xC0000000u
#define BOARD_SDRAM_SIZE (64u * 1024u * 1024u)
#define BOARD_INPUT_INVERT 0x00000000u
#define BOARD_UART_BAUD 6000000u

#endif
