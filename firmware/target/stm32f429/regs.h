/* Minimal STM32F429 register map: only what this firmware touches, written from RM0090
 * (reference manual) and PM0214 (Cortex-M4 programming manual). Not the vendor headers. */
#ifndef LHB_STM32F429_REGS_H
#define LHB_STM32F429_REGS_H

#include <stdint.h>

#define REG volatile uint32_t

typedef struct {
    REG CR, PLLCFGR, CFGR, CIR, AHB1RSTR, AHB2RSTR, AHB3RSTR, RES0, APB1RSTR, APB2RSTR, RES1[2],
        AHB1ENR, AHB2ENR, AHB3ENR, RES2, APB1ENR, APB2ENR, RES3[2], AHB1LPENR, AHB2LPENR,
        AHB3LPENR, RES4, APB1LPENR, APB2LPENR, RES5[2], BDCR, CSR;
} rcc_t;
_Static_assert(__builtin_offsetof(rcc_t, CSR) == 0x74u, "RCC_CSR offset (RM0090 6.3.21)");
#define RCC ((rcc_t *)0x40023800u)
#define RCC_CR_HSEON (1u << 16)
#define RCC_CR_HSERDY (1u << 17)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_PLLCFGR_SRC_HSE (1u << 22)
#define RCC_CFGR_SW_PLL 2u
#define RCC_CFGR_SWS_MASK (3u << 2)
#define RCC_CFGR_SWS_PLL (2u << 2)
#define RCC_CFGR_PPRE1_DIV4 (5u << 10)
#define RCC_CFGR_PPRE2_DIV2 (4u << 13)
#define RCC_CFGR_RTCPRE(n) ((uint32_t)(n) << 16)
#define RCC_CSR_RMVF (1u << 24)
#define RCC_CSR_IWDGRSTF (1u << 29)
#define RCC_AHB1ENR_GPIO(n) (1u << (n)) /* A = 0 ... K = 10 */
#define RCC_AHB1ENR_DMA2EN (1u << 22)
#define RCC_AHB3ENR_FMCEN (1u << 0)
#define RCC_APB1ENR_TIM5EN (1u << 3)
#define RCC_APB1ENR_PWREN (1u << 28)
#define RCC_APB2ENR_TIM8EN (1u << 1)
#define RCC_APB2ENR_USART1EN (1u << 4)
#define RCC_APB2ENR_SPI1EN (1u << 12)
#define RCC_APB2ENR_TIM11EN (1u << 18)

typedef struct {
    REG CR, CSR;
} pwr_t;
#define PWR ((pwr_t *)0x40007000u)
#define PWR_CR_VOS_SCALE1 (3u << 14)
#define PWR_CR_ODEN (1u << 16)
#define PWR_CR_ODSWEN (1u << 17)
#define PWR_CSR_ODRDY (1u << 16)
#define PWR_CSR_ODSWRDY (1u << 17)

typedef struct {
    REG ACR, KEYR, OPTKEYR, SR, CR, OPTCR;
} flash_t;
#define FLASH ((flash_t *)0x40023C00u)
#define FLASH_ACR_LATENCY_5WS 5u
#define FLASH_ACR_PRFTEN (1u << 8)
#define FLASH_ACR_ICEN (1u << 9)
#define FLASH_ACR_DCEN (1u << 10)

typedef struct {
    REG MODER, OTYPER, OSPEEDR, PUPDR, IDR, ODR, BSRR, LCKR, AFR[2];
} gpio_t;
#define GPIO(n) ((gpio_t *)(0x40020000u + 0x400u * (uint32_t)(n)))
enum { PORT_A, PORT_B, PORT_C, PORT_D, PORT_E, PORT_F, PORT_G, PORT_H, PORT_I, PORT_J, PORT_K };

typedef struct {
    REG CR1, CR2, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER, CNT, PSC, ARR, RCR, CCR1, CCR2, CCR3,
        CCR4, BDTR, DCR, DMAR, OR;
} tim_t;
#define TIM5 ((tim_t *)0x40000C00u) /* 32-bit */
#define TIM8 ((tim_t *)0x40010400u)
#define TIM11 ((tim_t *)0x40014800u)
#define TIM_SR_CC1IF (1u << 1)
#define TIM_SR_CC1OF (1u << 9)
#define TIM_CR2_MMS_UPDATE (2u << 4) /* TRGO = update event */
#define TIM_SMCR_SMS_EXT1 (7u << 0)  /* external clock mode 1: count TRGI edges */
#define TIM_SMCR_TS_ITR3 (3u << 4)   /* TIM5's ITR3 = TIM8_TRGO (RM0090 table 98) */
#define TIM_CCMR1_CC1S_TI1 (1u << 0) /* CC1 input capture of TI1 */
#define TIM_CCER_CC1E (1u << 0)      /* CC1P = 0: rising edge */
#define TIM_DIER_CC1IE (1u << 1)
#define TIM11_OR_TI1_HSE_RTC (2u << 0) /* TI1_RMP = 10: HSE_RTC (RM0090 18.5.11) */
_Static_assert(__builtin_offsetof(tim_t, OR) == 0x50u, "TIMx_OR offset");
#define TIM_CR1_CEN (1u << 0)
#define TIM_CR1_URS (1u << 2)
#define TIM_DIER_UDE (1u << 8)
#define TIM_DIER_CC1DE (1u << 9)
#define TIM_EGR_UG (1u << 0)

typedef struct {
    REG CR, NDTR, PAR, M0AR, M1AR, FCR;
} dma_stream_t;
typedef struct {
    REG LISR, HISR, LIFCR, HIFCR;
    dma_stream_t S[8];
} dma_t;
#define DMA2 ((dma_t *)0x40026400u)
#define DMA_CR_EN (1u << 0)
#define DMA_CR_DMEIE (1u << 1)
#define DMA_CR_TEIE (1u << 2)
#define DMA_CR_TCIE (1u << 4)
#define DMA_CR_DIR_P2M (0u << 6)
#define DMA_CR_MINC (1u << 10)
#define DMA_CR_PSIZE_16 (1u << 11)
#define DMA_CR_MSIZE_16 (1u << 13)
#define DMA_CR_PL_VERY_HIGH (3u << 16)
#define DMA_CR_DBM (1u << 18)
#define DMA_CR_CT (1u << 19)
#define DMA_CR_CHSEL(n) ((uint32_t)(n) << 25)
/* LISR/LIFCR flag positions of streams 0..3 */
#define DMA_LISR_SHIFT(s) ((s) == 0 ? 0u : (s) == 1 ? 6u : (s) == 2 ? 16u : 22u)
#define DMA_FLAG_FE 0x01u
#define DMA_FLAG_DME 0x04u
#define DMA_FLAG_TE 0x08u
#define DMA_FLAG_HT 0x10u
#define DMA_FLAG_TC 0x20u
#define DMA_FLAGS_ALL 0x3Du

typedef struct {
    REG CR1, CR2, SR, DR, CRCPR, RXCRCR, TXCRCR, I2SCFGR, I2SPR;
} spi_t;
#define SPI1 ((spi_t *)0x40013000u)
#define SPI_CR1_CPHA (1u << 0)
#define SPI_CR1_CPOL (1u << 1)
#define SPI_CR1_MSTR (1u << 2)
#define SPI_CR1_BR_DIV8 (2u << 3)
#define SPI_CR1_SPE (1u << 6)
#define SPI_CR1_SSI (1u << 8)
#define SPI_CR1_SSM (1u << 9)
#define SPI_SR_RXNE (1u << 0)
#define SPI_SR_TXE (1u << 1)
#define SPI_SR_BSY (1u << 7)

typedef struct {
    REG SR, DR, BRR, CR1, CR2, CR3, GTPR;
} usart_t;
#define USART1 ((usart_t *)0x40011000u)
#define USART_SR_ORE (1u << 3)
#define USART_SR_RXNE (1u << 5)
#define USART_SR_TC (1u << 6)
#define USART_SR_TXE (1u << 7)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_UE (1u << 13)
#define USART_CR1_OVER8 (1u << 15)
#define USART_CR3_RTSE (1u << 8)
#define USART_CR3_CTSE (1u << 9)

/* FMC SDRAM controller (bank 5/6 registers) */
typedef struct {
    REG SDCR[2], SDTR[2], SDCMR, SDRTR, SDSR;
} fmc_sdram_t;
#define FMC_SDRAM ((fmc_sdram_t *)0xA0000140u)
#define FMC_SDSR_BUSY (1u << 5)

typedef struct {
    REG KR, PR, RLR, SR;
} iwdg_t;
#define IWDG ((iwdg_t *)0x40003000u)

typedef struct {
    REG CTRL, LOAD, VAL, CALIB;
} systick_t;
#define SYSTICK ((systick_t *)0xE000E010u)

#define NVIC_ISER ((REG *)0xE000E100u)
#define NVIC_ICER ((REG *)0xE000E180u)
#define NVIC_IPR ((volatile uint8_t *)0xE000E400u)
#define SCB_CPACR (*(REG *)0xE000ED88u)
#define SCB_AIRCR (*(REG *)0xE000ED0Cu)
#define SCB_AIRCR_RESET ((0x05FAu << 16) | (1u << 2)) /* VECTKEY | SYSRESETREQ */
#define SCB_CFSR (*(REG *)0xE000ED28u)
#define SCB_HFSR (*(REG *)0xE000ED2Cu)
#define DEMCR (*(REG *)0xE000EDFCu)
#define DEMCR_TRCENA (1u << 24)
#define DWT_CTRL (*(REG *)0xE0001000u)
#define DWT_CYCCNT (*(REG *)0xE0001004u)
#define DBGMCU_APB1_FZ (*(REG *)0xE0042008u)
#define DBGMCU_IWDG_STOP (1u << 12)
#define UID_BASE ((const volatile uint32_t *)0x1FFF7A10u)

/* IRQ numbers used here (RM0090 vector table) */
#define IRQ_USART1 37
#define IRQ_TIM5 50
#define IRQ_DMA2_STREAM2 58

static inline void nvic_enable(int irq, uint8_t prio)
{
    NVIC_IPR[irq] = (uint8_t)(prio << 4); /* 4 priority bits implemented */
    NVIC_ISER[irq >> 5] = 1u << (irq & 31);
}

static inline void nvic_disable(int irq)
{
    NVIC_ICER[irq >> 5] = 1u << (irq & 31);
}

static inline void dsb(void) { __asm volatile("dsb" ::: "memory"); }
static inline void isb(void) { __asm volatile("isb" ::: "memory"); }
static inline uint32_t irq_save(void)
{
    uint32_t p;
    __asm volatile("mrs %0, primask\n cpsid i" : "=r"(p)::"memory");
    return p;
}
static inline void irq_restore(uint32_t p) { __asm volatile("msr primask, %0" ::"r"(p) : "memory"); }

#endif
