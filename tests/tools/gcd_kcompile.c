/* gcd_kcompile — compiles every kernel file (kernels/NAME.cl) through the OpenCL host driver
 * (the build-time kernel check and the kernels_compile test).
 *
 *   gcd_kcompile [--kernel-dir DIR] [--device SPEC] [--stamp FILE]
 *
 * Each file is built twice: with double precision (when the device has
 * cl_khr_fp64) and with -DGDT_X_NO_F64 (the integer-only path of devices
 * without it).  Prints one line per build with its kernel count.
 * Exit: 0 all built (the stamp file, if given, is then written); 1 a build
 * failed (its log is printed); 77 no OpenCL device (skip). */
#include <dirent.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_ocl.h"

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

int main(int argc, char **argv)
{
    const char *kdir = NULL, *device = NULL, *stamp = NULL;
    char *files[256];
    size_t nfiles = 0;
    int failed = 0;
    gdt_log log;

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--kernel-dir") == 0 && i + 1 < argc)
            kdir = argv[++i];
        else if (strcmp(argv[i], "--device") == 0 && i + 1 < argc)
            device = argv[++i];
        else if (strcmp(argv[i], "--stamp") == 0 && i + 1 < argc)
            stamp = argv[++i];
        else {
            fprintf(stderr, "usage: gcd_kcompile [--kernel-dir DIR] [--device SPEC] [--stamp FILE]\n");
            return 2;
        }
    }
    gdt_log_init(&log, 1);
    for (int fp = 1; fp >= 0; fp--) {
        gdt_ocl_opts o;
        gdt_ocl *ocl = NULL;
        gdt_error err;
        memset(&o, 0, sizeof o);
        memset(&err, 0, sizeof err);
        o.device = device;
        o.kernel_dir = kdir;
        o.force_no_fp64 = !fp;
        o.log = &log;
        if (gdt_ocl_create(&ocl, &o, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
        }
        if (fp && !gdt_ocl_has_fp64(ocl)) {
            printf("device %s has no cl_khr_fp64: integer path only\n", gdt_ocl_device_name(ocl));
            gdt_ocl_destroy(ocl);
            continue;
        }
        if (nfiles == 0) {
            DIR *d = opendir(gdt_ocl_kernel_dir(ocl));
            struct dirent *e;
            if (d == NULL) {
                fprintf(stderr, "gcd_kcompile: cannot open %s\n", gdt_ocl_kernel_dir(ocl));
                gdt_ocl_destroy(ocl);
                return 1;
            }
            while ((e = readdir(d)) != NULL && nfiles < 256) {
                size_t l = strlen(e->d_name);
                if (l > 3 && strcmp(e->d_name + l - 3, ".cl") == 0)
                    files[nfiles++] = strdup(e->d_name);
            }
            closedir(d);
            qsort(files, nfiles, sizeof files[0], cmp_str);
        }
        for (size_t i = 0; i < nfiles; i++) {
            gdt_ocl_program *p = NULL;
            memset(&err, 0, sizeof err);
            if (gdt_ocl_build(ocl, files[i], NULL, &p, &err) != GDT_OK) {
                gdt_error_print(&err, stderr);
                failed++;
                continue;
            }
            printf("%-20s %s: %zu kernels\n", files[i], fp ? "fp64" : "integer",
                   gdt_ocl_program_kernel_count(p));
        }
        gdt_ocl_destroy(ocl);
    }
    for (size_t i = 0; i < nfiles; i++)
        free(files[i]);
    if (failed)
        return 1;
    if (nfiles == 0) {
        fprintf(stderr, "gcd_kcompile: no .cl file found\n");
        return 1;
    }
    if (stamp != NULL) {
        FILE *f = fopen(stamp, "w");
        if (f == NULL || fprintf(f, "%zu kernel files compiled\n", nfiles) < 0 || fclose(f) != 0) {
            fprintf(stderr, "gcd_kcompile: cannot write %s\n", stamp);
            return 1;
        }
    }
    return 0;
}
