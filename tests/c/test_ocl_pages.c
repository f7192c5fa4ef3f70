/* test_ocl_pages — big buffers of the OpenCL CPU device stay on 4 KiB
 * pages: a 64 MiB device buffer the runtime fills maps no transparent huge
 * page (AnonHugePages over /proc/self/smaps does not grow).  With GDT_THP=1
 * the buffer may use huge pages; the figure is printed, not checked (the
 * kernel may not find any).  Exit 77 without an OpenCL device. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_ocl.h"

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
