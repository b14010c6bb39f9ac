/* Compiled (not run) by ctest with -DBOARD_HSE_HZ=...: the clock configuration's static
 * checks accept the crystals the PLL can use and refuse the others (tests "hse_*"). */
#include "clock_config.h"

int clock_config_pll_m(void);
int clock_config_pll_m(void)
{
    return (int)BOARD_PLL_M;
}
