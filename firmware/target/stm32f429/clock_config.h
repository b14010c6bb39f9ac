/* PLL settings derived from the HSE crystal frequency (a build setting: CMake -DLHB_HSE_HZ=),
 * with every range RM0090 6.3.2 (RCC_PLLCFGR) and DS9405 (HSE oscillator) impose checked at
 * compile time. The target's VCO is 360 MHz: /P = 2 gives SYSCLK 180 MHz, /Q = 8 gives 45 MHz
 * (the 48 MHz domain is unused). Also compiled on the host by the ctest "hse_*" checks. */
#ifndef LHB_CLOCK_CONFIG_H
#define LHB_CLOCK_CONFIG_H

#include "board.h"

#define PLL_VCO_HZ 360000000u
/* PLL input 2 MHz when the crystal allows it (recommended, least jitter), else 1 MHz */
#ifndef BOARD_PLL_M
#define BOARD_PLL_M (BOARD_HSE_HZ % 2000000u == 0u ? BOARD_HSE_HZ / 2000000u : BOARD_HSE_HZ / 1000000u)
#endif
#define PLL_IN_HZ (BOARD_HSE_HZ / BOARD_PLL_M)
#define PLL_N (PLL_VCO_HZ / PLL_IN_HZ)
#define PLL_P 2u
#define PLL_Q 8u
/* fallback when the HSE does not start: HSI 16 MHz / M to the same PLL input, same N, P, Q */
#define HSI_HZ 16000000u
#define PLL_HSI_M (HSI_HZ / PLL_IN_HZ)
/* RTCPRE: HSE / RTCPRE = 1 MHz feeds TIM11's input for the HSE-against-HSI measurement */
#define HSE_RTCPRE (BOARD_HSE_HZ / 1000000u)

_Static_assert(BOARD_HSE_HZ >= 4000000u && BOARD_HSE_HZ <= 26000000u,
               "HSE crystal must be 4..26 MHz (DS9405, HSE oscillator characteristics)");
_Static_assert(BOARD_PLL_M >= 2u && BOARD_PLL_M <= 63u, "PLLM must be 2..63 (RM0090 6.3.2)");
_Static_assert(PLL_IN_HZ * BOARD_PLL_M == BOARD_HSE_HZ && PLL_IN_HZ >= 1000000u &&
                   PLL_IN_HZ <= 2000000u,
               "PLL input HSE/M must be exactly 1..2 MHz (RM0090 6.3.2; 2 MHz recommended)");
_Static_assert(PLL_N * PLL_IN_HZ == PLL_VCO_HZ && PLL_N >= 50u && PLL_N <= 432u,
               "PLLN must be an integer 50..432 giving the 360 MHz VCO (RM0090 6.3.2)");
_Static_assert(PLL_VCO_HZ >= 100000000u && PLL_VCO_HZ <= 432000000u,
               "VCO output must be 100..432 MHz (RM0090 6.3.2)");
_Static_assert(PLL_VCO_HZ / PLL_P == BOARD_SYSCLK_HZ && BOARD_SYSCLK_HZ <= 180000000u,
               "SYSCLK must be 180 MHz at most (over-drive, DS9405)");
_Static_assert(PLL_VCO_HZ / PLL_Q <= 48000000u && PLL_Q >= 2u && PLL_Q <= 15u,
               "PLL48CK must be 48 MHz at most, PLLQ 2..15 (RM0090 6.3.2)");
_Static_assert(PLL_HSI_M * PLL_IN_HZ == HSI_HZ, "HSI fallback must give the same PLL input");
_Static_assert(HSE_RTCPRE >= 2u && HSE_RTCPRE <= 31u, "RTCPRE must be 2..31 (RM0090 6.3.3)");

#endif
