/* Reset handler and vector table for the STM32F429 (16 system + 91 device vectors). Every
 * vector without a driver (NMI, HardFault, MemManage, BusFault, UsageFault, unexpected
 * interrupts) goes to health.c's fault_entry. */
#include <stdint.h>

#include "regs.h"

extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss, _estack;
int main(void);

void Reset_Handler(void);
void SysTick_Handler(void);
void USART1_IRQHandler(void);
void DMA2_Stream2_IRQHandler(void);
void TIM5_IRQHandler(void);
void fault_entry(void); /* health.c: records the fault for the next boot, then resets */

void Reset_Handler(void)
{
    /* FPU on first (CP10, CP11 full access): compiled code may use FP registers */
    SCB_CPACR |= 0xFu << 20;
    dsb();
    isb();
    uint32_t *src = &_sidata;
    for (uint32_t *dst = &_sdata; dst < &_edata;) {
        *dst++ = *src++;
    }
    for (uint32_t *dst = &_sbss; dst < &_ebss;) {
        *dst++ = 0;
    }
    (void)main();
    for (;;) {
    }
}

typedef void (*vector_t)(void);

#define N_VECTORS (16 + 91)

#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Woverride-init"
__attribute__((section(".isr_vector"), used)) const vector_t vector_table[N_VECTORS] = {
    [0] = (vector_t)(uintptr_t)&_estack,
    [1] = Reset_Handler,
    [2 ... N_VECTORS - 1] = fault_entry, /* NMI, faults, unexpected interrupts */
    [7] = 0, [8] = 0, [9] = 0, [10] = 0, [13] = 0, /* reserved */
    [15] = SysTick_Handler,
    [16 + IRQ_USART1] = USART1_IRQHandler,
    [16 + IRQ_DMA2_STREAM2] = DMA2_Stream2_IRQHandler,
    [16 + IRQ_TIM5] = TIM5_IRQHandler,
};
#pragma GCC diagnostic pop
