/* plycheck_run — test tool: the streaming exact mesh checker on one PLY.
 *
 *   plycheck_run FILE [--mem-budget SIZE] [--temp-dir DIR]
 *
 * SIZE: bytes, or a number with the suffix K, M or G (powers of 1024).
 * Prints one line:
 *   stdout "OK: V vertices, F faces, h hull vertices, E interior edges
 *          checked; spill S bytes in N files; peak heap P of B bytes;
 *          predicates: orient O, incircle I (exact X), tie-break T"
 *   stdout "FAIL: GDT-<code>: <message>"   (a violation, 7360-7375)
 *   stderr "ERROR: GDT-<code>: <message>"  (bad file, I/O, out of memory)
 * Exit status: 0 valid, 7 violation or internal error (out of memory),
 * 3 bad file, 4 I/O error, 2 usage.
 */
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_plycheck.h"

static int parse_size(const char *s, size_t *out)
{
    char *end;
    unsigned long long v;
    unsigned shift = 0;

    if (*s < '0' || *s > '9')
        return 0;
    errno = 0;
    v = strtoull(s, &end, 10);
    if (errno != 0)
        return 0;
    if (*end == 'K' || *end == 'k')
        shift = 10, end++;
    else if (*end == 'M' || *end == 'm')
        shift = 20, end++;
    else if (*end == 'G' || *end == 'g')
        shift = 30, end++;
    if (*end != '\0' || v > (SIZE_MAX >> shift))
        return 0;
    *out = (size_t)(v << shift);
    return 1;
}

static int usage(void)
{
    fprintf(stderr, "usage: plycheck_run FILE [--mem-budget SIZE] [--temp-dir DIR]\n");
    return 2;
}

int main(int argc, char **argv)
{
    gdt_plycheck_opts opts;
    gdt_plycheck_result res;
    gdt_error err;
    const char *path = NULL;
    gdt_status s;

    gdt_plycheck_opts_init(&opts);
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--mem-budget") == 0 && i + 1 < argc) {
            if (!parse_size(argv[++i], &opts.mem_budget) || opts.mem_budget == 0) {
                fprintf(stderr, "plycheck_run: --mem-budget: '%s' is not a size\n", argv[i]);
                return 2;
            }
        } else if (strcmp(argv[i], "--temp-dir") == 0 && i + 1 < argc) {
            opts.temp_dir = argv[++i];
        } else if (argv[i][0] == '-' || path != NULL) {
            return usage();
        } else {
            path = argv[i];
        }
    }
    if (path == NULL)
        return usage();

    gdt_error_clear(&err);
    s = gdt_ply_check(&opts, path, &res, &err);
    if (s == GDT_OK) {
        printf("OK: %llu vertices, %llu faces, %llu hull vertices, %llu interior edges checked; "
               "spill %llu bytes in %llu files; peak heap %zu of %zu bytes; predicates: orient "
               "%llu, incircle %llu (exact %llu), tie-break %llu\n",
               (unsigned long long)res.vertices, (unsigned long long)res.faces,
               (unsigned long long)res.hull_vertices, (unsigned long long)res.interior_edges,
               (unsigned long long)res.spill_bytes, (unsigned long long)res.spill_files,
               res.peak_heap, res.mem_budget, (unsigned long long)res.pred.orient_calls,
               (unsigned long long)res.pred.incircle_calls,
               (unsigned long long)res.pred.incircle_exact,
               (unsigned long long)res.pred.tiebreak_calls);
        return 0;
    }
    if (s == GDT_EINTERNAL && err.code >= 7360 && err.code <= 7375) {
        printf("FAIL: GDT-%d: %s\n", err.code, err.msg);
        return 7;
    }
    fprintf(stderr, "ERROR: GDT-%d: %s\n", err.code, err.msg);
    return s == GDT_EIO ? 4 : s == GDT_EINPUT ? 3 : 7;
}
