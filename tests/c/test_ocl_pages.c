/* test_ocl_pages — big buffers of the OpenCL CPU device are asked to use
 * transparent huge pages only with GDT_THP=1.  A 64 MiB device buffer is
 * created and filled by the runtime; then, over /proc/self/smaps:
 *  - without GDT_THP: no new mapping carries the huge-page advice (VmFlags
 *    "hg") and AnonHugePages does not grow;
 *  - with GDT_THP=1: a new mapping carries the advice (checked where the
 *    kernel has transparent huge pages; whether it finds any is up to it).
 * Exit 77 without an OpenCL device. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_ocl.h"

/* Over every mapping of the process: *huge_kb = sum of AnonHugePages (kB),
 * *advised = mappings whose VmFlags include "hg" (MADV_HUGEPAGE).
 * Returns -1 if smaps cannot be read. */
static int smaps_scan(long *huge_kb, long *advised)
{
    char line[512];
    long v;
    FILE *f = fopen("/proc/self/smaps", "r");
    *huge_kb = *advised = 0;
    if (f == NULL)
        return -1;
    while (fgets(line, sizeof line, f) != NULL) {
        if (sscanf(line, "AnonHugePages: %ld kB", &v) == 1)
            *huge_kb += v;
        else if (strncmp(line, "VmFlags:", 8) == 0 && strstr(line, " hg") != NULL)
            (*advised)++;
    }
    fclose(f);
    return 0;
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
    long huge0, huge1, adv0, adv1;

    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    if (gdt_ocl_create(&ocl, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    if (smaps_scan(&huge0, &adv0) != 0) {
        printf("test_ocl_pages: /proc/self/smaps unreadable: skipped\n");
        gdt_ocl_destroy(ocl);
        return 77;
    }
    if (gdt_ocl_buf_create(ocl, (size_t)64 << 20, "test", &b, &err) != GDT_OK ||
        gdt_ocl_fill_u32(ocl, b, 0, 0x5a5a5a5au, (size_t)64 << 20, &err) != GDT_OK ||
        gdt_ocl_finish(ocl, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        GDT_CHECK(&t, 0, "%s", "buffer create or fill failed");
    } else {
        smaps_scan(&huge1, &adv1);
        printf("test_ocl_pages: GDT_THP %s: AnonHugePages %ld -> %ld kB, mappings with "
               "huge-page advice %ld -> %ld\n",
               keep ? keep : "unset", huge0, huge1, adv0, adv1);
        if (!keep_thp) {
            GDT_CHECK(&t, adv1 == adv0, "%ld new mappings with huge-page advice", adv1 - adv0);
            GDT_CHECK(&t, huge1 == huge0, "the buffer maps %ld kB of huge pages", huge1 - huge0);
        } else if (access("/sys/kernel/mm/transparent_hugepage/enabled", F_OK) == 0) {
            GDT_CHECK(&t, adv1 > adv0, "%s", "GDT_THP=1 but no mapping has the huge-page advice");
        }
    }
    gdt_ocl_buf_release(ocl, b);
    gdt_ocl_destroy(ocl);
    return gdt_check_finish(&t, "test_ocl_pages");
}
