/* Memory tests for the SDRAM bring-up, written against an accessor so that the host tests
 * can run them on a memory model with injected faults.
 *
 * - data bus: walking ones (and zeros) through one word: each of the 32 data lines alone;
 * - address bus: walking ones over the word address lines (offsets 1, 2, 4, ... words):
 *   finds lines stuck or shorted together (two addresses aliasing one cell);
 * - March C- (van de Goor): {up(w0); up(r0,w1); up(r1,w0); down(r0,w1); down(r1,w0); up(r0)}
 *   with "0" = a background word and "1" = its complement: stuck-at, transition, address
 *   decoder and most coupling faults within the region;
 * - retention: a word per `stride` written, read back later (the caller waits, with the
 *   refresh running, longer than the refresh period). */
#ifndef LHB_MEMTEST_H
#define LHB_MEMTEST_H

#include <stdint.h>

typedef struct {
    uint32_t (*rd)(void *ctx, uint32_t word);
    void (*wr)(void *ctx, uint32_t word, uint32_t value);
    void *ctx;
} lhb_mem_t;

/* Each returns -1 when the test passes, else the first failing word index (>= 0). */
long lhb_mem_data_bus(const lhb_mem_t *m, uint32_t word);
long lhb_mem_address_bus(const lhb_mem_t *m, uint32_t words); /* words: power of two */
long lhb_mem_march_c_minus(const lhb_mem_t *m, uint32_t first, uint32_t words,
                           uint32_t background);
void lhb_mem_retention_write(const lhb_mem_t *m, uint32_t words, uint32_t stride,
                             uint32_t seed);
long lhb_mem_retention_check(const lhb_mem_t *m, uint32_t words, uint32_t stride,
                             uint32_t seed);

#endif
