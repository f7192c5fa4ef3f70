/* test_ocl_caps — what the core needs of an OpenCL device
 * (gdt_ocl_caps_missing), from the strings devices report: OpenCL C 1.2
 * or later and 64-bit integers; double precision and 64-bit atomics are
 * not needed.  No device is used. */
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
    return gdt_check_finish(&checks, "test_ocl_caps");
}
