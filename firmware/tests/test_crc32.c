#include <string.h>

#include "check.h"
#include "lhb/crc32.h"

int main(void)
{
    const char *v = "123456789";
    CHECK_EQ(lhb_crc32(v, 9), 0xCBF43926u);
    CHECK_EQ(lhb_crc32(v, 0), 0u);
    CHECK_EQ(lhb_crc32(NULL, 0), 0u);
    /* chaining equals one pass */
    uint32_t c = lhb_crc32(v, 4);
    c = lhb_crc32_update(c, v + 4, 5);
    CHECK_EQ(c, 0xCBF43926u);
    /* more zlib.crc32 values */
    CHECK_EQ(lhb_crc32("a", 1), 0xE8B7BE43u);
    const char *fox = "The quick brown fox jumps over the lazy dog";
    CHECK_EQ(lhb_crc32(fox, strlen(fox)), 0x414FA339u);
    uint8_t zeros[32] = {0};
    CHECK_EQ(lhb_crc32(zeros, sizeof zeros), 0x190A55ADu);
    return check_result("crc32");
}
