/* CRC-32 with the zlib polynomial (reflected 0xEDB88320, init and xor-out 0xFFFFFFFF).
 * Same convention as Python's zlib.crc32: start with 0, chain by passing the previous value. */
#ifndef LHB_CRC32_H
#define LHB_CRC32_H

#include <stddef.h>
#include <stdint.h>

uint32_t lhb_crc32_update(uint32_t crc, const void *data, size_t len);

static inline uint32_t lhb_crc32(const void *data, size_t len)
{
    return lhb_crc32_update(0u, data, len);
}

#endif
