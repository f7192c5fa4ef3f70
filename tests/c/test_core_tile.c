/* test_core_tile — the tile side a run gets when it gives none
 * (gdt_core_auto_tile), from what devices report, and the memory bound it
 * relies on (gdt_core_tile_bytes).  No device is used: the bound against
 * measured peaks is tested in tests/python/test_gcd.py. */
#include <stdint.h>

#include "gdt_check.h"
#include "gdt_core.h"

static gdt_checks checks;
#define CHECK(e, ...) GDT_CHECK(&checks, e, __VA_ARGS__)

#define GB(x) ((uint64_t)((x) * 1e9))

int main(void)
{
    const uint64_t host128 = (uint64_t)128 << 30, host16 = (uint64_t)16 << 30;
    int t;

    /* a CPU device keeps the CPU tile whatever its memory */
    t = gdt_core_auto_tile(1, GB(1000), GB(250), host128);
    CHECK(t == GDT_CORE_CPU_TILE, "CPU: %d", t);
    t = gdt_core_auto_tile(1, 0, 0, 0);
    CHECK(t == GDT_CORE_CPU_TILE, "CPU, nothing known: %d", t);

    /* GPUs as they report themselves (CL_DEVICE_GLOBAL_MEM_SIZE, MAX_MEM_ALLOC:
     * a quarter of it on NVIDIA's driver) */
    t = gdt_core_auto_tile(0, GB(85.0), GB(21.2), host128); /* H100 80 GB */
    CHECK(t == 16384, "H100: %d", t);
    t = gdt_core_auto_tile(0, GB(150.0), GB(37.5), host128); /* H200 */
    CHECK(t == 16384, "H200: %d", t);
    t = gdt_core_auto_tile(0, GB(51.0), GB(12.7), host128); /* 48 GB */
    CHECK(t == 8192, "48 GB: %d", t);
    t = gdt_core_auto_tile(0, GB(25.4), GB(6.3), host128); /* 24 GB */
    CHECK(t == 8192, "24 GB: %d", t);
    t = gdt_core_auto_tile(0, GB(8.5), GB(2.1), host128); /* 8 GB */
    CHECK(t == GDT_CORE_CPU_TILE, "8 GB: %d", t);

    /* each limit alone can hold the tile back */
    t = gdt_core_auto_tile(0, GB(150.0), GB(1.0), host128);
    CHECK(t == GDT_CORE_CPU_TILE, "small largest buffer: %d", t);
    t = gdt_core_auto_tile(0, GB(150.0), GB(37.5), host16);
    CHECK(t == 8192, "16 GiB of host memory: %d", t);
    t = gdt_core_auto_tile(0, GB(150.0), GB(37.5), (uint64_t)4 << 30);
    CHECK(t == GDT_CORE_CPU_TILE, "4 GiB of host memory: %d", t);
    t = gdt_core_auto_tile(0, 0, 0, 0);
    CHECK(t == 16384, "nothing known is no limit: %d", t);

    /* the chosen tile's densest tile fits three quarters of the memory */
    for (int i = 0; i < 3; i++) {
        const uint64_t mem[3] = {GB(85.0), GB(51.0), GB(25.4)};
        int n = gdt_core_auto_tile(0, mem[i], 0, 0);
        uint64_t need = gdt_core_tile_bytes(n, (uint64_t)n * (uint64_t)n / 2);
        CHECK(need <= mem[i] / 4 * 3, "%d: %llu of %llu", n, (unsigned long long)need,
              (unsigned long long)mem[i]);
        if (n < 16384) {
            uint64_t next = gdt_core_tile_bytes(2 * n, (uint64_t)4 * n * n / 2);
            CHECK(next > mem[i] / 4 * 3, "%d: the next size would fit too", n);
        }
    }
    /* the bound grows with the texels and the points */
    CHECK(gdt_core_tile_bytes(8192, 1000) > gdt_core_tile_bytes(4096, 1000), "texels");
    CHECK(gdt_core_tile_bytes(4096, 2000000) > gdt_core_tile_bytes(4096, 1000000), "points");
    return gdt_check_finish(&checks, "test_core_tile");
}
