/* test_tri_seam — the parser of a .tri file's header and seam section
 * (tr_tri_check_header, tr_tri_read_seam of tiler/private/tiled_files.h).
 *
 * Files built here, each with the verdict and message number it must get:
 * a valid tile (its seam appended after the entries already there), a
 * header alone, a short file, a foreign magic, base or point count, another
 * job's id, counts whose byte sum wraps around 64 bits to the file's size
 * (faces, seam vertices, barrier edges), sizes a record short or a byte
 * long, more seam vertices than points, ids outside the tile and
 * coordinates outside the merge frame.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "private/tiled_files.h"

static gdt_checks T = {0, 0};

#define CHECK(cond, ...) GDT_CHECK(&T, cond, __VA_ARGS__)

static const uint64_t JOB[2] = {0x1111, 0x2222};

/* A file image under construction. */
typedef struct img {
    unsigned char b[512];
    size_t n;
} img;

static void put(img *m, uint64_t v)
{
    tr_put_u64(m->b + m->n, v);
    m->n += 8;
}

static void header(img *m, uint64_t base, uint64_t points, uint64_t nf, uint64_t nv, uint64_t ne,
                   uint64_t job1)
{
    memcpy(m->b, TR_MAGIC, 8);
    m->n = 8;
    put(m, base);
    put(m, points);
    put(m, nf);
    put(m, nv);
    put(m, ne);
    put(m, JOB[0]);
    put(m, job1);
}

static void vertex(img *m, uint64_t id, int64_t x, int64_t y)
{
    put(m, id);
    put(m, (uint64_t)x);
    put(m, (uint64_t)y);
    put(m, UINT64_C(0x4059000000000000)); /* z = 100.0 */
}

/* Reads m as tile (base, points) of job JOB into a seam holding one
 * entry of each kind; wants (verdict, code: 0 for success) and, on
 * success, nv and ne entries appended. */
static void one(const char *what, const img *m, uint64_t base, uint64_t points,
                tr_tri_verdict want_v, int want_code, size_t nv, size_t ne)
{
    static unsigned char scratch[TR_SEAM_VERTEX * (size_t)TR_CHUNK];
    tr_tri_expect ex = {base, points, JOB, 0};
    gdt_seam s;
    gdt_error err;
    uint64_t f_nf, f_nv, f_ne;
    FILE *f = tmpfile();
    gdt_status st;

    memset(&s, 0, sizeof s);
    s.v = malloc(sizeof *s.v);
    s.e = malloc(sizeof *s.e);
    if (f == NULL || s.v == NULL || s.e == NULL || fwrite(m->b, 1, m->n, f) != m->n) {
        CHECK(0, "%s: cannot set up", what);
        return;
    }
    s.nv = s.ne = s.cap_v = s.cap_e = 1;
    s.v[0] = (gdt_seam_vertex){9, 1, 1, 0.0};
    s.e[0] = (gdt_seam_edge){9, 8};
    if (m->n >= TR_HEADER)
        CHECK(tr_tri_check_header(m->b, m->n, &ex, &f_nf, &f_nv, &f_ne) == want_v,
              "%s: verdict", what);
    gdt_error_clear(&err);
    st = tr_tri_read_seam(f, m->n, &ex, &s, scratch, "t.tri", &err);
    if (want_code == 0) {
        CHECK(st == GDT_OK, "%s: %s", what, err.msg);
        CHECK(s.nv == 1 + nv && s.ne == 1 + ne && s.v[0].id == 9 && s.e[0].b == 8,
              "%s: seam of %zu vertices, %zu edges", what, s.nv, s.ne);
    } else {
        CHECK(st != GDT_OK && err.code == want_code && (int)st == want_code / 1000,
              "%s: status %d, message %d (%s), want %d", what, (int)st, err.code, err.msg,
              want_code);
    }
    fclose(f);
    free(s.v);
    free(s.e);
}

int main(void)
{
    img m;

    header(&m, 10, 4, 1, 2, 1, JOB[1]);
    put(&m, 0); /* a face: 12 bytes */
    put(&m, 0);
    m.n -= 4;
    vertex(&m, 10, 0, 5);
    vertex(&m, 13, GDT_COORD_MAX, 0);
    put(&m, 10);
    put(&m, 13);
    one("valid", &m, 10, 4, TR_TRI_FITS, 0, 2, 1);
    one("foreign base", &m, 11, 4, TR_TRI_FOREIGN, 6801, 0, 0);
    one("foreign point count", &m, 10, 5, TR_TRI_FOREIGN, 6801, 0, 0);
    header(&m, 0, 0, 0, 0, 0, JOB[1]);
    one("header alone", &m, 0, 0, TR_TRI_FITS, 0, 0, 0);
    m.n = 40;
    one("short header", &m, 0, 0, TR_TRI_FOREIGN, 6801, 0, 0);
    header(&m, 0, 4, 0, 0, 0, JOB[1] + 1);
    one("another job", &m, 0, 4, TR_TRI_JOB, 6801, 0, 0);
    header(&m, 0, 4, 0, 0, 0, JOB[1]);
    m.b[7] = '9';
    one("magic", &m, 0, 4, TR_TRI_FOREIGN, 6801, 0, 0);
    /* 12 * 2^62, 32 * 2^59 and 16 * 2^60 are 0 modulo 2^64 */
    header(&m, 0, 4, (uint64_t)1 << 62, 1, 0, JOB[1]);
    vertex(&m, 1, 1, 1);
    one("faces wrap", &m, 0, 4, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, 0, 4, 0, ((uint64_t)1 << 59) + 1, 0, JOB[1]);
    vertex(&m, 1, 1, 1);
    one("seam vertices wrap", &m, 0, 4, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, 0, 4, 0, 1, (uint64_t)1 << 60, JOB[1]);
    vertex(&m, 1, 1, 1);
    one("barrier edges wrap", &m, 0, 4, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, 0, 4, 0, 2, 0, JOB[1]);
    vertex(&m, 1, 1, 1);
    one("a vertex short", &m, 0, 4, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, 0, 4, 0, 1, 0, JOB[1]);
    vertex(&m, 1, 1, 1);
    m.b[m.n++] = 0;
    one("a byte long", &m, 0, 4, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, 0, 1, 0, 2, 0, JOB[1]);
    vertex(&m, 0, 1, 1);
    vertex(&m, 0, 1, 1);
    one("more seam vertices than points", &m, 0, 1, TR_TRI_SIZE, 6802, 0, 0);
    header(&m, UINT64_MAX - 1, 5, 0, 0, 0, JOB[1]);
    one("base + points wraps", &m, UINT64_MAX - 1, 5, TR_TRI_FOREIGN, 6801, 0, 0);
    header(&m, 100, 5, 0, 1, 0, JOB[1]);
    vertex(&m, 105, 1, 1);
    one("id past the tile", &m, 100, 5, TR_TRI_FITS, 6802, 0, 0);
    header(&m, 100, 5, 0, 1, 0, JOB[1]);
    vertex(&m, 99, 1, 1);
    one("id before the tile", &m, 100, 5, TR_TRI_FITS, 6802, 0, 0);
    header(&m, 0, 5, 0, 1, 0, JOB[1]);
    vertex(&m, 0, -1, 1);
    one("x below the frame", &m, 0, 5, TR_TRI_FITS, 6802, 0, 0);
    header(&m, 0, 5, 0, 1, 0, JOB[1]);
    vertex(&m, 0, 1, GDT_COORD_MAX + 1);
    one("y past the frame", &m, 0, 5, TR_TRI_FITS, 6802, 0, 0);
    header(&m, 0, 5, 0, 2, 1, JOB[1]);
    vertex(&m, 0, 1, 1);
    vertex(&m, 4, 2, 2);
    put(&m, 4);
    put(&m, 5);
    one("edge end past the tile", &m, 0, 5, TR_TRI_FITS, 6802, 0, 0);
    return gdt_check_finish(&T, "test_tri_seam");
}
