#include "lhb/memtest.h"

long lhb_mem_data_bus(const lhb_mem_t *m, uint32_t word)
{
    for (uint32_t bit = 1u; bit != 0u; bit <<= 1) {
        m->wr(m->ctx, word, bit);
        if (m->rd(m->ctx, word) != bit) {
            return (long)word;
        }
        m->wr(m->ctx, word, ~bit);
        if (m->rd(m->ctx, word) != ~bit) {
            return (long)word;
        }
    }
    return -1;
}

long lhb_mem_address_bus(const lhb_mem_t *m, uint32_t words)
{
    const uint32_t pattern = 0xAAAAAAAAu;
    const uint32_t anti = 0x55555555u;
    for (uint32_t off = 1u; off < words && off != 0u; off <<= 1) {
        m->wr(m->ctx, off, pattern);
    }
    m->wr(m->ctx, 0u, anti);
    /* an address line stuck high maps offset 0 onto a power of two */
    for (uint32_t off = 1u; off < words && off != 0u; off <<= 1) {
        if (m->rd(m->ctx, off) != pattern) {
            return (long)off;
        }
    }
    m->wr(m->ctx, 0u, pattern);
    /* stuck low or shorted: writing one offset changes another */
    for (uint32_t test = 1u; test < words && test != 0u; test <<= 1) {
        m->wr(m->ctx, test, anti);
        if (m->rd(m->ctx, 0u) != pattern) {
            return (long)test;
        }
        for (uint32_t off = 1u; off < words && off != 0u; off <<= 1) {
            if (off != test && m->rd(m->ctx, off) != pattern) {
                return (long)off;
            }
        }
        m->wr(m->ctx, test, pattern);
    }
    return -1;
}

/* One march element over [first, first+words): read `expect` (if check), write `value`. */
static long march_element(const lhb_mem_t *m, uint32_t first, uint32_t words, int up,
                          int check, uint32_t expect, uint32_t value)
{
    for (uint32_t k = 0; k < words; k++) {
        uint32_t i = first + (up ? k : words - 1u - k);
        if (check && m->rd(m->ctx, i) != expect) {
            return (long)i;
        }
        m->wr(m->ctx, i, value);
    }
    return -1;
}

long lhb_mem_march_c_minus(const lhb_mem_t *m, uint32_t first, uint32_t words,
                           uint32_t background)
{
    const uint32_t z = background;
    const uint32_t o = ~background;
    long r;
    if ((r = march_element(m, first, words, 1, 0, 0u, z)) >= 0 ||
        (r = march_element(m, first, words, 1, 1, z, o)) >= 0 ||
        (r = march_element(m, first, words, 1, 1, o, z)) >= 0 ||
        (r = march_element(m, first, words, 0, 1, z, o)) >= 0 ||
        (r = march_element(m, first, words, 0, 1, o, z)) >= 0) {
        return r;
    }
    for (uint32_t i = first; i < first + words; i++) {
        if (m->rd(m->ctx, i) != z) {
            return (long)i;
        }
    }
    return -1;
}

static uint32_t retention_word(uint32_t i, uint32_t seed)
{
    uint32_t x = (i + 1u) * 2654435761u ^ seed; /* address-dependent, never constant */
    return x ^ (x >> 15);
}

void lhb_mem_retention_write(const lhb_mem_t *m, uint32_t words, uint32_t stride,
                             uint32_t seed)
{
    for (uint32_t i = 0; i < words; i += stride) {
        m->wr(m->ctx, i, retention_word(i, seed));
    }
}

long lhb_mem_retention_check(const lhb_mem_t *m, uint32_t words, uint32_t stride,
                             uint32_t seed)
{
    for (uint32_t i = 0; i < words; i += stride) {
        if (m->rd(m->ctx, i) != retention_word(i, seed)) {
            return (long)i;
        }
    }
    return -1;
}
