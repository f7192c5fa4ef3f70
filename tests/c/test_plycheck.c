/* test_plycheck — unit test of the streaming exact PLY checker.
 *
 *   test_plycheck WORKDIR
 *
 * Meshes are triangulated by the CPU reference triangulator and written with
 * the PLY writer into a fresh folder under WORKDIR (removed at the end).
 * Every check runs twice: with the default budget (all in memory for these
 * sizes) and with the smallest budget (64 KiB), which sends the larger
 * meshes through temporary files, nested splits and several windows of the
 * vertex-use bitmap.  Asserted:
 *   - valid meshes of random and degenerate point sets pass with the same
 *     counts under both budgets, those counts agree with the mesh (F, h from
 *     Euler, interior edges = (3F - h) / 2), the heap peak stays within the
 *     budget, the small budget really spills, and no temporary file is left;
 *   - each planted fault is refused with its own message number, naming the
 *     face, edge or vertex at fault (wrong co-circular diagonal, non-Delaunay
 *     edge, missing face, notch in the hull, duplicated vertex, inverted
 *     face, unused vertex, index out of range, repeated index, bad count
 *     byte, edge in three faces or in the same direction twice, bow-tie,
 *     two separate pieces, off-lattice vertex, no faces on non-collinear
 *     points), also inside large meshes under the small budget;
 *   - bad files (truncated, trailing bytes, not PLY, other format, no
 *     lattice, extent beyond 2^31 - 1, absent) give GDT_EINPUT / GDT_EIO
 *     with the file name; an unusable temporary directory gives GDT_EIO.
 */
#include <dirent.h>
#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_plycheck.h"
#include "gdt_ply.h"
#include "gdt_reference.h"
#include "gen_degenerate.h"

typedef struct ctx {
    tctx c;
    char dir[4000];   /* work folder */
    char spill[4200]; /* temporary folder given to the checker */
    int serial;
} ctx;

/* A mesh as plain arrays (owned), easy to damage. */
typedef struct tm {
    gdt_ipt *pts;
    size_t nv;
    int32_t *tri;
    size_t nf;
} tm;

static const gdt_lattice LAT = {0.001, 0.002, 480000.0, 4860000.0};
/* Lattice integers of tile-local point (0, 0): exercises the origin shift. */
#define BASE_X INT64_C(-700000)
#define BASE_Y INT64_C(123456789)

static void tm_free(tm *m)
{
    free(m->pts);
    free(m->tri);
    memset(m, 0, sizeof *m);
}

static int tm_copy(tm *dst, const tm *src)
{
    memset(dst, 0, sizeof *dst);
    dst->pts = malloc((src->nv + 2) * sizeof *dst->pts);
    dst->tri = malloc((3 * src->nf + 9) * sizeof *dst->tri);
    if (dst->pts == NULL || dst->tri == NULL) {
        tm_free(dst);
        return -1;
    }
    if (src->nv > 0)
        memcpy(dst->pts, src->pts, src->nv * sizeof *dst->pts);
    if (src->nf > 0)
        memcpy(dst->tri, src->tri, 3 * src->nf * sizeof *dst->tri);
    dst->nv = src->nv;
    dst->nf = src->nf;
    return 0;
}

/* Triangulates pts with the reference; 0 on success. */
static int tm_triangulate(const gdt_ipt *pts, size_t n, tm *out)
{
    gdt_mesh m;
    gdt_error err;
    int rc = -1;

    memset(out, 0, sizeof *out);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    if (gdt_reference_triangulate(NULL, pts, n, &m, &err) != GDT_OK) {
        fprintf(stderr, "test_plycheck: reference failed: %s\n", err.msg);
        goto fail;
    }
    tm src = {m.pts, m.nverts, m.tri, m.ntris};
    if (tm_copy(out, &src) != 0)
        goto fail;
    rc = 0;
fail:
    gdt_mesh_free(&m);
    return rc;
}

static void next_path(ctx *t, char *out, size_t size, const char *label)
{
    snprintf(out, size, "%s/m%03d-%s.ply", t->dir, t->serial++, label);
}

/* Writes m with the PLY writer: x = ox + sx * (BASE_X + p.x), and so on. */
static int write_mesh(const char *path, const tm *m, const gdt_lattice *lat, int64_t bx, int64_t by)
{
    gdt_ply_meta meta;
    gdt_ply_writer *w = NULL;
    gdt_error err;
    double *xyz = malloc((3 * m->nv + 1) * sizeof *xyz);

    if (xyz == NULL)
        return -1;
    for (size_t i = 0; i < m->nv; i++) {
        xyz[3 * i] = lat->ox + lat->sx * (double)(m->pts[i].x + bx);
        xyz[3 * i + 1] = lat->oy + lat->sy * (double)(m->pts[i].y + by);
        xyz[3 * i + 2] = 0.5 * (double)i;
    }
    memset(&meta, 0, sizeof meta);
    meta.lattice = *lat;
    gdt_error_clear(&err);
    if (gdt_ply_create(&w, path, &meta, &err) != GDT_OK ||
        gdt_ply_write_vertices(w, xyz, m->nv, &err) != GDT_OK ||
        (m->nf > 0 && gdt_ply_write_faces(w, m->tri, m->nf, &err) != GDT_OK)) {
        fprintf(stderr, "test_plycheck: writing %s: %s\n", path, err.msg);
        gdt_ply_abort(w);
        free(xyz);
        return -1;
    }
    free(xyz);
    if (gdt_ply_finish(w, &err) != GDT_OK) {
        fprintf(stderr, "test_plycheck: finishing %s: %s\n", path, err.msg);
        return -1;
    }
    return 0;
}

/* Byte offset of the end of the header of a written file. */
static long header_len(const char *path)
{
    FILE *f = fopen(path, "rb");
    char line[8192];
    long off = -1;
    if (f == NULL)
        return -1;
    while (fgets(line, sizeof line, f) != NULL)
        if (strcmp(line, "end_header\n") == 0) {
            off = ftell(f);
            break;
        }
    fclose(f);
    return off;
}

static int patch(const char *path, long off, const void *bytes, size_t n)
{
    FILE *f = fopen(path, "r+b");
    int rc = -1;
    if (f == NULL)
        return -1;
    if (fseek(f, off, SEEK_SET) == 0 && fwrite(bytes, 1, n, f) == n)
        rc = 0;
    if (fclose(f) != 0)
        rc = -1;
    return rc;
}

static void put32(unsigned char *p, uint32_t v)
{
    for (int i = 0; i < 4; i++)
        p[i] = (unsigned char)(v >> (8 * i));
}

/* Number of entries of folder d (other than . and ..). */
static int entries(const char *d)
{
    DIR *dp = opendir(d);
    struct dirent *e;
    int n = 0;
    if (dp == NULL)
        return -1;
    while ((e = readdir(dp)) != NULL)
        if (strcmp(e->d_name, ".") != 0 && strcmp(e->d_name, "..") != 0)
            n++;
    closedir(dp);
    return n;
}

static gdt_status run(ctx *t, const char *path, size_t budget, gdt_plycheck_result *res,
                      gdt_error *err)
{
    gdt_plycheck_opts o;
    gdt_plycheck_opts_init(&o);
    o.mem_budget = budget;
    o.temp_dir = t->spill;
    gdt_error_clear(err);
    gdt_status s = gdt_ply_check(&o, path, res, err);
    CHECK(&t->c, entries(t->spill) == 0, "%s: temporary files left in %s", path, t->spill);
    CHECK(&t->c, res->peak_heap <= res->mem_budget, "%s: heap peak %zu above the budget %zu", path,
          res->peak_heap, res->mem_budget);
    return s;
}

/* A valid mesh passes under both budgets with consistent counts.
 * returns the spill bytes under the small budget. */
static uint64_t expect_valid(ctx *t, const char *label, const tm *m)
{
    char path[4200];
    gdt_plycheck_result big, small;
    gdt_error err;

    next_path(t, path, sizeof path, label);
    if (write_mesh(path, m, &LAT, BASE_X, BASE_Y) != 0) {
        CHECK(&t->c, 0, "%s: cannot write", label);
        return 0;
    }
    gdt_status s = run(t, path, 0, &big, &err);
    CHECK(&t->c, s == GDT_OK, "%s: valid mesh refused: GDT-%d %s", label, err.code, err.msg);
    s = run(t, path, GDT_PLYCHECK_MIN_BUDGET, &small, &err);
    CHECK(&t->c, s == GDT_OK, "%s (64 KiB): valid mesh refused: GDT-%d %s", label, err.code,
          err.msg);
    CHECK(&t->c, big.vertices == m->nv && big.faces == m->nf, "%s: counts %llu/%llu", label,
          (unsigned long long)big.vertices, (unsigned long long)big.faces);
    if (m->nf > 0) {
        uint64_t h = 2 * (uint64_t)m->nv - 2 - (uint64_t)m->nf;
        CHECK(&t->c, big.hull_vertices == h, "%s: h = %llu, expected %llu", label,
              (unsigned long long)big.hull_vertices, (unsigned long long)h);
        CHECK(&t->c, big.boundary_edges == h, "%s: %llu boundary edges, expected %llu", label,
              (unsigned long long)big.boundary_edges, (unsigned long long)h);
        CHECK(&t->c, 2 * big.interior_edges == 3 * (uint64_t)m->nf - h,
              "%s: %llu interior edges, expected %llu", label,
              (unsigned long long)big.interior_edges,
              (unsigned long long)((3 * (uint64_t)m->nf - h) / 2));
        CHECK(&t->c, big.collinear == 0, "%s: collinear flag on a mesh with faces", label);
    } else {
        CHECK(&t->c, big.hull_vertices == 0 && big.interior_edges == 0, "%s: counts on F = 0",
              label);
        CHECK(&t->c, big.collinear == (m->nv >= 3), "%s: collinear flag %d", label, big.collinear);
    }
    CHECK(&t->c,
          small.hull_vertices == big.hull_vertices && small.interior_edges == big.interior_edges &&
              small.pred.incircle_calls == big.pred.incircle_calls &&
              small.origin_x == big.origin_x && small.extent_y == big.extent_y,
          "%s: the small budget gives other counts", label);
    if (m->nv > 0) {
        int64_t x0 = m->pts[0].x, x1 = x0, y0 = m->pts[0].y, y1 = y0;
        for (size_t i = 1; i < m->nv; i++) {
            x0 = m->pts[i].x < x0 ? m->pts[i].x : x0;
            x1 = m->pts[i].x > x1 ? m->pts[i].x : x1;
            y0 = m->pts[i].y < y0 ? m->pts[i].y : y0;
            y1 = m->pts[i].y > y1 ? m->pts[i].y : y1;
        }
        CHECK(&t->c,
              big.origin_x == BASE_X + x0 && big.origin_y == BASE_Y + y0 &&
                  big.extent_x == x1 - x0 && big.extent_y == y1 - y0,
              "%s: origin (%lld, %lld) extent (%lld, %lld)", label, (long long)big.origin_x,
              (long long)big.origin_y, (long long)big.extent_x, (long long)big.extent_y);
    }
    CHECK(&t->c, big.spill_bytes == 0 && big.spill_splits == 0,
          "%s: the default budget spilled %llu bytes", label, (unsigned long long)big.spill_bytes);
    /* Under 64 KiB a sorted bucket holds 1170 records and one level has at
     * most 4 buckets: more half-edges than 4 x 1170 force a second split. */
    if (3 * m->nf > 4 * 1170)
        CHECK(&t->c, small.spill_splits > 0, "%s: %zu faces: no bucket was split", label, m->nf);
    if (12 * m->nf * sizeof(uint32_t) > GDT_PLYCHECK_MIN_BUDGET)
        CHECK(&t->c, small.spill_bytes > 0 && small.spill_files > 0,
              "%s: %zu faces did not spill under 64 KiB", label, m->nf);
    remove(path);
    return small.spill_bytes;
}

/* The file at path is refused under both budgets with st / code, and the
 * message names the file and contains want (when not NULL). */
static void expect_fault_file(ctx *t, const char *label, const char *path, gdt_status st, int code,
                              const char *want)
{
    static const size_t budgets[2] = {0, GDT_PLYCHECK_MIN_BUDGET};
    for (int k = 0; k < 2; k++) {
        gdt_plycheck_result res;
        gdt_error err;
        gdt_status s = run(t, path, budgets[k], &res, &err);
        CHECK(&t->c, s == st && err.code == code,
              "%s (budget %zu): expected status %d code %d, got %d code %d: %s", label, budgets[k],
              (int)st, code, (int)s, err.code, err.msg);
        CHECK(&t->c, strstr(err.msg, path) != NULL, "%s: message does not name the file: %s", label,
              err.msg);
        if (want != NULL)
            CHECK(&t->c, strstr(err.msg, want) != NULL, "%s: message lacks '%s': %s", label, want,
                  err.msg);
    }
}

static void expect_fault(ctx *t, const char *label, const tm *m, int code, const char *want)
{
    char path[4200];
    next_path(t, path, sizeof path, label);
    if (write_mesh(path, m, &LAT, BASE_X, BASE_Y) != 0) {
        CHECK(&t->c, 0, "%s: cannot write", label);
        return;
    }
    expect_fault_file(t, label, path, GDT_EINTERNAL, code, want);
    remove(path);
}

/* ---- mesh surgery ---- */

static int32_t *face(tm *m, size_t k)
{
    return m->tri + 3 * k;
}

static int has(const int32_t *f, int32_t v)
{
    return f[0] == v || f[1] == v || f[2] == v;
}

/* Faces holding edge a-b: returns how many (up to 2 stored in k). */
static int edge_faces(const tm *m, int32_t a, int32_t b, size_t k[2])
{
    int n = 0;
    for (size_t f = 0; f < m->nf; f++)
        if (has(m->tri + 3 * f, a) && has(m->tri + 3 * f, b)) {
            if (n < 2)
                k[n] = f;
            n++;
        }
    return n;
}

static int32_t apex(const int32_t *f, int32_t a, int32_t b)
{
    for (int i = 0; i < 3; i++)
        if (f[i] != a && f[i] != b)
            return f[i];
    return -1;
}

/* Replaces the two faces on edge a-b by the other diagonal c-d, keeping
 * both counter-clockwise (the quad must be strictly convex). */
static int flip(tm *m, int32_t a, int32_t b)
{
    size_t k[2];
    if (edge_faces(m, a, b, k) != 2)
        return -1;
    int32_t *f1 = face(m, k[0]), *f2 = face(m, k[1]);
    int32_t c = apex(f1, a, b), d = apex(f2, a, b);
    /* Orient so that f1 = (p, q, c) with p -> q its traversal of the edge. */
    int32_t p = a, q = b;
    for (int i = 0; i < 3; i++)
        if (f1[i] == b && f1[(i + 1) % 3] == a)
            p = b, q = a;
    /* (p, q, c) and (q, p, d) CCW  ->  (p, d, c) and (d, q, c). */
    f1[0] = p, f1[1] = d, f1[2] = c;
    f2[0] = d, f2[1] = q, f2[2] = c;
    return 0;
}

static void remove_face(tm *m, size_t k)
{
    memmove(m->tri + 3 * k, m->tri + 3 * (k + 1), 3 * (m->nf - k - 1) * sizeof *m->tri);
    m->nf--;
}

/* Sorted undirected keys (min << 32 | max) of all 3F half-edges, for
 * counting the faces of an edge in O(log F). */
typedef struct eidx {
    uint64_t *k;
    size_t n;
} eidx;

static uint64_t ekey(int32_t a, int32_t b)
{
    return a < b ? (uint64_t)a << 32 | (uint32_t)b : (uint64_t)b << 32 | (uint32_t)a;
}

static int cmp_u64(const void *x, const void *y)
{
    uint64_t a = *(const uint64_t *)x, b = *(const uint64_t *)y;
    return (a > b) - (a < b);
}

static int eidx_build(const tm *m, eidx *e)
{
    e->n = 3 * m->nf;
    e->k = malloc((e->n + 1) * sizeof *e->k);
    if (e->k == NULL)
        return -1;
    for (size_t f = 0; f < m->nf; f++)
        for (int i = 0; i < 3; i++)
            e->k[3 * f + (size_t)i] =
                ekey(m->tri[3 * f + (size_t)i], m->tri[3 * f + (size_t)(i + 1) % 3]);
    qsort(e->k, e->n, sizeof *e->k, cmp_u64);
    return 0;
}

static size_t eidx_count(const eidx *e, int32_t a, int32_t b)
{
    uint64_t key = ekey(a, b);
    size_t lo = 0, hi = e->n;
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (e->k[mid] < key)
            lo = mid + 1;
        else
            hi = mid;
    }
    size_t n = 0;
    while (lo + n < e->n && e->k[lo + n] == key)
        n++;
    return n;
}

/* hull[v] = 1 for the vertices on a boundary edge (malloc'ed). */
static unsigned char *hull_flags(const tm *m, const eidx *e)
{
    unsigned char *hv = calloc(m->nv + 1, 1);
    if (hv == NULL)
        return NULL;
    for (size_t f = 0; f < m->nf; f++)
        for (int i = 0; i < 3; i++) {
            int32_t a = m->tri[3 * f + (size_t)i], b = m->tri[3 * f + (size_t)(i + 1) % 3];
            if (eidx_count(e, a, b) == 1)
                hv[a] = hv[b] = 1;
        }
    return hv;
}

/* Number of faces vertex v is in. */
static size_t degree(const tm *m, int32_t v)
{
    size_t n = 0;
    for (size_t f = 0; f < m->nf; f++)
        n += has(m->tri + 3 * f, v) != 0;
    return n;
}

/* ---- valid meshes ---- */

static void test_valid(ctx *t)
{
    gen_rng r;
    size_t n;
    gdt_ipt *p;
    tm m;
    char label[64];

    gen_seed(&r, 20240611);
    for (int k = 0; k < 3; k++) {
        p = gen_uniform(&r, 300 + 700 * (size_t)k, 0, 5000, &n);
        if (p != NULL && tm_triangulate(p, n, &m) == 0) {
            snprintf(label, sizeof label, "uniform%d", k);
            expect_valid(t, label, &m);
            tm_free(&m);
        }
        free(p);
    }
    struct {
        const char *name;
        gdt_ipt *pts;
        size_t n;
    } sets[] = {
        {"grid", NULL, 0},     {"rotgrid", NULL, 0},  {"circle", NULL, 0},    {"thin", NULL, 0},
        {"clusters", NULL, 0}, {"extremes", NULL, 0}, {"collinear", NULL, 0}, {"one", NULL, 0},
        {"two", NULL, 0},      {"three", NULL, 0},    {"empty", NULL, 0},
    };
    sets[0].pts = gen_grid(23, 17, 100, 200, 7, &sets[0].n);
    sets[1].pts = gen_rotated_grid(9, 3, 4, 1000, 1000, &sets[1].n);
    sets[2].pts = gen_circle(10000, 10000, 5 * 5 * 13 * 17, &sets[2].n);
    sets[3].pts = gen_thin_circle(&r, 400, 100000, 100000, 50000, 3, &sets[3].n);
    sets[4].pts = gen_clusters(&r, 6, 150, 40, &sets[4].n);
    sets[5].pts = gen_extremes(&r, &sets[5].n);
    sets[6].pts = gen_collinear(&r, 50, 10, 20, 3, 7, 1000, &sets[6].n);
    sets[7].pts = gen_grid(1, 1, 5, 5, 1, &sets[7].n);
    sets[8].pts = gen_grid(2, 1, 5, 5, 3, &sets[8].n);
    sets[9].pts = gen_grid(3, 1, 5, 5, 3, &sets[9].n);
    for (size_t k = 0; k < sizeof sets / sizeof sets[0]; k++) {
        if (strcmp(sets[k].name, "three") == 0 && sets[k].pts != NULL)
            sets[k].pts[2].y += 4; /* a real triangle */
        if (sets[k].pts == NULL && strcmp(sets[k].name, "empty") != 0) {
            CHECK(&t->c, 0, "generator %s failed", sets[k].name);
            continue;
        }
        if (tm_triangulate(sets[k].pts, sets[k].n, &m) == 0) {
            expect_valid(t, sets[k].name, &m);
            tm_free(&m);
        } else {
            CHECK(&t->c, 0, "%s: reference failed", sets[k].name);
        }
        free(sets[k].pts);
    }
}

/* ---- planted faults ---- */

static void test_faults_small(ctx *t)
{
    size_t n;
    gdt_ipt *p = gen_grid(5, 5, 10, 10, 1, &n);
    tm g, m;
    char want[128];

    if (p == NULL || tm_triangulate(p, n, &g) != 0) {
        CHECK(&t->c, 0, "grid setup failed");
        free(p);
        return;
    }
    free(p);
    /* Vertex i*5 + j of gen_grid(5, 5) is (10 + i, 10 + j) (x-major). */
    int32_t a = -1, b = -1;
    for (int32_t v = 0; v < (int32_t)g.nv; v++) {
        if (g.pts[v].x == 12 && g.pts[v].y == 12)
            a = v;
        if (g.pts[v].x == 13 && g.pts[v].y == 13)
            b = v;
    }
    size_t k2[2];
    CHECK(&t->c, a >= 0 && b >= 0 && edge_faces(&g, a, b, k2) == 2,
          "the grid mesh lacks the (1, 1) diagonal of cell (12, 12)");

    /* Wrong co-circular diagonal. */
    if (tm_copy(&m, &g) == 0 && flip(&m, a, b) == 0) {
        expect_fault(t, "cocircular", &m, 7371, "loses the tie-break");
        tm_free(&m);
    }
    /* Inverted face. */
    if (tm_copy(&m, &g) == 0) {
        int32_t *f = face(&m, 3), x = f[1];
        f[1] = f[2], f[2] = x;
        snprintf(want, sizeof want, "face 3 = (%d, %d, %d)", f[0], f[1], f[2]);
        expect_fault(t, "inverted", &m, 7366, want);
        expect_fault(t, "inverted", &m, 7366, "clockwise");
        tm_free(&m);
    }
    /* Duplicated vertex (unused copy, then the copy used in one face). */
    if (tm_copy(&m, &g) == 0) {
        m.pts[m.nv++] = m.pts[6];
        snprintf(want, sizeof want, "vertices 6 and %zu", m.nv - 1);
        expect_fault(t, "dupvertex", &m, 7361, want);
        for (size_t f = 0; f < m.nf; f++)
            for (int i = 0; i < 3; i++)
                if (m.tri[3 * f + (size_t)i] == 6) {
                    m.tri[3 * f + (size_t)i] = (int32_t)(m.nv - 1);
                    f = m.nf;
                    break;
                }
        expect_fault(t, "dupvertex-used", &m, 7361, want);
        tm_free(&m);
    }
    /* Unused vertex. */
    if (tm_copy(&m, &g) == 0) {
        m.pts[m.nv].x = 100;
        m.pts[m.nv].y = 3;
        m.nv++;
        snprintf(want, sizeof want, "vertex %zu at lattice point (%lld, %lld) is in no face",
                 m.nv - 1, (long long)(100 + BASE_X), (long long)(3 + BASE_Y));
        expect_fault(t, "unused", &m, 7367, want);
        tm_free(&m);
    }
    /* Missing interior face: a hole, whose boundary turns right. */
    eidx ge;
    if (eidx_build(&g, &ge) != 0) {
        CHECK(&t->c, 0, "out of memory");
        tm_free(&g);
        return;
    }
    if (tm_copy(&m, &g) == 0) {
        unsigned char *hv = hull_flags(&m, &ge);
        for (size_t f = 0; hv != NULL && f < m.nf; f++) {
            int32_t *q = face(&m, f);
            if (!hv[q[0]] && !hv[q[1]] && !hv[q[2]]) {
                remove_face(&m, f);
                break;
            }
        }
        free(hv);
        CHECK(&t->c, m.nf + 1 == g.nf, "no interior face found");
        expect_fault(t, "hole", &m, 7373, "reflex");
        tm_free(&m);
    }
    /* Notch: remove the hull face of the corner cell at (10, 10) whose third
     * vertex is interior-free of loss: (10,10), (11,10), (11,11). */
    if (tm_copy(&m, &g) == 0) {
        for (size_t f = 0; f < m.nf; f++) {
            int32_t *q = face(&m, f);
            int corner = 0, right = 0, diag = 0;
            for (int i = 0; i < 3; i++) {
                gdt_ipt s = m.pts[q[i]];
                corner += s.x == 10 && s.y == 10;
                right += s.x == 11 && s.y == 10;
                diag += s.x == 11 && s.y == 11;
            }
            if (corner && right && diag) {
                remove_face(&m, f);
                break;
            }
        }
        CHECK(&t->c, m.nf + 1 == g.nf, "corner face not found");
        expect_fault(t, "notch", &m, 7373, "reflex");
        tm_free(&m);
    }
    /* The same face twice: its edges are in three faces.  A new face on the
     * hull edge (10,10) -> (11,10), on the inner side: that edge is then
     * traversed twice in the same direction. */
    if (tm_copy(&m, &g) == 0) {
        memcpy(face(&m, m.nf), face(&m, 0), 3 * sizeof(int32_t));
        m.nf++;
        expect_fault(t, "sameface", &m, 7368, "in 3 faces");
        tm_free(&m);
    }
    if (tm_copy(&m, &g) == 0) {
        int32_t c0 = -1, c1 = -1;
        for (int32_t v = 0; v < (int32_t)m.nv; v++) {
            if (m.pts[v].x == 10 && m.pts[v].y == 10)
                c0 = v;
            if (m.pts[v].x == 11 && m.pts[v].y == 10)
                c1 = v;
        }
        m.pts[m.nv].x = 40;
        m.pts[m.nv].y = 60;
        int32_t *q = face(&m, m.nf);
        q[0] = c0, q[1] = c1, q[2] = (int32_t)m.nv;
        m.nv++;
        m.nf++;
        snprintf(want, sizeof want, "edge %d->%d is traversed in the same direction", c0, c1);
        expect_fault(t, "samedir", &m, 7369, want);
        tm_free(&m);
    }
    /* An edge in three faces: a new vertex far above, joined to the
     * diagonal a-b of the cell at (12, 12) (counter-clockwise). */
    if (tm_copy(&m, &g) == 0) {
        m.pts[m.nv].x = 40;
        m.pts[m.nv].y = 60;
        int32_t *q = face(&m, m.nf);
        q[0] = a, q[1] = b, q[2] = (int32_t)m.nv;
        /* (12,12) -> (13,13) -> (40,60) is counter-clockwise. */
        m.nv++;
        m.nf++;
        snprintf(want, sizeof want, "edge %d-%d is in 3 faces", a < b ? a : b, a < b ? b : a);
        expect_fault(t, "threefaces", &m, 7368, want);
        tm_free(&m);
    }
    /* Two separate copies of the grid: two boundary loops. */
    if (tm_copy(&m, &g) == 0) {
        tm two;
        memset(&two, 0, sizeof two);
        two.pts = malloc(2 * m.nv * sizeof *two.pts);
        two.tri = malloc(6 * m.nf * sizeof *two.tri);
        if (two.pts != NULL && two.tri != NULL) {
            for (size_t v = 0; v < m.nv; v++) {
                two.pts[v] = m.pts[v];
                two.pts[m.nv + v].x = m.pts[v].x + 50;
                two.pts[m.nv + v].y = m.pts[v].y;
            }
            for (size_t h = 0; h < 3 * m.nf; h++) {
                two.tri[h] = m.tri[h];
                two.tri[3 * m.nf + h] = m.tri[h] + (int32_t)m.nv;
            }
            two.nv = 2 * m.nv;
            two.nf = 2 * m.nf;
            expect_fault(t, "twopieces", &two, 7374, "several loops");
        }
        tm_free(&two);
        tm_free(&m);
    }
    /* Bow-tie: two triangles sharing one vertex. */
    {
        gdt_ipt bp[5] = {{0, 0}, {4, 1}, {1, 4}, {-4, -1}, {-1, -4}};
        int32_t bt[6] = {0, 1, 2, 0, 3, 4};
        for (int i = 0; i < 5; i++)
            bp[i].x += 10, bp[i].y += 10;
        tm bow = {bp, 5, bt, 2};
        expect_fault(t, "bowtie", &bow, 7372, "vertex 0 is on 4 boundary edges");
    }
    /* No faces on points that are not collinear. */
    {
        gdt_ipt tp[3] = {{0, 0}, {5, 0}, {0, 5}};
        tm tri = {tp, 3, NULL, 0};
        expect_fault(t, "nofaces", &tri, 7362, "not collinear");
    }
    /* A degenerate face on collinear points. */
    {
        gdt_ipt lp[3] = {{0, 0}, {1, 1}, {2, 2}};
        int32_t lt[3] = {0, 1, 2};
        tm line = {lp, 3, lt, 1};
        expect_fault(t, "flat", &line, 7366, "degenerate (collinear)");
    }

    /* Faults that the writer refuses are patched into the file. */
    char path[4200];
    next_path(t, path, sizeof path, "patched");
    if (write_mesh(path, &g, &LAT, BASE_X, BASE_Y) == 0) {
        long h = header_len(path);
        long f7 = h + 24 * (long)g.nv + 13 * 7;
        unsigned char rec[13];
        FILE *fp = fopen(path, "rb");
        int ok = fp != NULL && fseek(fp, f7, SEEK_SET) == 0 && fread(rec, 1, 13, fp) == 13;
        if (fp != NULL)
            fclose(fp);
        CHECK(&t->c, h > 0 && ok, "cannot read back %s", path);
        unsigned char bad[13];
        memcpy(bad, rec, 13);
        put32(bad + 5, (uint32_t)g.nv + 4);
        if (patch(path, f7, bad, 13) == 0) {
            snprintf(want, sizeof want, "face 7 = (%d, %d, %d): vertex index %d", g.tri[21],
                     (int)g.nv + 4, g.tri[23], (int)g.nv + 4);
            expect_fault_file(t, "outofrange", path, GDT_EINTERNAL, 7364, want);
        }
        put32(bad + 5, (uint32_t)-3);
        if (patch(path, f7, bad, 13) == 0)
            expect_fault_file(t, "negative", path, GDT_EINTERNAL, 7364, "vertex index -3");
        memcpy(bad, rec, 13);
        memcpy(bad + 5, bad + 1, 4);
        if (patch(path, f7, bad, 13) == 0)
            expect_fault_file(t, "repeat", path, GDT_EINTERNAL, 7365, "face 7");
        memcpy(bad, rec, 13);
        bad[0] = 4;
        if (patch(path, f7, bad, 13) == 0)
            expect_fault_file(t, "arity", path, GDT_EINTERNAL, 7363, "face 7 has 4");
        patch(path, f7, rec, 13);
        /* Off the lattice by 0.4 steps. */
        double x = LAT.ox + LAT.sx * (double)(g.pts[4].x + BASE_X) + 0.4 * LAT.sx;
        unsigned char xb[8];
        uint64_t u;
        memcpy(&u, &x, 8);
        for (int i = 0; i < 8; i++)
            xb[i] = (unsigned char)(u >> (8 * i));
        if (patch(path, h + 24 * 4, xb, 8) == 0)
            expect_fault_file(t, "offlattice", path, GDT_EINTERNAL, 7360, "vertex 4 at");
        remove(path);
    }
    free(ge.k);
    tm_free(&g);
}

/* Faults inside a large mesh, caught through the spill files under the
 * small budget too. */
static void test_faults_large(ctx *t)
{
    gen_rng r;
    size_t n;
    gdt_ipt *p;
    tm g, m;
    char want[160];

    eidx ge;
    gen_seed(&r, 77);
    p = gen_uniform(&r, 70000, 0, 1 << 22, &n);
    if (p == NULL || tm_triangulate(p, n, &g) != 0 || eidx_build(&g, &ge) != 0) {
        CHECK(&t->c, 0, "large setup failed");
        free(p);
        return;
    }
    free(p);
    uint64_t sp = expect_valid(t, "large", &g);
    CHECK(&t->c, sp > 48 * (uint64_t)g.nf, "large: only %llu bytes spilled",
          (unsigned long long)sp);

    /* Non-Delaunay edge: flip a strictly convex interior edge of a late face. */
    if (tm_copy(&m, &g) == 0) {
        int done = 0;
        for (size_t f = m.nf - 1; f > 0 && !done; f--)
            for (int i = 0; i < 3 && !done; i++) {
                int32_t a = m.tri[3 * f + (size_t)i], b = m.tri[3 * f + (size_t)(i + 1) % 3];
                size_t k[2];
                if (eidx_count(&ge, a, b) != 2 || edge_faces(&m, a, b, k) != 2)
                    continue;
                int32_t c = apex(face(&m, k[0]), a, b), d = apex(face(&m, k[1]), a, b);
                gdt_ipt A = m.pts[a], B = m.pts[b], C = m.pts[c], D = m.pts[d];
                if (gdt_orient2d(NULL, A, B, C) * gdt_orient2d(NULL, A, B, D) < 0 &&
                    gdt_orient2d(NULL, C, D, A) * gdt_orient2d(NULL, C, D, B) < 0 &&
                    gdt_incircle(NULL, A, B, C, D) != 0 && flip(&m, a, b) == 0)
                    done = 1;
            }
        CHECK(&t->c, done, "no flippable edge found");
        expect_fault(t, "nondelaunay", &m, 7370, "strictly inside the circumcircle");
        tm_free(&m);
    }
    /* Missing face with interior vertices near the end of the list. */
    if (tm_copy(&m, &g) == 0) {
        unsigned char *hv = hull_flags(&m, &ge);
        for (size_t f = m.nf - 1; hv != NULL && f > 0; f--) {
            int32_t *q = face(&m, f);
            if (!hv[q[0]] && !hv[q[1]] && !hv[q[2]]) {
                remove_face(&m, f);
                break;
            }
        }
        free(hv);
        expect_fault(t, "largehole", &m, 7373, "reflex");
        tm_free(&m);
    }
    /* Hull face with one boundary edge and an interior apex: a notch. */
    if (tm_copy(&m, &g) == 0) {
        unsigned char *hv = hull_flags(&m, &ge);
        int found = 0;
        for (size_t f = 0; hv != NULL && f < m.nf && !found; f++) {
            int32_t *q = face(&m, f);
            for (int i = 0; i < 3 && !found; i++) {
                int32_t a = q[i], b = q[(i + 1) % 3], c = q[(i + 2) % 3];
                if (!hv[c] && eidx_count(&ge, a, b) == 1 && degree(&m, a) > 1 &&
                    degree(&m, b) > 1) {
                    snprintf(want, sizeof want, "reflex turn %d -> %d -> %d", a, c, b);
                    remove_face(&m, f);
                    found = 1;
                }
            }
        }
        free(hv);
        CHECK(&t->c, found, "no notch candidate");
        expect_fault(t, "largenotch", &m, 7373, want);
        tm_free(&m);
    }
    /* Unused vertex beyond the first bitmap window (65536 under 64 KiB),
     * and a duplicate of a late vertex. */
    if (tm_copy(&m, &g) == 0) {
        m.pts[m.nv].x = (1 << 22) + 9;
        m.pts[m.nv].y = 5;
        m.nv++;
        snprintf(want, sizeof want, "vertex %zu at", m.nv - 1);
        expect_fault(t, "largeunused", &m, 7367, want);
        m.pts[m.nv - 1] = m.pts[m.nv - 7];
        snprintf(want, sizeof want, "vertices %zu and %zu", m.nv - 7, m.nv - 1);
        expect_fault(t, "largedup", &m, 7361, want);
        tm_free(&m);
    }
    /* Inverted late face. */
    if (tm_copy(&m, &g) == 0) {
        int32_t *f = face(&m, m.nf - 2), x = f[0];
        f[0] = f[1], f[1] = x;
        snprintf(want, sizeof want, "face %zu = ", m.nf - 2);
        expect_fault(t, "largeinverted", &m, 7366, want);
        tm_free(&m);
    }
    free(ge.k);
    tm_free(&g);

    /* A co-circular grid large enough to spill: one wrong diagonal. */
    p = gen_grid(120, 120, 0, 0, 3, &n);
    if (p != NULL && tm_triangulate(p, n, &g) == 0) {
        expect_valid(t, "largegrid", &g);
        int32_t a = -1, b = -1;
        for (int32_t v = 0; v < (int32_t)g.nv; v++) {
            if (g.pts[v].x == 300 && g.pts[v].y == 210)
                a = v;
            if (g.pts[v].x == 303 && g.pts[v].y == 213)
                b = v;
        }
        if (tm_copy(&m, &g) == 0) {
            CHECK(&t->c, a >= 0 && b >= 0 && flip(&m, a, b) == 0, "grid diagonal not found");
            expect_fault(t, "largecocircular", &m, 7371, "co-circular");
            tm_free(&m);
        }
        tm_free(&g);
    }
    free(p);

    /* One edge in more faces than a sorted bucket holds under 64 KiB. */
    {
        size_t k = 3000;
        tm fan;
        memset(&fan, 0, sizeof fan);
        fan.pts = malloc((k + 2) * sizeof *fan.pts);
        fan.tri = malloc(3 * k * sizeof *fan.tri);
        if (fan.pts != NULL && fan.tri != NULL) {
            fan.pts[0].x = 0, fan.pts[0].y = 0;
            fan.pts[1].x = 1000000, fan.pts[1].y = 0;
            for (size_t i = 0; i < k; i++) {
                fan.pts[2 + i].x = (int64_t)(7 * i + 3);
                fan.pts[2 + i].y = (int64_t)(i + 1);
                fan.tri[3 * i] = 0, fan.tri[3 * i + 1] = 1, fan.tri[3 * i + 2] = (int32_t)(2 + i);
            }
            fan.nv = k + 2;
            fan.nf = k;
            expect_fault(t, "heavyedge", &fan, 7368, "edge 0-1 is in 3000 faces");
        }
        tm_free(&fan);
    }
}

/* ---- bad files ---- */

static int copy_prefix(const char *src, const char *dst, long n, const char *tail)
{
    FILE *a = fopen(src, "rb"), *b = fopen(dst, "wb");
    int rc = -1;
    if (a != NULL && b != NULL) {
        long k = 0;
        int ch;
        while ((n < 0 || k < n) && (ch = fgetc(a)) != EOF) {
            fputc(ch, b);
            k++;
        }
        if (tail != NULL)
            fputs(tail, b);
        rc = 0;
    }
    if (a != NULL)
        fclose(a);
    if (b != NULL && fclose(b) != 0)
        rc = -1;
    return rc;
}

/* Replaces the first occurrence of from by to (same length) in the header. */
static int patch_header(const char *path, const char *from, const char *to)
{
    FILE *f = fopen(path, "rb");
    char head[8192];
    size_t n;
    if (f == NULL)
        return -1;
    n = fread(head, 1, sizeof head - 1, f);
    fclose(f);
    head[n] = '\0';
    char *at = strstr(head, from);
    if (at == NULL || strlen(from) != strlen(to))
        return -1;
    return patch(path, at - head, to, strlen(to));
}

static int patched(ctx *t, int rc)
{
    CHECK(&t->c, rc == 0, "%s", "a header patch did not apply");
    return rc;
}

static void test_bad_files(ctx *t)
{
    size_t n;
    gdt_ipt *p = gen_grid(4, 4, 0, 0, 2, &n);
    tm g;
    char good[4200], bad[4200];

    if (p == NULL || tm_triangulate(p, n, &g) != 0) {
        CHECK(&t->c, 0, "setup failed");
        free(p);
        return;
    }
    free(p);
    next_path(t, good, sizeof good, "good");
    if (write_mesh(good, &g, &LAT, 0, 0) != 0) {
        CHECK(&t->c, 0, "cannot write %s", good);
        tm_free(&g);
        return;
    }
    struct stat sb;
    stat(good, &sb);

    next_path(t, bad, sizeof bad, "truncated");
    copy_prefix(good, bad, (long)sb.st_size - 5, NULL);
    expect_fault_file(t, "truncated", bad, GDT_EINPUT, 3364, "truncated");
    remove(bad);
    next_path(t, bad, sizeof bad, "trailing");
    copy_prefix(good, bad, -1, "x");
    expect_fault_file(t, "trailing", bad, GDT_EINPUT, 3364, "trailing bytes");
    remove(bad);
    next_path(t, bad, sizeof bad, "header-only");
    copy_prefix(good, bad, header_len(good) - 3, NULL);
    expect_fault_file(t, "cut header", bad, GDT_EINPUT, 3361, "end_header");
    remove(bad);
    next_path(t, bad, sizeof bad, "text");
    copy_prefix(good, bad, 0, "hello, world\n");
    expect_fault_file(t, "text", bad, GDT_EINPUT, 3360, "not a PLY file");
    remove(bad);
    next_path(t, bad, sizeof bad, "empty");
    copy_prefix(good, bad, 0, NULL);
    expect_fault_file(t, "empty", bad, GDT_EINPUT, 3360, "not a PLY file");
    remove(bad);

    next_path(t, bad, sizeof bad, "format");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "binary_little_endian 1.0", "binary_big_endian 1.0   ")) == 0)
        expect_fault_file(t, "format", bad, GDT_EINPUT, 3362, "binary_little_endian 1.0 only");
    remove(bad);
    next_path(t, bad, sizeof bad, "format2");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "binary_little_endian 1.0", "binary_little_endian 2.0")) == 0)
        expect_fault_file(t, "format2", bad, GDT_EINPUT, 3362, "binary_little_endian");
    remove(bad);
    next_path(t, bad, sizeof bad, "float");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "property double y", "property float  y")) == 0)
        expect_fault_file(t, "float", bad, GDT_EINPUT, 3362, "double x, double y");
    remove(bad);
    next_path(t, bad, sizeof bad, "nolattice");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "comment lattice", "comment latticX")) == 0)
        expect_fault_file(t, "nolattice", bad, GDT_EINPUT, 3363, "comment lattice");
    remove(bad);
    next_path(t, bad, sizeof bad, "badlattice");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "comment lattice 0.001", "comment lattice -.001")) == 0)
        expect_fault_file(t, "badlattice", bad, GDT_EINPUT, 3363, "malformed");
    remove(bad);
    next_path(t, bad, sizeof bad, "hugecount");
    copy_prefix(good, bad, -1, NULL);
    if (patched(t, patch_header(bad, "element vertex 16        ", "element vertex 9999999999")) ==
        0)
        expect_fault_file(t, "hugecount", bad, GDT_EINPUT, 3365, "9999999999 vertices");
    remove(bad);

    /* Extent beyond the predicates' range. */
    {
        gdt_ipt ep[3] = {{0, 0}, {(int64_t)1 << 31, 0}, {0, 5}};
        int32_t et[3] = {0, 1, 2};
        tm wide = {ep, 3, et, 1};
        next_path(t, bad, sizeof bad, "wide");
        if (write_mesh(bad, &wide, &LAT, 0, 0) == 0)
            expect_fault_file(t, "wide", bad, GDT_EINPUT, 3366, "2147483648 x 5");
        remove(bad);
        ep[1].x = GDT_COORD_MAX;
        next_path(t, bad, sizeof bad, "widest");
        if (write_mesh(bad, &wide, &LAT, -((int64_t)1 << 40), 0) == 0) {
            gdt_plycheck_result res;
            gdt_error err;
            gdt_status s = run(t, bad, 0, &res, &err);
            CHECK(&t->c, s == GDT_OK && res.extent_x == GDT_COORD_MAX,
                  "extent 2^31 - 1 refused: %s", err.msg);
        }
        remove(bad);
    }

    next_path(t, bad, sizeof bad, "absent");
    expect_fault_file(t, "absent", bad, GDT_EIO, 4360, "cannot open");

    /* Temporary directory that does not exist: only a spilling check needs it. */
    {
        gen_rng r;
        gen_seed(&r, 5);
        gdt_ipt *q = gen_uniform(&r, 3000, 0, 100000, &n);
        tm big;
        if (q != NULL && tm_triangulate(q, n, &big) == 0) {
            next_path(t, bad, sizeof bad, "notemp");
            if (write_mesh(bad, &big, &LAT, 0, 0) == 0) {
                gdt_plycheck_opts o;
                gdt_plycheck_result res;
                gdt_error err;
                char nodir[4200];
                snprintf(nodir, sizeof nodir, "%s/no-such-dir", t->dir);
                gdt_plycheck_opts_init(&o);
                o.temp_dir = nodir;
                gdt_error_clear(&err);
                gdt_status s = gdt_ply_check(&o, bad, &res, &err);
                CHECK(&t->c, s == GDT_OK, "in-memory check needed the temp dir: %s", err.msg);
                o.mem_budget = 1;
                gdt_error_clear(&err);
                s = gdt_ply_check(&o, bad, &res, &err);
                CHECK(&t->c, s == GDT_EIO && err.code == 4362 && strstr(err.msg, nodir) != NULL,
                      "missing temp dir: %d %d %s", (int)s, err.code, err.msg);
                CHECK(&t->c, res.mem_budget == GDT_PLYCHECK_MIN_BUDGET, "budget %zu",
                      res.mem_budget);
                /* Default temporary folder: the PLY's own. */
                o.temp_dir = NULL;
                gdt_error_clear(&err);
                s = gdt_ply_check(&o, bad, &res, &err);
                CHECK(&t->c, s == GDT_OK && res.spill_files > 0, "default temp dir: %s", err.msg);
            }
            remove(bad);
            tm_free(&big);
        }
        free(q);
    }
    CHECK(&t->c, entries(t->dir) == 2, "files left in %s", t->dir);
    {
        gdt_plycheck_result res;
        gdt_error err;
        gdt_error_clear(&err);
        CHECK(&t->c, gdt_ply_check(NULL, NULL, &res, &err) == GDT_EINTERNAL && err.code == 7376,
              "NULL path accepted");
        gdt_error_clear(&err);
        CHECK(&t->c, gdt_ply_check(NULL, good, &res, &err) == GDT_OK, "NULL opts: %s", err.msg);
    }
    remove(good);
    tm_free(&g);
}

int main(int argc, char **argv)
{
    ctx t;
    memset(&t, 0, sizeof t);
    if (argc != 2) {
        fprintf(stderr, "usage: test_plycheck WORKDIR\n");
        return 2;
    }
    snprintf(t.dir, sizeof t.dir, "%s/plycheck-XXXXXX", argv[1]);
    if (mkdtemp(t.dir) == NULL) {
        fprintf(stderr, "test_plycheck: mkdtemp %s: %s\n", t.dir, strerror(errno));
        return 1;
    }
    snprintf(t.spill, sizeof t.spill, "%s/spill", t.dir);
    if (mkdir(t.spill, 0700) != 0) {
        fprintf(stderr, "test_plycheck: mkdir %s: %s\n", t.spill, strerror(errno));
        return 1;
    }
    test_valid(&t);
    test_faults_small(&t);
    test_faults_large(&t);
    test_bad_files(&t);
    rmdir(t.spill);
    rmdir(t.dir);
    return gdt_check_finish(&t.c, "test_plycheck");
}
