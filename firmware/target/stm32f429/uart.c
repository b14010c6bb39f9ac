/* USART1 at 6 Mbaud with RTS/CTS, interrupt-driven both ways: received bytes go into a ring
 * buffer that the main loop drains; answers go whole into a send ring (core txring.c) that
 * the TXE interrupt empties, so the main loop prepares the next READ answer (CRC, COBS)
 * while the previous one is on the wire. Sending never waits: the main loop hands requests
 * to the protocol only while the ring has room for the largest answer (lhb_link_service),
 * so a host that never asserts CTS stalls the link, not the board; an answer that still
 * does not fit is dropped whole and counted (STATUS tx_dropped).
 * 6 Mbaud is exact: 90 MHz / (8 * 1.875), BRR = 1 << 4 | 7. */
#include "board.h"
#include "hw.h"
#include "regs.h"

#define RX_SIZE 1024u /* power of two */
#define TX_SIZE 8192u /* power of two; holds one whole READ answer and the start of the next */

static volatile uint8_t rx_buf[RX_SIZE];
static volatile uint32_t rx_head; /* written by the interrupt */
static volatile uint32_t rx_tail; /* written by the main loop */
static volatile uint8_t tx_buf[TX_SIZE];
static lhb_txring_t tx_ring;

static void pin_af7(uint32_t n)
{
    gpio_t *g = GPIO(PORT_A);
    g->MODER = (g->MODER & ~(3u << (2u * n))) | (2u << (2u * n));
    g->OSPEEDR |= 3u << (2u * n);
    g->PUPDR = (g->PUPDR & ~(3u << (2u * n))) | (1u << (2u * n)); /* pull-up: idle high */
    g->AFR[n >> 3] = (g->AFR[n >> 3] & ~(0xFu << (4u * (n & 7u)))) | (7u << (4u * (n & 7u)));
}

void uart_init(void)
{
    RCC->AHB1ENR |= RCC_AHB1ENR_GPIO(PORT_A);
    RCC->APB2ENR |= RCC_APB2ENR_USART1EN;
    (void)RCC->APB2ENR;
    pin_af7(9);  /* TX */
    pin_af7(10); /* RX */
    pin_af7(11); /* CTS */
    pin_af7(12); /* RTS */
    USART1->CR1 = 0;
    lhb_txring_init(&tx_ring, tx_buf, TX_SIZE, &g_diag.tx_dropped);
    /* OVER8: USARTDIV = 90e6 / (8 * 6e6) = 1.875 -> mantissa 1, fraction 0.875 * 8 = 7 */
    _Static_assert(BOARD_PCLK2_HZ == 90000000u && BOARD_UART_BAUD == 6000000u,
                   "BRR below is for 90 MHz / 6 Mbaud");
    USART1->BRR = (1u << 4) | 7u;
    USART1->CR2 = 0;
    USART1->CR3 = USART_CR3_RTSE | USART_CR3_CTSE;
    USART1->CR1 = USART_CR1_OVER8 | USART_CR1_TE | USART_CR1_RE | USART_CR1_RXNEIE | USART_CR1_UE;
    nvic_enable(IRQ_USART1, 0u); /* above the DMA interrupt: never lose a received byte */
}

void USART1_IRQHandler(void);
void USART1_IRQHandler(void)
{
    uint32_t sr = USART1->SR;
    if ((sr & (USART_SR_RXNE | USART_SR_ORE)) != 0u) {
        uint8_t b = (uint8_t)USART1->DR; /* reading SR then DR also clears ORE */
        uint32_t next = (rx_head + 1u) & (RX_SIZE - 1u);
        if (next != rx_tail) { /* full: drop (the frame CRC catches it, the host retries) */
            rx_buf[rx_head] = b;
            rx_head = next;
        }
    }
    if ((sr & USART_SR_TXE) != 0u && (USART1->CR1 & USART_CR1_TXEIE) != 0u) {
        uint8_t b;
        if (lhb_txring_pop(&tx_ring, &b)) {
            USART1->DR = b;
        } else {
            USART1->CR1 &= ~USART_CR1_TXEIE; /* nothing left to send */
        }
    }
}

bool uart_rx_pop(uint8_t *b)
{
    uint32_t t = rx_tail;
    if (t == rx_head) {
        return false;
    }
    *b = rx_buf[t];
    rx_tail = (t + 1u) & (RX_SIZE - 1u);
    return true;
}

void uart_tx(void *ctx, const uint8_t *data, size_t n)
{
    (void)ctx;
    (void)lhb_txring_put(&tx_ring, data, n); /* whole or not at all; never waits */
    uint32_t p = irq_save();
    USART1->CR1 |= USART_CR1_TXEIE;
    irq_restore(p);
}

const lhb_txring_t *uart_tx_ring(void)
{
    return &tx_ring;
}
