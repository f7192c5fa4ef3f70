/* Streaming tests of the LAS reader through gdt_source: a file written here
 * (LAS 1.2, format 1 with extra bytes and a WKT VLR) is read back with many
 * buffer and chunk sizes and its CRS checked; a file that shrinks between
 * open and read fails with GDT_EINPUT (GDT-3131) and keeps failing; a
 * missing file is bad input.
 *
 *   test_las_stream TMPDIR
 */
#include <inttypes.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "gdt_check.h"
#include "gdt_source.h"

enum { NPTS = 257, FORMAT = 1, BASE_LEN = 28, EXTRA = 5, HEADER = 227, VLR_HEADER = 54 };

/* A WKT VLR payload, NUL-padded as writers often do. */
static const char wkt[] = "GEOGCS[\"WGS 84\",AUTHORITY[\"EPSG\",\"4326\"]]";
enum { WKT_PAYLOAD = sizeof wkt + 6, POINTS_AT = HEADER + VLR_HEADER + WKT_PAYLOAD };

static gdt_checks checks;

#define CHECK(cond) GDT_CHECK(&checks, cond, "%s", "")

static void put_u16(unsigned char *p, unsigned v)
{
    p[0] = (unsigned char)(v & 0xff);
    p[1] = (unsigned char)((v >> 8) & 0xff);
}

static void put_u32(unsigned char *p, uint32_t v)
{
    for (int k = 0; k < 4; k++)
        p[k] = (unsigned char)((v >> (8 * k)) & 0xff);
}

static void put_f64(unsigned char *p, double d)
{
    uint64_t u;
    memcpy(&u, &d, sizeof u);
    for (int k = 0; k < 8; k++)
        p[k] = (unsigned char)((u >> (8 * k)) & 0xff);
}

/* Deterministic record integers spanning the whole int32 range. */
static int32_t coord(uint64_t *state)
{
    *state = *state * 6364136223846793005ULL + 1442695040888963407ULL;
    uint32_t u = (uint32_t)(*state >> 32);
    return u <= (uint32_t)INT32_MAX ? (int32_t)u
                                    : (int32_t)(u - (uint32_t)2147483648u) - INT32_MAX - 1;
}

static const double scale[3] = {0.001, 1e-7, 0.25};
static const double offset[3] = {1e6, -73.5, 0.0};

static int write_file(const char *path, int32_t (*xyz)[3])
{
    unsigned char h[HEADER];
    unsigned char vlr[VLR_HEADER + WKT_PAYLOAD];
    unsigned char rec[BASE_LEN + EXTRA];
    uint64_t state = 12345;
    FILE *f = fopen(path, "wb");
    if (f == NULL)
        return -1;
    memset(h, 0, sizeof h);
    memcpy(h, "LASF", 4);
    h[24] = 1;
    h[25] = 2;
    put_u16(h + 94, HEADER);
    put_u32(h + 96, POINTS_AT);
    put_u32(h + 100, 1);
    h[104] = FORMAT;
    put_u16(h + 105, BASE_LEN + EXTRA);
    put_u32(h + 107, NPTS);
    for (int k = 0; k < 3; k++) {
        put_f64(h + 131 + 8 * k, scale[k]);
        put_f64(h + 155 + 8 * k, offset[k]);
    }
    fwrite(h, 1, sizeof h, f);
    memset(vlr, 0, sizeof vlr);
    memcpy(vlr + 2, "LASF_Projection", 15);
    put_u16(vlr + 18, 2112);
    put_u16(vlr + 20, WKT_PAYLOAD);
    memcpy(vlr + VLR_HEADER, wkt, sizeof wkt);
    fwrite(vlr, 1, sizeof vlr, f);
    for (int i = 0; i < NPTS; i++) {
        memset(rec, 0xa5, sizeof rec);
        for (int k = 0; k < 3; k++) {
            xyz[i][k] = i == 0 ? INT32_MIN : i == 1 ? INT32_MAX : coord(&state);
            put_u32(rec + 4 * k, (uint32_t)xyz[i][k]);
        }
        fwrite(rec, 1, sizeof rec, f);
    }
    return fclose(f) == 0 ? 0 : -1;
}

static void read_back(const char *path, int32_t (*xyz)[3], size_t buffer_bytes, size_t chunk)
{
    gdt_source_opts opts = {.log = NULL, .buffer_bytes = buffer_bytes};
    gdt_error err;
    gdt_source *src = NULL;
    gdt_src_point *buf = calloc(chunk, sizeof *buf);
    size_t total = 0, n = 0;

    gdt_error_clear(&err);
    int opened = buf != NULL && gdt_source_open(&src, path, &opts, &err) == GDT_OK;
    GDT_CHECK(&checks, opened, "open failed: %s", err.msg);
    if (!opened) {
        free(buf);
        return;
    }
    const gdt_source_info *in = gdt_source_get_info(src);
    CHECK(in->extra_bytes == EXTRA && in->point_count == NPTS && in->vlr_count == 1);
    CHECK(in->crs_wkt != NULL && strcmp(in->crs_wkt, wkt) == 0);
    CHECK(in->epsg == 4326 && in->crs_geographic == 1 && strcmp(in->crs_desc, "EPSG:4326") == 0);
    CHECK(in->file_size == (uint64_t)POINTS_AT + (uint64_t)NPTS * (BASE_LEN + EXTRA));
    for (;;) {
        gdt_status rs = gdt_source_read(src, buf, chunk, &n, &err);
        GDT_CHECK(&checks, rs == GDT_OK, "read failed: %s", err.msg);
        if (rs != GDT_OK)
            break;
        if (n == 0)
            break;
        CHECK(n <= chunk);
        for (size_t k = 0; k < n && total + k < NPTS; k++) {
            const gdt_src_point *p = &buf[k];
            const int32_t *e = xyz[total + k];
            int ok = p->X == e[0] && p->Y == e[1] && p->Z == e[2] &&
                     p->x == (double)e[0] * scale[0] + offset[0] &&
                     p->y == (double)e[1] * scale[1] + offset[1] &&
                     p->z == (double)e[2] * scale[2] + offset[2];
            GDT_CHECK(&checks, ok, "point %zu differs (buffer %zu, chunk %zu)", total + k,
                      buffer_bytes, chunk);
            if (!ok)
                break;
        }
        total += n;
    }
    CHECK(total == NPTS);
    /* After the end, reads keep returning 0. */
    CHECK(gdt_source_read(src, buf, chunk, &n, &err) == GDT_OK && n == 0);
    gdt_source_close(src);
    free(buf);
}

static void shrink_while_reading(const char *path)
{
    gdt_source_opts opts = {.log = NULL, .buffer_bytes = 64};
    gdt_error err;
    gdt_source *src = NULL;
    gdt_src_point buf[16];
    size_t n = 0, total = 0;
    gdt_status st;

    gdt_error_clear(&err);
    gdt_status os = gdt_source_open(&src, path, &opts, &err);
    GDT_CHECK(&checks, os == GDT_OK, "open failed: %s", err.msg);
    if (os != GDT_OK)
        return;
    /* Cut the file in the middle of record 100. */
    CHECK(truncate(path, POINTS_AT + 100 * (BASE_LEN + EXTRA) + 7) == 0);
    do {
        st = gdt_source_read(src, buf, 16, &n, &err);
        total += n;
    } while (st == GDT_OK && n > 0);
    CHECK(st == GDT_EINPUT);
    CHECK(err.code == 3131);
    CHECK(strstr(err.msg, path) != NULL);
    CHECK(total <= 100);
    gdt_error_clear(&err);
    CHECK(gdt_source_read(src, buf, 16, &n, &err) == GDT_EINPUT && n == 0);
    gdt_source_close(src);
}

int main(int argc, char **argv)
{
    static int32_t xyz[NPTS][3];
    static const size_t buffers[] = {1, 2, 11, 12, 13, 33, 34, 1000, 1 << 20};
    static const size_t chunks[] = {1, 2, 7, 256, 257, 4096};
    char path[4096];
    gdt_error err;
    gdt_source *src = NULL;

    if (argc != 2) {
        fprintf(stderr, "usage: test_las_stream TMPDIR\n");
        return 2;
    }
    snprintf(path, sizeof path, "%s/test_las_stream_%ld.las", argv[1], (long)getpid());
    if (write_file(path, xyz) != 0) {
        fprintf(stderr, "cannot write %s\n", path);
        return 1;
    }
    for (size_t b = 0; b < sizeof buffers / sizeof buffers[0]; b++)
        for (size_t c = 0; c < sizeof chunks / sizeof chunks[0]; c++)
            read_back(path, xyz, buffers[b], chunks[c]);
    shrink_while_reading(path);
    remove(path);

    gdt_error_clear(&err);
    CHECK(gdt_source_open(&src, path, NULL, &err) == GDT_EINPUT && src == NULL);
    CHECK(strstr(err.msg, path) != NULL);

    return gdt_check_finish(&checks, "test_las_stream");
}
