/* gdt_dump — test tool: streams one input through gdt_source and prints it.
 *
 *   gdt_dump [--buffer-bytes N] [--chunk N] [--threads N] [--need BITS] [--info] FILE
 *
 * Without --info: one line per point, "x y z X Y Z" (%.17g for the doubles,
 * the LAS record integers last; 0 for formats without a lattice).
 * With --info: the validated header as "key=value" lines (LAZ: also the
 * compressor, items, chunk size and chunk count).  --threads N: decoder
 * threads of a compressed input (the output must not depend on it).
 * --need BITS: gdt_source_opts.need (GDT_SRC_NEED_* bits; 0, the default,
 * is every field).
 * Exit status: the gdt_status of the first failure (3 bad input, 4 I/O, ...).
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_source.h"

static int parse_size(const char *s, size_t *out)
{
    char *end = NULL;
    unsigned long long v = strtoull(s, &end, 10);
    if (end == s || *end != '\0' || v == 0)
        return -1;
    *out = (size_t)v;
    return 0;
}

static void print_info(const gdt_source_info *in)
{
    printf("format=%s\nversion=%s\nencoding=%s\npoint_count=%" PRIu64 "\n", in->format_name,
           in->version, in->encoding, in->point_count);
    if (in->has_bounds)
        printf("bounds=%.17g %.17g %.17g %.17g %.17g %.17g\n", in->min[0], in->min[1],
               in->min[2], in->max[0], in->max[1], in->max[2]);
    if (in->has_lattice)
        printf("scale=%.17g %.17g %.17g\noffset=%.17g %.17g %.17g\n", in->scale[0],
               in->scale[1], in->scale[2], in->offset[0], in->offset[1], in->offset[2]);
    printf("epsg=%d\ngeographic=%d\ncrs=%s\n", in->epsg, in->crs_geographic,
           in->crs_desc ? in->crs_desc : "");
    printf("point_format=%u\nrecord_length=%u\nextra_bytes=%u\nvlrs=%u\nevlrs=%u\n",
           in->point_format, in->record_length, in->extra_bytes, in->vlr_count,
           in->evlr_count);
    if (in->compressed)
        printf("compressor=%s\nlaz_items=%s\nlaz_chunk_size=%" PRIu32 "\nlaz_chunks=%" PRIu64 "\n",
               in->compressor, in->laz_items, in->laz_chunk_size, in->laz_chunks);
}

int main(int argc, char **argv)
{
    gdt_source_opts opts;
    gdt_log log;
    gdt_error err;
    gdt_source *src = NULL;
    gdt_src_point *buf = NULL;
    size_t chunk = 4096;
    int info = 0;
    const char *path = NULL;
    gdt_status st;

    memset(&opts, 0, sizeof opts);
    gdt_log_init(&log, 0);
    gdt_error_clear(&err);
    opts.log = &log;
    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--buffer-bytes") == 0 && i + 1 < argc) {
            if (parse_size(argv[++i], &opts.buffer_bytes) != 0)
                return GDT_EUSAGE;
        } else if (strcmp(argv[i], "--chunk") == 0 && i + 1 < argc) {
            if (parse_size(argv[++i], &chunk) != 0)
                return GDT_EUSAGE;
        } else if (strcmp(argv[i], "--threads") == 0 && i + 1 < argc) {
            size_t t;
            if (parse_size(argv[++i], &t) != 0 || t > 1024)
                return GDT_EUSAGE;
            opts.threads = (int)t;
        } else if (strcmp(argv[i], "--need") == 0 && i + 1 < argc) {
            char *end = NULL;
            unsigned long v = strtoul(argv[++i], &end, 10);
            if (end == argv[i] || *end != '\0' || v > 0xFFFFu)
                return GDT_EUSAGE;
            opts.need = (unsigned)v;
        } else if (strcmp(argv[i], "--info") == 0) {
            info = 1;
        } else if (path == NULL && argv[i][0] != '-') {
            path = argv[i];
        } else {
            fprintf(stderr, "usage: gdt_dump [--buffer-bytes N] [--chunk N] [--threads N] [--need BITS]"
                            " [--info] FILE\n");
            return GDT_EUSAGE;
        }
    }
    if (path == NULL) {
        fprintf(stderr, "usage: gdt_dump [--buffer-bytes N] [--chunk N] [--threads N] [--need BITS]"
                        " [--info] FILE\n");
        return GDT_EUSAGE;
    }
    st = gdt_source_open(&src, path, &opts, &err);
    if (st != GDT_OK)
        goto fail;
    if (info) {
        print_info(gdt_source_get_info(src));
        gdt_source_close(src);
        return 0;
    }
    buf = malloc(chunk * sizeof *buf);
    if (buf == NULL) {
        st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    for (;;) {
        size_t n = 0;
        st = gdt_source_read(src, buf, chunk, &n, &err);
        if (st != GDT_OK)
            goto fail;
        if (n == 0)
            break;
        for (size_t k = 0; k < n; k++)
            printf("%.17g %.17g %.17g %" PRId32 " %" PRId32 " %" PRId32 "\n", buf[k].x, buf[k].y,
                   buf[k].z, buf[k].X, buf[k].Y, buf[k].Z);
    }
    free(buf);
    gdt_source_close(src);
    return fflush(stdout) == 0 ? 0 : GDT_EIO;
fail:
    gdt_error_print(&err, stderr);
    free(buf);
    gdt_source_close(src);
    return (int)st;
}
