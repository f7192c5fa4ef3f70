/* test_ocl_caps — what the core needs of an OpenCL device
 * (gdt_ocl_caps_missing), from the strings devices report: OpenCL C 1.2
 * or later and 64-bit integers; double precision and 64-bit atomics are
 * not needed.  And which runtimes give each further command queue of a
 * device programs of its own (gdt_ocl_queues_need_own_programs).  No
 * device is used. */
#include <string.h>

#include "gdt_check.h"
#include "gdt_ocl.h"

static gdt_checks checks;
#define CHECK(e, ...) GDT_CHECK(&checks, e, __VA_ARGS__)

int main(void)
{
    char out[512];
    int n;

    /* what PoCL, NVIDIA and AMD report: nothing missing, fp64 or not */
    n = gdt_ocl_caps_missing("FULL_PROFILE", "OpenCL C 1.2 pocl",
                             "cl_khr_byte_addressable_store cl_khr_fp64", out, sizeof out);
    CHECK(n == 0 && out[0] == '\0', "PoCL: %d: %s", n, out);
    n = gdt_ocl_caps_missing("FULL_PROFILE", "OpenCL C 1.2 ", "cl_khr_global_int32_base_atomics",
                             out, sizeof out);
    CHECK(n == 0, "no fp64 is fine (the integer path): %s", out);
    n = gdt_ocl_caps_missing("FULL_PROFILE", "OpenCL C 3.0 ", "", out, sizeof out);
    CHECK(n == 0, "OpenCL C 3.0: %s", out);
    n = gdt_ocl_caps_missing("FULL_PROFILE", "OpenCL C 2.0 ", "", out, sizeof out);
    CHECK(n == 0, "OpenCL C 2.0: %s", out);
    n = gdt_ocl_caps_missing("EMBEDDED_PROFILE", "OpenCL C 1.2 ", "cles_khr_int64 cl_khr_fp16",
                             out, sizeof out);
    CHECK(n == 0, "embedded with cles_khr_int64: %s", out);

    /* what is missing is named */
    n = gdt_ocl_caps_missing("FULL_PROFILE", "OpenCL C 1.1 ", "", out, sizeof out);
    CHECK(n == 1 && strstr(out, "OpenCL C 1.2") != NULL &&
              strstr(out, "offers \"OpenCL C 1.1 \"") != NULL,
          "1.1: %d: %s", n, out);
    n = gdt_ocl_caps_missing("EMBEDDED_PROFILE", "OpenCL C 1.2 ", "cl_khr_fp16", out, sizeof out);
    CHECK(n == 1 && strstr(out, "64-bit integers") != NULL, "embedded: %d: %s", n, out);
    n = gdt_ocl_caps_missing("EMBEDDED_PROFILE", "garbage", "", out, sizeof out);
    CHECK(n == 2 && strstr(out, "OpenCL C 1.2") != NULL && strstr(out, "; 64-bit") != NULL,
          "both: %d: %s", n, out);
    n = gdt_ocl_caps_missing(NULL, NULL, NULL, out, sizeof out);
    CHECK(n == 2, "nothing reported: %d: %s", n, out);
    /* a short buffer is cut, still terminated */
    n = gdt_ocl_caps_missing("EMBEDDED_PROFILE", "OpenCL C 1.0", "", out, 12);
    CHECK(n == 2 && strlen(out) < 12, "cut: %d: %s", n, out);

    /* which devices' further queues need programs of their own: PoCL's CPU
     * drivers before PoCL 7, nothing else */
    CHECK(gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL 3.1+debian  Linux, None+Asserts, "
                                           "RELOC, SPIR, LLVM 15.0.6, SLEEF, DISTRO, POCL_DEBUG",
                                           1),
          "PoCL 3.1 CPU");
    CHECK(gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL 6.0  Linux, Release", 1), "PoCL 6.0");
    CHECK(gdt_ocl_queues_need_own_programs("OpenCL 1.2 PoCL 1.8", 1), "PoCL 1.8");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL 7.0  Linux, Release", 1),
          "PoCL 7.0 CPU");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL 12.1", 1), "PoCL 12.1 CPU");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL 3.1+debian  Linux", 0),
          "PoCL 3.1, not a CPU device (its CUDA driver)");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 3.0 CUDA 12.4.131", 0), "NVIDIA");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 2.1 AMD-APP (3614.0)", 1), "AMD's CPU");
    CHECK(!gdt_ocl_queues_need_own_programs("OpenCL 3.0 PoCL", 1), "no version number");
    CHECK(!gdt_ocl_queues_need_own_programs(NULL, 1), "nothing reported");
    return gdt_check_finish(&checks, "test_ocl_caps");
}
