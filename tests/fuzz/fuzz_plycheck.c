/* Fuzz target of the PLY checker's reader (gdt_plycheck.h): header parsing,
 * the size check, the mapped vertex section, the face records and the
 * spill files, all under the smallest heap budget so that every spill and
 * split path is reachable from inputs of a few kilobytes.
 *
 * Besides the sanitizers' findings, it aborts when a failure is reported
 * without its class and message, or when a mesh is accepted whose counts
 * break the relations the checker proves (Euler's, and one boundary edge
 * per hull vertex).
 */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "fuzz_input.h"
#include "gdt_error.h"
#include "gdt_plycheck.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    const char *path = NULL, *dir = NULL;
    gdt_plycheck_opts opts;
    gdt_plycheck_result res;
    gdt_error err;
    gdt_status st;

    if (gdt_fuzz_memfile(data, size, &path) != 0 || gdt_fuzz_workdir(&dir) != 0)
        gdt_fuzz_die("input file");
    gdt_plycheck_opts_init(&opts);
    opts.mem_budget = GDT_PLYCHECK_MIN_BUDGET;
    opts.temp_dir = dir; /* the memory file's folder (/proc/self/fd) takes no files */
    gdt_error_clear(&err);
    st = gdt_ply_check(&opts, path, &res, &err);
    if (st != GDT_OK) {
        gdt_fuzz_check_error(st, &err);
        return 0;
    }
    if (res.faces > 0 && (res.faces != 2 * res.vertices - res.hull_vertices - 2 ||
                          res.boundary_edges != res.hull_vertices))
        abort();
    return 0;
}
