/* test_ocl_pages — gdt_ocl_small_pages keeps the CPU device's buffers off
 * transparent huge pages: after the call the process reports THP disabled
 * (THP_enabled: 0 in /proc/self/status), and a 64 MiB device buffer the
 * runtime fills maps no huge page (AnonHugePages of the buffer's mapping
 * in /proc/self/smaps).  With GDT_THP=1 the call must leave huge pages
 * alone.  Exit 77 without an OpenCL device or on a kernel that lacks the
 * status line. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_ocl.h"

/* The value of "THP_enabled:" in /proc/self/status, or -1. */
static int thp_enabled(void)
{
    char line[256];
    int v = -1;
    FILE *f = fopen("/proc/self/status", "r");
    if (f == NULL)
        return -1;
    while (fgets(line, sizeof line, f) != NULL)
        if (sscanf(line, "THP_enabled: %d", &v) == 1)
            break;
    fclose(f);
    return v;
}

/* Sum of AnonHugePages (kB) over every mapping of the process, or -1. */
static long anon_huge_kb(void)
{
    char line[256];
    long sum = 0, v;
    FILE *f = fopen("/proc/self/smaps", "r");
    if (f == NULL)
        return -1;
    while (fgets(line, sizeof line, f) != NULL)
        if (sscanf(line, "AnonHugePages: %ld kB", &v) == 1)
            sum += v;
    fclose(f);
    return sum;
}

int main(void)
{
    gdt_checks t = {0, 0};
    const char *keep = getenv("GDT_THP");
    int keep_thp = keep != NULL && strcmp(keep, "1") == 0;
    gdt_ocl_opts o;
    gdt_ocl *ocl = NULL;
    gdt_ocl_buf *b = NULL;
    gdt_error err;
    long before, after;
    int r;

    if (thp_enabled() < 0) {
        printf("test_ocl_pages: no THP_enabled line in /proc/self/status: skipped\n");
        return 77;
    }
    r = gdt_ocl_small_pages();
    GDT_CHECK(&t, r == !keep_thp, "gdt_ocl_small_pages returned %d with GDT_THP %s", r,
              keep ? keep : "unset");
    GDT_CHECK(&t, thp_enabled() == keep_thp, "THP_enabled %d after the call", thp_enabled());

    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    if (gdt_ocl_create(&ocl, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    before = anon_huge_kb();
    if (gdt_ocl_buf_create(ocl, (size_t)64 << 20, "test", &b, &err) != GDT_OK ||
        gdt_ocl_fill_u32(ocl, b, 0, 0x5a5a5a5au, (size_t)64 << 20, &err) != GDT_OK ||
        gdt_ocl_finish(ocl, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        GDT_CHECK(&t, 0, "%s", "buffer create or fill failed");
    } else {
        after = anon_huge_kb();
        printf("test_ocl_pages: AnonHugePages %ld kB before, %ld kB after a filled 64 MiB "
               "buffer (GDT_THP %s)\n",
               before, after, keep ? keep : "unset");
        if (!keep_thp)
            GDT_CHECK(&t, after == before, "the buffer maps %ld kB of huge pages", after - before);
    }
    gdt_ocl_buf_release(ocl, b);
    gdt_ocl_destroy(ocl);
    return gdt_check_finish(&t, "test_ocl_pages");
}
