/* src_read — benchmark and test tool: streams every point of one input
 * through gdt_source, as a run's passes do, and prints what it read.
 *
 *   src_read [--threads N] [--need xyz|attrs|class|flags|all] [--repeat K]
 *            [--range FIRST END] [--starts] FILE
 *
 * Prints one line per repeat:
 *   points=N seconds=S checksum=HEX
 * seconds is the wall time from gdt_source_open to the last point (the file
 * is read from the page cache when it is warm); checksum is an FNV-1a style
 * mix of every point's X Y Z and, when needed, cls ret nret flags, so two
 * readers that hand on different points or a different order disagree.
 * --need: xyz is GDT_SRC_NEED_XYZ alone, attrs (the default) adds class and
 * flags, as a run with filters reads.
 * --range: only the records [FIRST, END), through gdt_source_seek (FIRST
 * any record of uncompressed LAS, a chunk start of LAZ).
 * --starts: prints the records a chunked source can start at, one line
 * "starts=N" then the numbers, and reads nothing.
 * Exit status: the gdt_status of the first failure (3 bad input, 4 I/O, ...).
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_source.h"

#define READ_CHUNK 65536

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static uint64_t mix(uint64_t h, uint64_t v)
{
    h ^= v;
    return h * 0x100000001b3ull;
}

static int parse_need(const char *s, unsigned *need)
{
    if (strcmp(s, "xyz") == 0)
        *need = GDT_SRC_NEED_XYZ;
    else if (strcmp(s, "class") == 0)
        *need = GDT_SRC_NEED_XYZ | GDT_SRC_NEED_CLASS;
    else if (strcmp(s, "flags") == 0)
        *need = GDT_SRC_NEED_XYZ | GDT_SRC_NEED_FLAGS;
    else if (strcmp(s, "attrs") == 0 || strcmp(s, "all") == 0)
        *need = GDT_SRC_NEED_XYZ | GDT_SRC_NEED_ATTRS;
    else
        return -1;
    return 0;
}

/* Reads the file (or the records [first, end)) once; returns a gdt_status. */
static int read_once(const char *path, const gdt_source_opts *opts, gdt_src_point *buf,
                     int ranged, uint64_t first, uint64_t end)
{
    gdt_error err;
    gdt_source *src = NULL;
    uint64_t h = 0xcbf29ce484222325ull, count = 0;
    unsigned need = opts->need;
    double t0 = now_s();
    gdt_status st;

    gdt_error_clear(&err);
    st = gdt_source_open(&src, path, opts, &err);
    if (st == GDT_OK && ranged)
        st = gdt_source_seek(src, first, end, &err);
    for (;;) {
        size_t n = 0, want = READ_CHUNK;
        if (st != GDT_OK)
            break;
        if (ranged && want > end - first - count)
            want = (size_t)(end - first - count);
        if (want == 0)
            break;
        st = gdt_source_read(src, buf, want, &n, &err);
        if (st != GDT_OK || n == 0)
            break;
        for (size_t i = 0; i < n; i++) {
            const gdt_src_point *p = &buf[i];
            h = mix(h, (uint64_t)(uint32_t)p->X);
            h = mix(h, (uint64_t)(uint32_t)p->Y);
            h = mix(h, (uint64_t)(uint32_t)p->Z);
            if (need & GDT_SRC_NEED_CLASS)
                h = mix(h, p->cls);
            if (need & GDT_SRC_NEED_FLAGS)
                h = mix(h, (uint64_t)p->ret | (uint64_t)p->nret << 8 | (uint64_t)p->flags << 16);
        }
        count += n;
    }
    double t1 = now_s();
    gdt_source_close(src);
    if (st != GDT_OK) {
        gdt_error_print(&err, stderr);
        return (int)st;
    }
    printf("points=%" PRIu64 " seconds=%.6f checksum=%016" PRIx64 "\n", count, t1 - t0, h);
    fflush(stdout);
    return 0;
}

/* Prints the records the source can start at; returns a gdt_status. */
static int print_starts(const char *path, const gdt_source_opts *opts)
{
    gdt_error err;
    gdt_source *src = NULL;
    gdt_status st;
    uint64_t n, *v;

    gdt_error_clear(&err);
    st = gdt_source_open(&src, path, opts, &err);
    if (st != GDT_OK) {
        gdt_error_print(&err, stderr);
        return (int)st;
    }
    n = gdt_source_starts(src, NULL, 0);
    v = malloc((n + 1) * sizeof *v);
    if (v == NULL) {
        gdt_source_close(src);
        return 7;
    }
    gdt_source_starts(src, v, n);
    printf("starts=%" PRIu64 "\n", n);
    for (uint64_t i = 0; i < n; i++)
        printf("%" PRIu64 "\n", v[i]);
    free(v);
    gdt_source_close(src);
    return 0;
}

int main(int argc, char **argv)
{
    gdt_source_opts opts;
    gdt_log log;
    gdt_src_point *buf;
    const char *path = NULL;
    long repeat = 1;
    int rc = 0, ranged = 0, starts = 0;
    uint64_t first = 0, end = 0;

    memset(&opts, 0, sizeof opts);
    opts.need = GDT_SRC_NEED_XYZ | GDT_SRC_NEED_ATTRS;
    opts.threads = 1;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
            opts.threads = atoi(argv[++i]);
        } else if (strcmp(argv[i], "--need") == 0 && i + 1 < argc) {
            if (parse_need(argv[++i], &opts.need) != 0) {
                fprintf(stderr, "src_read: bad --need %s\n", argv[i]);
                return 2;
            }
        } else if (strcmp(argv[i], "--repeat") == 0 && i + 1 < argc) {
            repeat = atol(argv[++i]);
        } else if (strcmp(argv[i], "--range") == 0 && i + 2 < argc) {
            first = strtoull(argv[++i], NULL, 10);
            end = strtoull(argv[++i], NULL, 10);
            ranged = 1;
        } else if (strcmp(argv[i], "--starts") == 0) {
            starts = 1;
        } else if (argv[i][0] == '-' || path != NULL) {
            fprintf(stderr, "usage: src_read [--threads N] [--need xyz|class|flags|attrs] "
                            "[--repeat K] [--range FIRST END] [--starts] FILE\n");
            return 2;
        } else {
            path = argv[i];
        }
    }
    if (path == NULL || repeat < 1 || opts.threads < 1 || (ranged && end < first)) {
        fprintf(stderr, "usage: src_read [--threads N] [--need xyz|class|flags|attrs] "
                        "[--repeat K] [--range FIRST END] [--starts] FILE\n");
        return 2;
    }
    gdt_log_init(&log, 0);
    opts.log = &log;
    buf = malloc(READ_CHUNK * sizeof *buf);
    if (buf == NULL)
        return 7;
    if (starts)
        rc = print_starts(path, &opts);
    for (long r = 0; r < repeat && rc == 0 && !starts; r++)
        rc = read_once(path, &opts, buf, ranged, first, end);
    free(buf);
    return rc;
}
