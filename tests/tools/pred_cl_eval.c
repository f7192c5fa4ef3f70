/* pred_cl_eval — evaluates predicate cases on an OpenCL device with the
 * shared header kernels/gdt_exact.clh compiled as OpenCL C 1.2, so the tests
 * can check that the kernels' predicates equal the host's and big-integer
 * arithmetic.
 *
 * usage: pred_cl_eval [--no-fp64] [--kernel-dir DIR]
 *
 * Input and output as pred_eval's binary mode (records of 9 native-endian
 * int64: op v0..v7; output 2 bytes per case: result, path bits).  The inputs
 * are not range-checked here: run pred_eval on the same cases first.
 * --no-fp64 compiles the header with GDT_X_NO_F64 (the integer-only path
 * used on devices without cl_khr_fp64).
 * Exit 0; 77 when no OpenCL device is available; 1 on any OpenCL failure
 * (with the build log when the program does not compile); 3 on bad input.
 */
#define CL_TARGET_OPENCL_VERSION 120
#include <CL/cl.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "private/kernel_text.h"

#ifndef GDT_PRED_KERNEL_DIR
#define GDT_PRED_KERNEL_DIR "kernels"
#endif

#define REC_VALUES 9

/* Test kernel: one work-item per case, same op codes as pred_eval. */
static const char *kernel_source =
    "\n#line 1 \"pred_cl_eval.c kernel\"\n" /* after the header's text, its own lines */
    "__kernel void pred_eval(__global const long *rec, __global uchar *out, uint n)\n"
    "{\n"
    "    size_t i = get_global_id(0);\n"
    "    if (i >= n)\n"
    "        return;\n"
    "    __global const long *r = rec + 9 * i;\n"
    "    int res = 0;\n"
    "    uint path = 0;\n"
    "    if (r[0] == 0) {\n"
    "        res = gdt_x_orient2d(r[1], r[2], r[3], r[4], r[5], r[6]);\n"
    "    } else if (r[0] == 1) {\n"
    "        int used_exact = 0;\n"
    "        res = gdt_x_incircle(r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8], &used_exact);\n"
    "        path = used_exact ? 1u : 0u;\n"
    "    } else if (r[0] == 2) {\n"
    "        res = gdt_x_prefer_diagonal(r[1], r[2], r[3], r[4]);\n"
    "    } else {\n"
    "        uint code = gdt_x_edge_flip_code(r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8]);\n"
    "        res = (code & GDT_X_FLIP) ? 1 : 0;\n"
    "        path = ((code & GDT_X_USED_EXACT) ? 1u : 0u) | ((code & GDT_X_USED_TIEBREAK) ? 2u : 0u);\n"
    "    }\n"
    "    out[2 * i] = (uchar)(char)res;\n"
    "    out[2 * i + 1] = (uchar)path;\n"
    "}\n";

typedef struct cl_state {
    cl_context ctx;
    cl_command_queue queue;
    cl_program prog;
    cl_kernel kern;
    cl_mem in, out;
} cl_state;

static void cl_state_release(cl_state *s)
{
    if (s->in)
        clReleaseMemObject(s->in);
    if (s->out)
        clReleaseMemObject(s->out);
    if (s->kern)
        clReleaseKernel(s->kern);
    if (s->prog)
        clReleaseProgram(s->prog);
    if (s->queue)
        clReleaseCommandQueue(s->queue);
    if (s->ctx)
        clReleaseContext(s->ctx);
}

/* Reads all of stdin; returns a malloc'd buffer (caller frees) or NULL. */
static unsigned char *read_all(size_t *len)
{
    size_t cap = 1 << 20, n = 0;
    unsigned char *buf = malloc(cap);
    if (buf == NULL)
        return NULL;
    for (;;) {
        if (n == cap) {
            unsigned char *nb = realloc(buf, cap * 2);
            if (nb == NULL) {
                free(buf);
                return NULL;
            }
            buf = nb;
            cap *= 2;
        }
        size_t got = fread(buf + n, 1, cap - n, stdin);
        n += got;
        if (got == 0)
            break;
    }
    if (ferror(stdin)) {
        free(buf);
        return NULL;
    }
    *len = n;
    return buf;
}

int main(int argc, char **argv)
{
    const char *kdir = GDT_PRED_KERNEL_DIR;
    int no_fp64 = 0;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--no-fp64") == 0) {
            no_fp64 = 1;
        } else if (strcmp(argv[i], "--kernel-dir") == 0 && i + 1 < argc) {
            kdir = argv[++i];
        } else {
            fprintf(stderr, "usage: pred_cl_eval [--no-fp64] [--kernel-dir DIR] < cases\n");
            return 2;
        }
    }

    int rc = 1;
    cl_int e = CL_SUCCESS;
    cl_state s;
    memset(&s, 0, sizeof s);
    unsigned char *out = NULL;
    char *header = NULL;
    size_t len = 0;
    unsigned char *in = read_all(&len);
    if (in == NULL) {
        fprintf(stderr, "pred_cl_eval: cannot read stdin\n");
        return 4;
    }
    const size_t rec_bytes = sizeof(int64_t) * REC_VALUES;
    if (len % rec_bytes != 0 || len / rec_bytes > UINT32_MAX) {
        fprintf(stderr, "pred_cl_eval: input is not a whole number of records\n");
        rc = 3;
        goto fail;
    }
    cl_uint n = (cl_uint)(len / rec_bytes);

    cl_platform_id plat;
    cl_uint nplat = 0;
    cl_device_id dev;
    cl_uint ndev = 0;
    if (clGetPlatformIDs(1, &plat, &nplat) != CL_SUCCESS || nplat == 0
        || clGetDeviceIDs(plat, CL_DEVICE_TYPE_ALL, 1, &dev, &ndev) != CL_SUCCESS || ndev == 0) {
        fprintf(stderr, "pred_cl_eval: no OpenCL device\n");
        rc = 77;
        goto fail;
    }
    char ext[8192] = "";
    clGetDeviceInfo(dev, CL_DEVICE_EXTENSIONS, sizeof ext - 1, ext, NULL);
    int has_fp64 = strstr(ext, "cl_khr_fp64") != NULL;

    s.ctx = clCreateContext(NULL, 1, &dev, NULL, NULL, &e);
    if (e != CL_SUCCESS)
        goto fail;
    s.queue = clCreateCommandQueue(s.ctx, dev, 0, &e);
    if (e != CL_SUCCESS)
        goto fail;
    /* the header's text in front of the kernel, as the product hands its
     * programs over (private/kernel_text.h): no -I naming a directory,
     * which a path with spaces would break */
    char failed[1024] = "";
    int te = gdt_kernel_text(kdir, "gdt_exact.clh", &header, NULL, failed, sizeof failed);
    if (te != 0) {
        fprintf(stderr, "pred_cl_eval: cannot read %s: %s\n", failed, strerror(te));
        goto fail;
    }
    const char *texts[2] = {header, kernel_source};
    s.prog = clCreateProgramWithSource(s.ctx, 2, texts, NULL, &e);
    if (e != CL_SUCCESS)
        goto fail;
    char opts[256];
    snprintf(opts, sizeof opts, "-cl-std=CL1.2 -Werror%s", no_fp64 ? " -D GDT_X_NO_F64" : "");
    e = clBuildProgram(s.prog, 1, &dev, opts, NULL, NULL);
    if (e != CL_SUCCESS) {
        size_t log_len = 0;
        clGetProgramBuildInfo(s.prog, dev, CL_PROGRAM_BUILD_LOG, 0, NULL, &log_len);
        char *log = malloc(log_len + 1);
        if (log != NULL) {
            clGetProgramBuildInfo(s.prog, dev, CL_PROGRAM_BUILD_LOG, log_len, log, NULL);
            log[log_len] = '\0';
            fprintf(stderr, "pred_cl_eval: build failed (%s):\n%s\n", opts, log);
            free(log);
        }
        goto fail;
    }
    s.kern = clCreateKernel(s.prog, "pred_eval", &e);
    if (e != CL_SUCCESS)
        goto fail;
    out = malloc(2 * (size_t)n + 1);
    if (out == NULL)
        goto fail;
    if (n > 0) {
        s.in = clCreateBuffer(s.ctx, CL_MEM_READ_ONLY | CL_MEM_COPY_HOST_PTR, len, in, &e);
        if (e != CL_SUCCESS)
            goto fail;
        s.out = clCreateBuffer(s.ctx, CL_MEM_WRITE_ONLY, 2 * (size_t)n, NULL, &e);
        if (e != CL_SUCCESS)
            goto fail;
        e = clSetKernelArg(s.kern, 0, sizeof s.in, &s.in);
        e |= clSetKernelArg(s.kern, 1, sizeof s.out, &s.out);
        e |= clSetKernelArg(s.kern, 2, sizeof n, &n);
        if (e != CL_SUCCESS)
            goto fail;
        size_t local = 64, global = ((size_t)n + local - 1) / local * local;
        e = clEnqueueNDRangeKernel(s.queue, s.kern, 1, NULL, &global, &local, 0, NULL, NULL);
        if (e != CL_SUCCESS)
            goto fail;
        e = clEnqueueReadBuffer(s.queue, s.out, CL_TRUE, 0, 2 * (size_t)n, out, 0, NULL, NULL);
        if (e != CL_SUCCESS)
            goto fail;
        if (fwrite(out, 2, n, stdout) != n) {
            fprintf(stderr, "pred_cl_eval: write error\n");
            rc = 4;
            goto fail;
        }
    }
    fprintf(stderr, "pred_cl_eval: cases %u device-fp64 %d filter %s\n", (unsigned)n, has_fp64,
            (has_fp64 && !no_fp64) ? "on" : "off");
    rc = 0;
fail:
    if (e != CL_SUCCESS)
        fprintf(stderr, "pred_cl_eval: OpenCL error %d\n", (int)e);
    cl_state_release(&s);
    free(header);
    free(out);
    free(in);
    return rc;
}
