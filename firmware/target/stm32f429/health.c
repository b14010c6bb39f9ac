/* Board health: cycle counter and bounded waits, reset cause, the fault record kept over a
 * reset, the independent watchdog and the status LED.
 *
 * Fault record: HardFault, MemManage, BusFault, UsageFault, NMI and any unexpected interrupt
 * go to fault_entry, which stores the stacked PC and LR (PM0214 2.3.7, exception frame),
 * CFSR and HFSR (PM0214 4.3.10/4.3.11) and the exception number in a RAM section the reset
 * handler does not clear (.noinit), lights the LED and resets the chip. At the next boot
 * health_boot() moves a valid record into g_diag (STATUS bytes 48..63, self-test bit
 * LHB_ST_FAULT_RECORD) and clears it.
 *
 * Watchdog: IWDG from the LSI (~32 kHz, 17..47 kHz per DS9405) / 64, reload 1000: ~2 s
 * (1.4..3.8 s); refreshed by the main loop; stopped while a debugger halts the core.
 *
 * LED patterns (1 s period): heartbeat (one 100 ms flash) = all self-tests passed; two
 * flashes = the last reset followed a fault or the watchdog; blinking at 2 Hz = a self-test
 * failed (STATUS byte 40 says which); steady on = in the fault handler, about to reset. */
#include "board.h"
#include "hw.h"
#include "regs.h"

lhb_diag_t g_diag;

#define FAULT_MAGIC 0xFA017EC0u

typedef struct {
    uint32_t magic;
    uint32_t pc, lr, cfsr, hfsr, ipsr;
    uint32_t check; /* magic ^ pc ^ lr ^ cfsr ^ hfsr ^ ipsr: RAM after power-up is random */
} fault_record_t;

static fault_record_t fault_record __attribute__((section(".noinit")));

static uint32_t record_check(const fault_record_t *r)
{
    return r->magic ^ r->pc ^ r->lr ^ r->cfsr ^ r->hfsr ^ r->ipsr;
}

void cycles_init(void)
{
    DEMCR |= DEMCR_TRCENA;
    DWT_CYCCNT = 0;
    DWT_CTRL |= 1u; /* CYCCNTENA */
}

uint32_t cycles_now(void)
{
    return DWT_CYCCNT;
}

bool wait_reg(const volatile uint32_t *reg, uint32_t mask, uint32_t value, uint32_t cycles)
{
    uint32_t t0 = DWT_CYCCNT;
    while ((*reg & mask) != value) {
        if (DWT_CYCCNT - t0 > cycles) {
            return (*reg & mask) == value;
        }
    }
    return true;
}

void delay_cycles(uint32_t cycles)
{
    uint32_t t0 = DWT_CYCCNT;
    while (DWT_CYCCNT - t0 < cycles) {
    }
}

void health_boot(void)
{
    uint32_t csr = RCC->CSR;
    g_diag.reset_cause = csr >> 24;
    RCC->CSR = csr | RCC_CSR_RMVF; /* clear the flags for the next reset */
    if ((csr & RCC_CSR_IWDGRSTF) != 0u) {
        g_diag.selftest |= LHB_ST_WATCHDOG_RESET;
    }
    if (fault_record.magic == FAULT_MAGIC && fault_record.check == record_check(&fault_record)) {
        g_diag.selftest |= LHB_ST_FAULT_RECORD;
        g_diag.fault_pc = fault_record.pc;
        g_diag.fault_lr = fault_record.lr;
        g_diag.fault_cfsr = fault_record.cfsr;
        g_diag.fault_hfsr = fault_record.hfsr;
    }
    fault_record.magic = 0;
}

void watchdog_start(void)
{
    DBGMCU_APB1_FZ |= DBGMCU_IWDG_STOP;
    IWDG->KR = 0xCCCCu; /* start (also starts the LSI) */
    IWDG->KR = 0x5555u; /* unlock PR and RLR */
    IWDG->PR = 4u;      /* /64 */
    IWDG->RLR = 1000u;
    /* PVU/RVU clear once the values reached the LSI domain (a few LSI periods) */
    if (!wait_reg(&IWDG->SR, 3u, 0u, BOARD_SYSCLK_HZ / 50u)) {
        g_diag.selftest |= LHB_ST_PERIPH_TIMEOUT;
    }
    IWDG->KR = 0xAAAAu;
}

void watchdog_refresh(void)
{
    IWDG->KR = 0xAAAAu;
}

static void led_set(bool on)
{
    bool level = BOARD_LED_ACTIVE_LOW ? !on : on;
    GPIO(BOARD_LED_PORT)->BSRR = level ? 1u << BOARD_LED_PIN : 1u << (BOARD_LED_PIN + 16u);
}

void led_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIO(BOARD_LED_PORT);
    (void)RCC->AHB1ENR;
    led_set(false);
    gpio_t *g = GPIO(BOARD_LED_PORT);
    g->MODER = (g->MODER & ~(3u << (2u * BOARD_LED_PIN))) | (1u << (2u * BOARD_LED_PIN));
}

void led_update(uint32_t now_ms)
{
    const uint32_t failures = g_diag.selftest & ~(LHB_ST_FAULT_RECORD | LHB_ST_WATCHDOG_RESET);
    uint32_t t = now_ms % 1000u;
    bool on;
    if (failures != 0u) {
        on = (now_ms % 500u) < 250u;
    } else if ((g_diag.selftest & (LHB_ST_FAULT_RECORD | LHB_ST_WATCHDOG_RESET)) != 0u) {
        on = t < 100u || (t >= 200u && t < 300u);
    } else {
        on = t < 100u;
    }
    led_set(on);
}

void fault_entry(void);
void fault_record_and_reset(const uint32_t *frame, uint32_t ipsr);

void fault_record_and_reset(const uint32_t *frame, uint32_t ipsr)
{
    fault_record.pc = frame[6]; /* exception frame: r0-r3, r12, lr, pc, xpsr */
    fault_record.lr = frame[5];
    fault_record.cfsr = SCB_CFSR;
    fault_record.hfsr = SCB_HFSR;
    fault_record.ipsr = ipsr;
    fault_record.magic = FAULT_MAGIC;
    fault_record.check = record_check(&fault_record);
    led_set(true);
    cycles_init(); /* the fault may precede main's cycles_init: the delay needs the counter */
    delay_cycles(BOARD_SYSCLK_HZ / 4u); /* ~0.25 s of steady light (more on the HSI) */
    dsb();
    SCB_AIRCR = SCB_AIRCR_RESET;
    dsb();
    for (;;) {
    }
}

/* Picks the stack the exception frame was pushed on (EXC_RETURN bit 2) and the exception
 * number, then records. A fault with a broken stack pointer escalates to a lockup, which
 * the watchdog then resets. */
__attribute__((naked)) void fault_entry(void)
{
    __asm volatile("tst lr, #4\n"
                   "ite eq\n"
                   "mrseq r0, msp\n"
                   "mrsne r0, psp\n"
                   "mrs r1, ipsr\n"
                   "b fault_record_and_reset\n");
}
