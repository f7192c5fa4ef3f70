/* The out-of-core tiler on generated clouds with voids, clusters, duplicates
 * and negative coordinates (written as ascii PCD on the unit lattice):
 *  - every input point lands in exactly one tile, the right one, in input
 *    order (multiset equality of (x, y, z, ord) over the .raw files);
 *  - each tile's points equal a brute-force --dup merge, for every rule;
 *  - each halo equals the brute-force set of points in the halo box;
 *  - the index read back holds the counts pass 2 wrote;
 *  - the tiny test budget takes every spill and merge path and writes
 *    byte-identical files;
 *  - auto cell and halo, density-grid coarsening, refused ranges, and an
 *    input that changes between the passes;
 *  - pass 1 and pass 2 in shares equal one pass: a tile's shares taken into
 *    memory hold its .raw file's records in order, or, when .raw files
 *    must stay, are joined into that file.
 * argv[1]: a work directory (created). */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_cloud.h"
#include "gdt_tiler.h"
#include "gdt_vdb_index.h"
#include "private/tiler_io.h"

static int failures, checks;

#define CHECK(cond, ...)                                                                   \
    do {                                                                                   \
        checks++;                                                                          \
        if (!(cond)) {                                                                     \
            failures++;                                                                    \
            fprintf(stderr, "%s:%d: check failed: %s: ", __FILE__, __LINE__, #cond);       \
            fprintf(stderr, __VA_ARGS__);                                                  \
            fputc('\n', stderr);                                                           \
        }                                                                                  \
    } while (0)

static uint64_t rng_state;

static uint64_t rng(void)
{
    uint64_t z = (rng_state += UINT64_C(0x9e3779b97f4a7c15));
    z = (z ^ (z >> 30)) * UINT64_C(0xbf58476d1ce4e5b9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94d049bb133111eb);
    return z ^ (z >> 31);
}

static int64_t below(int64_t n)
{
    return (int64_t)(rng() % (uint64_t)n);
}

static char workdir[2048];

/* ---- the generated cloud ------------------------------------------------ */

/* Uniform background over [-3000, 3000)^2 with a round lake and a strip
 * without points, dense clusters, re-recorded (x, y) with other z. */
static gdt_point *make_cloud(size_t *n_out, uint64_t seed)
{
    size_t cap = 60000, n = 0;
    gdt_point *p = malloc(cap * sizeof *p);
    rng_state = seed;
    while (n < 30000) {
        int64_t x = below(6000) - 3000, y = below(6000) - 3000;
        if ((x - 800) * (x - 800) + (y + 500) * (y + 500) < 900 * 900)
            continue; /* lake */
        if (x > -2000 && x < -1200)
            continue; /* a strip without returns */
        p[n].x = x;
        p[n].y = y;
        p[n].z = (double)below(100000) / 64.0;
        n++;
    }
    for (int c = 0; c < 6; c++) {
        int64_t cx = below(5000) - 2500, cy = below(5000) - 2500;
        for (int k = 0; k < 1500; k++) {
            p[n].x = cx + below(41) - 20;
            p[n].y = cy + below(41) - 20;
            p[n].z = (double)below(100000) / 64.0;
            n++;
        }
    }
    for (int k = 0; k < 3000; k++) {
        size_t src = (size_t)below((int64_t)n);
        p[n] = p[src];
        p[n].z = (double)below(100000) / 64.0;
        if (k % 8 == 0) { /* equal z of either sign: min-z / max-z ties */
            p[src].z = k % 16 == 0 ? -0.0 : 0.0;
            p[n].z = k % 16 == 0 ? 0.0 : -0.0;
        }
        n++;
    }
    for (size_t k = n; k-- > 1;) { /* shuffle: duplicates anywhere in the stream */
        size_t j = (size_t)below((int64_t)k + 1);
        gdt_point t = p[k];
        p[k] = p[j];
        p[j] = t;
    }
    for (size_t k = 0; k < n; k++)
        p[k].ord = k;
    *n_out = n;
    return p;
}

/* Ascii PCD with fixed-width fields, so a rewrite keeps the file size. */
static int write_pcd(const char *path, const gdt_point *p, size_t n, int64_t shift)
{
    FILE *f = fopen(path, "w");
    if (f == NULL)
        return -1;
    fprintf(f, "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
               "WIDTH %zu\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS %zu\nDATA ascii\n",
            n, n);
    for (size_t k = 0; k < n; k++)
        fprintf(f, "%+09" PRId64 " %+09" PRId64 " %016.6f\n", p[k].x + shift, p[k].y, p[k].z);
    return fclose(f) == 0 ? 0 : -1;
}

/* ---- helpers ------------------------------------------------------------ */

static int64_t fdiv(int64_t a, int64_t b)
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

static int cmp_ord(const void *pa, const void *pb)
{
    const gdt_point *a = pa, *b = pb;
    return (a->ord > b->ord) - (a->ord < b->ord);
}

static int same_point(const gdt_point *a, const gdt_point *b)
{
    return a->x == b->x && a->y == b->y && a->ord == b->ord &&
           memcmp(&a->z, &b->z, sizeof a->z) == 0;
}

/* Reads a record file; *n receives the count.  NULL on failure. */
static gdt_point *read_records(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    unsigned char rec[32];
    size_t cap = 1024;
    gdt_point *p = malloc(cap * sizeof *p);
    *n = 0;
    if (f == NULL) {
        free(p);
        return NULL;
    }
    while (fread(rec, sizeof rec, 1, f) == 1) {
        if (*n == cap) {
            cap *= 2;
            p = realloc(p, cap * sizeof *p);
        }
        tl_rec_get(&p[(*n)++], rec);
    }
    fclose(f);
    return p;
}

/* Same bytes but (possibly) those at [skip0, skip1). */
static int files_equal_but(const char *a, const char *b, long skip0, long skip1)
{
    FILE *fa = fopen(a, "rb"), *fb = fopen(b, "rb");
    int eq = fa != NULL && fb != NULL;
    for (long at = 0; eq; at++) {
        int ca = fgetc(fa), cb = fgetc(fb);
        if (ca != cb && !(at >= skip0 && at < skip1))
            eq = 0;
        if (ca == EOF || cb == EOF)
            break;
    }
    if (fa != NULL)
        fclose(fa);
    if (fb != NULL)
        fclose(fb);
    return eq;
}

static int files_equal(const char *a, const char *b) { return files_equal_but(a, b, 0, 0); }

static void make_dir(const char *path)
{
    if (mkdir(path, 0777) != 0 && errno != EEXIST) {
        fprintf(stderr, "cannot create %s: %s\n", path, strerror(errno));
        exit(1);
    }
}

typedef struct prog {
    unsigned calls[4];
    uint64_t last[4];
    int stop_stage;      /* stop at the first call of this stage (0: never) */
    int bad;             /* done went backwards or past total */
} prog;

static int on_progress(void *ctx, int stage, uint64_t done, uint64_t total)
{
    prog *p = ctx;
    if (stage < 1 || stage > 3 || done < p->last[stage] || done > total)
        p->bad++;
    else
        p->last[stage] = done;
    if (stage >= 1 && stage <= 3)
        p->calls[stage]++;
    return stage == p->stop_stage;
}

typedef struct run_opts {
    int tile;
    double cell;
    long halo;
    gdt_dup_policy dup;
    int tiny;
    unsigned voxels;
    int nosync;
    prog *progress;
    int threads;         /* --dup merge workers (0: one) */
    uint64_t id;         /* the job id's first word (the checksums' seed) */
    int drop_spill;      /* pass 2 keeps no .raw file (else every one stays, to compare) */
} run_opts;

typedef struct vdb_check {
    const gdt_tiler *t;
    int64_t i0, j0;
    uint64_t seen, bad;
} vdb_check;

static int vdb_visit(void *ctx, int64_t ci, int64_t cj, uint64_t count)
{
    vdb_check *c = ctx;
    gdt_tile_desc d;
    int found = 0;
    c->seen++;
    for (uint64_t k = 0; k < gdt_tiler_tile_count(c->t); k++) {
        gdt_tiler_tile_info(c->t, k, &d, NULL);
        if (d.i == c->i0 + ci && d.j == c->j0 + cj) {
            found = 1;
            if (d.raw_points != count)
                c->bad++;
        }
    }
    if (!found)
        c->bad++;
    return 0;
}

/* Checks one finished run against the brute force. */
static void check_run(gdt_tiler *t, const char *job, const gdt_point *in, size_t n,
                      const gdt_point *merged, size_t nmerged, const char *what)
{
    const gdt_tile_plan *p = gdt_tiler_get_plan(t);
    const int64_t T = p->span, h = p->halo * p->cell;
    gdt_point_buf pts = {0}, halo = {0};
    gdt_point *all = malloc((n + 1) * sizeof *all), *exp = malloc((nmerged + 1) * sizeof *exp);
    size_t nall = 0;
    uint64_t sum_points = 0;
    gdt_error err;

    for (uint64_t k = 0; k < gdt_tiler_tile_count(t); k++) {
        gdt_tile_desc d;
        char path[4096];
        size_t nr = 0, ne = 0, nexp = 0;
        gdt_point *raw, *edge;

        gdt_tiler_tile_info(t, k, &d, NULL);
        CHECK(d.x0 == d.i * T && d.y0 == d.j * T, "%s: tile corner", what);
        CHECK(d.local_extent == T + 2 * h && d.local_extent <= (INT64_C(1) << 31),
              "%s: local extent", what);
        gdt_tiler_tile_path(t, k, "raw", path, sizeof path);
        raw = read_records(path, &nr);
        CHECK(raw != NULL && nr == d.raw_points, "%s: raw file of tile %" PRIu64, what, k);
        for (size_t r = 0; raw != NULL && r < nr; r++) {
            CHECK(fdiv(raw[r].x, T) == d.i && fdiv(raw[r].y, T) == d.j,
                  "%s: point %" PRIu64 " in the wrong tile", what, raw[r].ord);
            CHECK(r == 0 || raw[r].ord > raw[r - 1].ord, "%s: raw file not in input order", what);
            all[nall++] = raw[r];
            if (nall > n)
                break;
        }
        free(raw);

        /* The expected tile and halo, from the globally merged points. */
        for (size_t q = 0; q < nmerged; q++)
            if (fdiv(merged[q].x, T) == d.i && fdiv(merged[q].y, T) == d.j)
                exp[nexp++] = merged[q];
        qsort(exp, nexp, sizeof *exp, cmp_ord);
        gdt_error_clear(&err);
        CHECK(gdt_tiler_load_tile(t, k, &pts, &halo, &err) == GDT_OK, "%s: load: %s", what,
              err.msg);
        CHECK(pts.n == nexp && d.points == nexp, "%s: tile %" PRIu64 " has %zu points, expected %zu",
              what, k, pts.n, nexp);
        for (size_t q = 0; q < nexp && q < pts.n; q++)
            if (!same_point(&pts.pts[q], &exp[q])) {
                CHECK(0, "%s: tile %" PRIu64 " point %zu differs from the brute-force merge",
                      what, k, q);
                break;
            }
        {
            /* the local loader: the same points relative to the tile's
             * local origin, the same halo */
            gdt_ipt *xy = malloc((d.points + 1) * sizeof *xy);
            double *zl = malloc((d.points + 1) * sizeof *zl);
            gdt_point_buf h2 = {0};
            size_t nl = 0;
            gdt_error_clear(&err);
            CHECK(xy != NULL && zl != NULL &&
                      gdt_tiler_load_tile_local(t, k, d.local_x0, d.local_y0, xy, zl, &nl,
                                                &h2, &err) == GDT_OK,
                  "%s: local load: %s", what, err.msg);
            CHECK(nl == pts.n && h2.n == halo.n, "%s: local load of tile %" PRIu64
                  ": %zu points, %zu halo (expected %zu, %zu)", what, k, nl, h2.n, pts.n, halo.n);
            for (size_t q = 0; xy != NULL && q < nl && q < pts.n; q++)
                if (xy[q].x != pts.pts[q].x - d.local_x0 || xy[q].y != pts.pts[q].y - d.local_y0 ||
                    memcmp(&zl[q], &pts.pts[q].z, sizeof zl[q]) != 0) {
                    CHECK(0, "%s: local load of tile %" PRIu64 ": point %zu differs", what, k, q);
                    break;
                }
            for (size_t q = 0; q < h2.n && q < halo.n; q++)
                if (!same_point(&h2.pts[q], &halo.pts[q])) {
                    CHECK(0, "%s: local load of tile %" PRIu64 ": halo point %zu differs", what,
                          k, q);
                    break;
                }
            gdt_point_buf_free(&h2);
            free(xy);
            free(zl);
        }
        sum_points += pts.n;
        /* .edge: exactly the tile's points within h of its border, by ord. */
        gdt_tiler_tile_path(t, k, "edge", path, sizeof path);
        edge = read_records(path, &ne);
        CHECK(edge != NULL && ne == d.edge_points, "%s: edge file", what);
        {
            size_t ke = 0, q = 0;
            for (; q < nexp; q++) {
                const gdt_point *m = &exp[q];
                if (!(m->x - d.x0 < h || d.x0 + T - 1 - m->x < h || m->y - d.y0 < h ||
                      d.y0 + T - 1 - m->y < h))
                    continue;
                if (edge == NULL || ke >= ne || !same_point(&edge[ke], m))
                    break;
                ke++;
            }
            CHECK(q == nexp && ke == ne, "%s: tile %" PRIu64 " edge file is not the border set",
                  what, k);
        }
        free(edge);

        nexp = 0;
        for (size_t q = 0; q < nmerged; q++) {
            const gdt_point *m = &merged[q];
            int in_tile = fdiv(m->x, T) == d.i && fdiv(m->y, T) == d.j;
            if (!in_tile && m->x >= d.x0 - h && m->x < d.x0 + T + h && m->y >= d.y0 - h &&
                m->y < d.y0 + T + h)
                exp[nexp++] = *m;
        }
        qsort(exp, nexp, sizeof *exp, cmp_ord);
        CHECK(halo.n == nexp, "%s: tile %" PRIu64 " halo has %zu points, brute force %zu", what,
              k, halo.n, nexp);
        for (size_t q = 0; q < nexp && q < halo.n; q++)
            if (!same_point(&halo.pts[q], &exp[q])) {
                CHECK(0, "%s: tile %" PRIu64 " halo point %zu differs", what, k, q);
                break;
            }
    }
    CHECK(sum_points == nmerged, "%s: %" PRIu64 " merged points in tiles, expected %zu", what,
          sum_points, nmerged);
    /* Every input point exactly once: the raw files are a permutation of the input. */
    CHECK(nall == n, "%s: %zu records in raw files, %zu points in", what, nall, n);
    if (nall == n) {
        qsort(all, nall, sizeof *all, cmp_ord);
        for (size_t q = 0; q < n; q++)
            if (!same_point(&all[q], &in[q])) {
                CHECK(0, "%s: record %zu of the raw files differs from the input", what, q);
                break;
            }
    }
    {
        char ipath[4096];
        gdt_vdb_meta meta;
        vdb_check vc = {t, p->tile_i0, p->tile_j0, 0, 0};
        snprintf(ipath, sizeof ipath, "%s/index.vdb", job);
        gdt_error_clear(&err);
        CHECK(gdt_vdb_index_read_tiles(ipath, &meta, vdb_visit, &vc, &err) == GDT_OK,
              "%s: index: %s", what, err.msg);
        CHECK(vc.seen == gdt_tiler_tile_count(t) && vc.bad == 0,
              "%s: index holds %" PRIu64 " tiles, %" PRIu64 " wrong", what, vc.seen, vc.bad);
        CHECK(meta.span == T && meta.cell == p->cell && meta.halo == p->halo &&
                  meta.points == (int64_t)n && meta.tile_i0 == p->tile_i0,
              "%s: index metadata", what);
    }
    gdt_point_buf_free(&pts);
    gdt_point_buf_free(&halo);
    free(all);
    free(exp);
}

/* Damage 1 flips a bit of path (at byte 40), 2 swaps path and other, 5
 * removes path; doing 1 or 2 again undoes it. */
static void damage_file(int damage, const char *path, const char *other)
{
    if (damage == 1) {
        FILE *f = fopen(path, "r+b");
        int ch = EOF;
        if (f != NULL && fseek(f, 40, SEEK_SET) == 0 && (ch = fgetc(f)) != EOF &&
            fseek(f, 40, SEEK_SET) == 0)
            fputc(ch ^ 4, f);
        CHECK(f != NULL && ch != EOF, "cannot damage %s", path);
        if (f != NULL)
            fclose(f);
    } else if (damage == 2) {
        char tmp[4200];
        snprintf(tmp, sizeof tmp, "%s.swap", path);
        CHECK(rename(path, tmp) == 0 && rename(other, path) == 0 && rename(tmp, other) == 0,
              "cannot swap %s and %s", path, other);
    } else if (damage == 5) {
        unlink(path);
    }
}

static gdt_status open_inputs(const char *const *paths, size_t np, const char *job,
                              const run_opts *ro, gdt_cloud **cloud, gdt_tiler **t,
                              gdt_error *err)
{
    gdt_cloud_opts co;
    gdt_tiler_opts o;
    gdt_status st;

    memset(&co, 0, sizeof co);
    co.quantum = 1.0;
    memset(&o, 0, sizeof o);
    o.tile = ro->tile;
    o.cell = ro->cell;
    o.halo = ro->halo;
    o.dup = ro->dup;
    o.job_dir = job;
    o.test_tiny = ro->tiny;
    o.keep_spill = !ro->drop_spill;
    o.density_voxels = ro->voxels;
    o.test_nosync = ro->nosync;
    o.threads = ro->threads;
    o.file_id[0] = ro->id;
    o.file_id[1] = 42;
    if (ro->progress != NULL) {
        o.progress = on_progress;
        o.progress_ctx = ro->progress;
    }
    *t = NULL;
    st = gdt_cloud_open(cloud, paths, np, &co, err);
    if (st == GDT_OK)
        st = gdt_tiler_create(t, &o, *cloud, err);
    return st;
}

static gdt_status open_tiler(const char *pcd, const char *job, const run_opts *ro,
                             gdt_cloud **cloud, gdt_tiler **t, gdt_error *err)
{
    const char *inputs[1] = {pcd};
    return open_inputs(inputs, 1, job, ro, cloud, t, err);
}

static gdt_tiler *run(const char *pcd, const char *job, const run_opts *ro, gdt_cloud **cloud)
{
    gdt_tiler *t = NULL;
    gdt_error err;
    gdt_status st;
    gdt_error_clear(&err);
    make_dir(job);
    st = open_tiler(pcd, job, ro, cloud, &t, &err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1(t, &err);
    if (st == GDT_OK)
        st = gdt_tiler_pass2(t, &err);
    CHECK(st == GDT_OK, "run %s: %s", job, err.msg);
    if (st != GDT_OK) {
        gdt_tiler_destroy(t);
        gdt_cloud_close(*cloud);
        *cloud = NULL;
        return NULL;
    }
    return t;
}

static void finish(gdt_tiler *t, gdt_cloud *cloud)
{
    gdt_tiler_destroy(t);
    gdt_cloud_close(cloud);
}

/* Same tile files, byte for byte. */
static void compare_jobs(gdt_tiler *a, gdt_tiler *b, const char *what)
{
    static const char *kinds[3] = {"raw", "pts", "edge"};
    CHECK(gdt_tiler_tile_count(a) == gdt_tiler_tile_count(b), "%s: tile counts", what);
    for (uint64_t k = 0; k < gdt_tiler_tile_count(a) && k < gdt_tiler_tile_count(b); k++)
        for (int q = 0; q < 3; q++) {
            char pa[4096], pb[4096];
            gdt_tiler_tile_path(a, k, kinds[q], pa, sizeof pa);
            gdt_tiler_tile_path(b, k, kinds[q], pb, sizeof pb);
            CHECK(files_equal(pa, pb), "%s: %s and %s differ", what, pa, pb);
        }
}

/* Nothing but the tile files is left in <job>/tiles. */
static void check_no_temporaries(const char *job)
{
    char cmd[4200];
    snprintf(cmd, sizeof cmd, "ls %s/tiles | grep -v -E '^tile_-?[0-9]+_-?[0-9]+\\.(raw|pts|edge)$' "
                              ">/dev/null", job);
    CHECK(system(cmd) != 0, "temporary files left in %s/tiles", job);
}

static void test_sort_by_ord(void)
{
    for (int round = 0; round < 20; round++) {
        size_t n = (size_t)below(5000) + 1;
        uint64_t range = round % 3 == 0 ? 7 : round % 3 == 1 ? 100000 : UINT64_MAX;
        gdt_point *a = malloc(n * sizeof *a);
        gdt_error err;
        int ok = 1;
        for (size_t k = 0; k < n; k++) {
            a[k].ord = range == UINT64_MAX ? rng() : rng() % range;
            a[k].x = (int64_t)k; /* the original position, to check stability */
            a[k].y = 0;
            a[k].z = 0.0;
        }
        CHECK(tl_sort_by_ord(a, n, NULL, &err) == GDT_OK, "sort: %s", err.msg);
        for (size_t k = 1; k < n; k++)
            if (a[k - 1].ord > a[k].ord || (a[k - 1].ord == a[k].ord && a[k - 1].x > a[k].x))
                ok = 0;
        CHECK(ok, "radix sort by ord (n %zu, range %" PRIu64 ") is not a stable sort", n, range);
        free(a);
    }
}

/* A record file mapped with tl_map_records reads as it was written
 * (tl_rec_xyz against tl_rec_get) also after records below a point were
 * handed back, which happens a page at a time; a file of another size is
 * refused with 6503 naming it, an empty one maps to nothing. */
static void test_map_records(void)
{
    char path[2200];
    const size_t n = 5000;
    unsigned char *img = malloc(n * TL_REC);
    const unsigned char *map = NULL;
    size_t len = 0, released = 0;
    gdt_error err;
    FILE *f;
    int ok = 1;

    snprintf(path, sizeof path, "%s/map.pts", workdir);
    for (size_t k = 0; img != NULL && k < n; k++) {
        gdt_point p;
        p.x = (int64_t)(rng() % 2000000001u) - 1000000000;
        p.y = -(int64_t)k;
        p.z = (double)rng() / 7.0;
        p.ord = rng();
        tl_rec_put(img + k * TL_REC, &p);
    }
    f = fopen(path, "wb");
    CHECK(img != NULL && f != NULL && fwrite(img, TL_REC, n, f) == n && fclose(f) == 0,
          "cannot write %s", path);
    gdt_error_clear(&err);
    CHECK(tl_map_records(path, n, &map, &len, &err) == GDT_OK && map != NULL &&
              len == n * TL_REC,
          "mapping %s: %s", path, err.msg);
    if (map != NULL && img != NULL) {
        tl_release_records(map, len, &released, 3001);
        CHECK(released > 0 && released <= 3001 * TL_REC && released % 4096 == 0,
              "records below 3001 handed back as %zu bytes", released);
        for (size_t k = 0; k < n; k++) {
            gdt_point want;
            int64_t x, y;
            double z;
            tl_rec_get(&want, img + k * TL_REC);
            tl_rec_xyz(map + k * TL_REC, &x, &y, &z);
            if (x != want.x || y != want.y || memcmp(&z, &want.z, sizeof z) != 0)
                ok = 0;
        }
        CHECK(ok, "the mapped records differ from those written");
        tl_unmap_records(map, len);
    }
    gdt_error_clear(&err);
    CHECK(tl_map_records(path, n + 1, &map, &len, &err) == GDT_EJOB && err.code == 6503 &&
              strstr(err.msg, path) != NULL && map == NULL,
          "a file one record short: %d: %s", err.code, err.msg);
    f = fopen(path, "wb");
    CHECK(f != NULL && fclose(f) == 0, "cannot empty %s", path);
    gdt_error_clear(&err);
    CHECK(tl_map_records(path, 0, &map, &len, &err) == GDT_OK && map == NULL && len == 0,
          "an empty file: %s", err.msg);
    free(img);
}

/* ---- pass 1 in shares ----------------------------------------------------- */

static int cmp_x(const void *pa, const void *pb)
{
    const gdt_point *a = pa, *b = pb;
    return (a->x > b->x) - (a->x < b->x);
}

/* Same bytes but the file's UUID (the 36 characters at byte 21 of an
 * OpenVDB file, new for every file written). */
static int vdb_files_equal(const char *a, const char *b) { return files_equal_but(a, b, 21, 57); }

/* Pass 1 read in three shares (whole inputs: PCD cannot start inside one)
 * and summed in another order gives the plan and the index.vdb bytes of one
 * pass over the whole cloud, and the same filter counts.  The inputs are
 * strips of x, so that the shares' density grids coarsen to different
 * shifts under a small voxel cap. */
static void test_pass1_shares(const gdt_point *in, size_t n)
{
    enum { NIN = 4, NSH = 3 };
    gdt_point *p = malloc(n * sizeof *p);
    char paths[NIN][2200];
    const char *pp[NIN];
    size_t at = 0;
    static const struct { double cell; unsigned voxels; } cases[3] = {{0.0, 0}, {0.0, 24},
                                                                     {11.0, 40}};
    memcpy(p, in, n * sizeof *p);
    qsort(p, n, sizeof *p, cmp_x);
    for (int i = 0; i < NIN; i++) {
        /* unequal strips: 10%, 20%, 30%, 40% of the points */
        size_t m = i + 1 == NIN ? n - at : n * (size_t)(i + 1) / 10;
        snprintf(paths[i], sizeof paths[i], "%s/strip%d.pcd", workdir, i);
        CHECK(write_pcd(paths[i], p + at, m, 0) == 0, "cannot write %s", paths[i]);
        pp[i] = paths[i];
        at += m;
    }
    for (int q = 0; q < 3; q++) {
        run_opts ro = {64, cases[q].cell, -1, GDT_DUP_FIRST, 0, cases[q].voxels, 1, NULL, 0, 0, 0};
        char jw[2300], js[2300], iw[2400], is[2400];
        gdt_cloud *cw = NULL, *cs[NSH] = {NULL};
        gdt_tiler *tw = NULL, *ts[NSH] = {NULL};
        uint64_t bounds[NSH + 1];
        gdt_error err;
        gdt_status st;
        gdt_error_clear(&err);
        snprintf(jw, sizeof jw, "%s/job-p1-whole-%d", workdir, q);
        snprintf(js, sizeof js, "%s/job-p1-shares-%d", workdir, q);
        make_dir(jw);
        make_dir(js);
        st = open_inputs(pp, NIN, jw, &ro, &cw, &tw, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(tw, &err);
        CHECK(st == GDT_OK, "pass 1 over the whole cloud: %s", err.msg);
        /* case 1: the shares' tiler keeps no .raw file, so the owner of a
         * tile takes its shares into memory; the other cases join them */
        run_opts rs = ro;
        rs.drop_spill = q == 1;
        for (int r = 0; st == GDT_OK && r < NSH; r++) {
            st = open_inputs(pp, NIN, r == 0 ? js : NULL, &rs, &cs[r], &ts[r], &err);
            if (st == GDT_OK && r == 0) {
                CHECK(gdt_cloud_split(cs[0], NSH, bounds) == 1, "a PCD cloud can be shared");
                for (int j = 0; j <= NSH; j++) {
                    /* every boundary at the start or end of an input */
                    uint64_t b = 0;
                    int ok = bounds[j] == 0;
                    for (int i = 0; i < NIN; i++) {
                        b += gdt_cloud_input_info(cs[0], (size_t)i)->point_count;
                        ok |= bounds[j] == b;
                    }
                    CHECK(ok, "share boundary %" PRIu64 " inside an input", bounds[j]);
                }
                CHECK(bounds[NSH] == n && bounds[1] > 0 && bounds[2] > bounds[1] &&
                          bounds[2] < n,
                      "shares %" PRIu64 " %" PRIu64 " %" PRIu64, bounds[1], bounds[2],
                      bounds[3]);
            }
            if (st == GDT_OK)
                st = gdt_cloud_set_range(cs[r], bounds[r], bounds[r + 1], 0, &err);
            if (st == GDT_OK)
                st = gdt_tiler_pass1_part(ts[r], &err);
        }
        /* the planner adds the last share first; a share cut short is
         * refused (by a share's tiler already exported, which it fails) */
        for (int r = NSH - 1; st == GDT_OK && r >= 1; r--) {
            unsigned char *b = NULL;
            size_t len = 0;
            st = gdt_tiler_pass1_part_export(ts[r], &b, &len, &err);
            if (st == GDT_OK)
                st = gdt_tiler_pass1_part_merge(ts[0], b, len, &err);
            if (st == GDT_OK && r == 1) /* ts[2] is spent: it can take the test */
                CHECK(gdt_tiler_pass1_part_merge(ts[2], b, len - 8, NULL) == GDT_EINTERNAL,
                      "a share of pass 1 cut short was taken");
            free(b);
        }
        if (st == GDT_OK)
            st = gdt_tiler_pass1_end(ts[0], &err);
        CHECK(st == GDT_OK, "pass 1 in shares: %s", err.msg);
        if (st == GDT_OK) {
            const gdt_tile_plan *a = gdt_tiler_get_plan(tw), *b = gdt_tiler_get_plan(ts[0]);
            gdt_filter_counts fa = gdt_cloud_total_counts(cw), fb = gdt_cloud_total_counts(cs[0]);
            snprintf(iw, sizeof iw, "%s/index.vdb", jw);
            snprintf(is, sizeof is, "%s/index.vdb", js);
            CHECK(a->points == b->points && a->tiles == b->tiles && a->cell == b->cell &&
                      a->halo == b->halo && a->density_shift == b->density_shift &&
                      a->min_x == b->min_x && a->max_x == b->max_x && a->min_y == b->min_y &&
                      a->max_y == b->max_y && a->min_z == b->min_z && a->max_z == b->max_z &&
                      a->median_points == b->median_points,
                  "case %d: the shares' plan differs (cell %" PRId64 "/%" PRId64
                  ", shift %d/%d, tiles %" PRIu64 "/%" PRIu64 ")",
                  q, a->cell, b->cell, a->density_shift, b->density_shift, a->tiles, b->tiles);
            CHECK(q == 0 || a->density_shift > 0, "case %d: the voxel cap did not coarsen", q);
            CHECK(vdb_files_equal(iw, is),
                  "case %d: index.vdb differs between whole and shares", q);
            CHECK(memcmp(&fa, &fb, sizeof fa) == 0, "case %d: filter counts differ", q);
            for (uint64_t k = 0; k < a->tiles && k < b->tiles; k++) {
                gdt_tile_desc da, db;
                gdt_tiler_tile_info(tw, k, &da, NULL);
                gdt_tiler_tile_info(ts[0], k, &db, NULL);
                CHECK(da.i == db.i && da.j == db.j && da.raw_points == db.raw_points,
                      "case %d: tile %" PRIu64 " differs", q, k);
            }
            /* pass 2 in shares through files: each share spilled with its
             * first ordinal, then every tile's shares taken into memory
             * (gdt_tiler_take_parts: these tiles are far below half the
             * budget) or joined, is the .raw file of one pass 2 (the shares
             * spilled from one tiler here) */
            st = gdt_tiler_pass2(tw, &err);
            if (st == GDT_OK)
                st = gdt_tiler_pass2_open(ts[0], &err);
            for (int r = NSH - 1; st == GDT_OK && r >= 0; r--) {
                st = gdt_cloud_set_range(cs[0], bounds[r], bounds[r + 1], bounds[r], &err);
                if (st == GDT_OK)
                    st = gdt_tiler_spill_part(ts[0], r, &err);
            }
            for (uint64_t k = 0; st == GDT_OK && k < a->tiles; k++) {
                char ra[4096], rb[4096];
                gdt_point *recs = NULL, *want = NULL;
                uint64_t nr = 0;
                size_t got = 0;
                tl_rfile rf;
                gdt_tile_desc da;
                st = gdt_tiler_take_parts(ts[0], k, NSH, &recs, &nr, &err);
                gdt_tiler_tile_info(tw, k, &da, NULL);
                gdt_tiler_tile_path(tw, k, "raw", ra, sizeof ra);
                gdt_tiler_tile_path(ts[0], k, "raw", rb, sizeof rb);
                if (!rs.drop_spill) {
                    /* a .raw file that must stay: joined, not taken */
                    CHECK(st != GDT_OK || (recs == NULL && nr == 0 && files_equal(ra, rb)),
                          "case %d: tile %" PRIu64 " was not joined into %s", q, k, rb);
                    free(recs);
                    continue;
                }
                CHECK(st != GDT_OK || (recs != NULL && nr == da.raw_points),
                      "case %d: tile %" PRIu64 " not taken into memory (%" PRIu64 " of %" PRIu64
                      ")", q, k, nr, da.raw_points);
                CHECK(st != GDT_OK || access(rb, F_OK) != 0, "case %d: %s was joined", q, rb);
                want = malloc((size_t)(nr + 1) * sizeof *want);
                if (st == GDT_OK && recs != NULL && want != NULL &&
                    tl_rfile_open(&rf, ra, nr, 4096, &err) == GDT_OK) {
                    if (tl_rfile_read(&rf, want, (size_t)nr, &got, &err) != GDT_OK)
                        got = 0;
                    tl_rfile_close(&rf);
                    CHECK(got == nr && memcmp(want, recs, (size_t)nr * sizeof *recs) == 0,
                          "case %d: tile %" PRIu64 ": the shares in memory are not %s", q, k,
                          ra);
                }
                free(want);
                free(recs);
            }
            for (int r = NSH - 1; st == GDT_OK && !rs.drop_spill && r >= 0; r--) {
                st = gdt_cloud_set_range(cs[0], bounds[r], bounds[r + 1], bounds[r], &err);
                if (st == GDT_OK)
                    st = gdt_tiler_spill_part(ts[0], r, &err);
            }
            for (uint64_t k = 0; st == GDT_OK && !rs.drop_spill && k < a->tiles; k++) {
                char ra[4096], rb[4096];
                st = gdt_tiler_join_parts(ts[0], k, NSH, &err);
                gdt_tiler_tile_path(tw, k, "raw", ra, sizeof ra);
                gdt_tiler_tile_path(ts[0], k, "raw", rb, sizeof rb);
                CHECK(st != GDT_OK || files_equal(ra, rb), "case %d: %s and %s differ", q, ra,
                      rb);
            }
            CHECK(st == GDT_OK, "case %d: pass 2 in shares: %s", q, err.msg);
            if (q == 0) {
                /* a share's file left by a killed run goes with the next
                 * pass 2 over the job directory; other names stay */
                char junk[2400], other[2400];
                gdt_cloud *cj = NULL;
                gdt_tiler *tj = NULL;
                FILE *f;
                snprintf(junk, sizeof junk, "%s/tiles/tile_9_9.raw.tmp.p12", jw);
                snprintf(other, sizeof other, "%s/tiles/tile_9_9.raw.tmp.px", jw);
                f = fopen(junk, "w");
                if (f != NULL)
                    fclose(f);
                f = fopen(other, "w");
                if (f != NULL)
                    fclose(f);
                st = open_inputs(pp, NIN, jw, &ro, &cj, &tj, &err);
                if (st == GDT_OK)
                    st = gdt_tiler_pass1(tj, &err);
                if (st == GDT_OK)
                    st = gdt_tiler_pass2(tj, &err);
                CHECK(st == GDT_OK, "pass 2 again: %s", err.msg);
                CHECK(access(junk, F_OK) != 0, "%s was left", junk);
                CHECK(access(other, F_OK) == 0, "%s was removed", other);
                unlink(other);
                finish(tj, cj);
            }
        }
        finish(tw, cw);
        for (int r = 0; r < NSH; r++)
            finish(ts[r], cs[r]);
    }
    free(p);
}

int main(int argc, char **argv)
{
    char pcd[2100], job[2200], job2[2200];
    gdt_point *in, *merged;
    size_t n, nmerged;
    gdt_error err;
    static const gdt_dup_policy rules[3] = {GDT_DUP_FIRST, GDT_DUP_MIN_Z, GDT_DUP_MAX_Z};

    if (argc != 2) {
        fprintf(stderr, "usage: test_tiler WORKDIR\n");
        return 2;
    }
    snprintf(workdir, sizeof workdir, "%s", argv[1]);
    make_dir(workdir);
    snprintf(pcd, sizeof pcd, "%s/cloud.pcd", workdir);
    in = make_cloud(&n, 12345);
    if (write_pcd(pcd, in, n, 0) != 0) {
        fprintf(stderr, "cannot write %s\n", pcd);
        return 1;
    }
    test_sort_by_ord();
    test_map_records();
    test_pass1_shares(in, n);

    /* Given cell and halo, every --dup rule, normal and tiny budgets. */
    for (int r = 0; r < 3; r++) {
        run_opts ro = {64, 13.0, 5, rules[r], 0, 0, r > 0, NULL, 0, 0, 0};
        gdt_cloud *c1 = NULL, *c2 = NULL;
        gdt_tiler *a, *b;
        char what[64];
        merged = malloc(n * sizeof *merged);
        memcpy(merged, in, n * sizeof *merged);
        gdt_points_dedup(merged, n, rules[r], &nmerged, &err);
        snprintf(job, sizeof job, "%s/job-%s", workdir, gdt_dup_policy_name(rules[r]));
        snprintf(job2, sizeof job2, "%s/job-%s-tiny", workdir, gdt_dup_policy_name(rules[r]));
        a = run(pcd, job, &ro, &c1);
        ro.tiny = 1;
        ro.nosync = 1;
        b = run(pcd, job2, &ro, &c2);
        if (a != NULL && b != NULL) {
            const gdt_tiler_stats *sa = gdt_tiler_get_stats(a), *sb = gdt_tiler_get_stats(b);
            snprintf(what, sizeof what, "--dup %s", gdt_dup_policy_name(rules[r]));
            check_run(a, job, in, n, merged, nmerged, what);
            snprintf(what, sizeof what, "--dup %s tiny", gdt_dup_policy_name(rules[r]));
            check_run(b, job2, in, n, merged, nmerged, what);
            compare_jobs(a, b, what);
            CHECK(sa->spill_levels == 0 && sa->external_merges == 0,
                  "normal budget spilled (%u levels, %" PRIu64 " external merges)",
                  sa->spill_levels, sa->external_merges);
            CHECK(sb->spill_levels >= 3 && sb->bucket_records >= 3 * n,
                  "tiny budget: %u bucket levels, %" PRIu64 " bucket records", sb->spill_levels,
                  sb->bucket_records);
            CHECK(sb->external_merges > 0 && sb->merge_levels >= 2,
                  "tiny budget: %" PRIu64 " external merges, %u levels", sb->external_merges,
                  sb->merge_levels);
            CHECK(sa->merged_duplicates == n - nmerged && sb->merged_duplicates == n - nmerged,
                  "merged duplicates %" PRIu64 "/%" PRIu64 ", expected %zu",
                  sa->merged_duplicates, sb->merged_duplicates, n - nmerged);
            check_no_temporaries(job);
            check_no_temporaries(job2);
        }
        finish(a, c1);
        finish(b, c2);
        free(merged);
    }

    merged = malloc(n * sizeof *merged);
    memcpy(merged, in, n * sizeof *merged);
    gdt_points_dedup(merged, n, GDT_DUP_FIRST, &nmerged, &err);

    /* A halo wider than a tile, and no halo at all. */
    {
        long halos[2] = {100, 0};
        for (int q = 0; q < 2; q++) {
            run_opts ro = {64, 9.0, halos[q], GDT_DUP_FIRST, q == 0, 0, 1, NULL, 0, 0, 0};
            gdt_cloud *c = NULL;
            gdt_tiler *t;
            char what[64];
            snprintf(job, sizeof job, "%s/job-halo%ld", workdir, halos[q]);
            snprintf(what, sizeof what, "--halo %ld", halos[q]);
            t = run(pcd, job, &ro, &c);
            if (t != NULL) {
                check_run(t, job, in, n, merged, nmerged, what);
                if (halos[q] == 0)
                    for (uint64_t k = 0; k < gdt_tiler_tile_count(t); k++) {
                        gdt_tile_desc d;
                        gdt_tiler_tile_info(t, k, &d, NULL);
                        CHECK(d.edge_points == 0, "--halo 0 wrote edge points");
                    }
            }
            finish(t, c);
        }
    }

    /* Auto cell and halo: about N^2/4 points per tile, exact counts. */
    {
        run_opts ro = {64, 0.0, -1, GDT_DUP_FIRST, 0, 0, 1, NULL, 0, 7, 0};
        gdt_cloud *c = NULL;
        gdt_tiler *t;
        gdt_tiler_file_sum *sums = NULL;
        uint64_t nt = 0;
        snprintf(job, sizeof job, "%s/job-auto", workdir);
        t = run(pcd, job, &ro, &c);
        if (t != NULL) {
            const gdt_tile_plan *p = gdt_tiler_get_plan(t);
            CHECK(p->cell_auto && p->halo_auto && p->halo >= 1 && p->halo <= 32,
                  "auto plan: cell %" PRId64 " halo %" PRId64, p->cell, p->halo);
            CHECK(p->median_points >= 64 * 64 / 16 && p->median_points <= 64 * 64,
                  "auto cell gives a median of %" PRIu64 " points per tile (target 1024)",
                  p->median_points);
            CHECK(p->span % (INT64_C(1) << p->density_shift) == 0,
                  "density voxel does not divide the tile");
            check_run(t, job, in, n, merged, nmerged, "auto");
            /* the records a journal would keep: each checksum is the one of
             * the file's bytes as written */
            nt = gdt_tiler_tile_count(t);
            sums = calloc(2 * nt + 1, sizeof *sums);
            for (uint64_t k = 0; sums != NULL && k < nt; k++) {
                char path[4096];
                uint64_t size = 0, sum = 0;
                CHECK(gdt_tiler_file_sums(t, k, &sums[2 * k], &err) == GDT_OK, "sums: %s",
                      err.msg);
                gdt_tiler_tile_path(t, k, "pts", path, sizeof path);
                CHECK(tl_file_sum(path, gdt_job_file_seed((uint64_t[2]){7, 42}, k,
                                                          GDT_JOB_FILE_PTS),
                                  &size, &sum, &err) == GDT_OK &&
                          size == sums[2 * k].size && sum == sums[2 * k].sum,
                      "tile %" PRIu64 ": the recorded .pts checksum is not the file's", k);
            }
        }
        finish(t, c);
        /* Resume: pass 1 again, then adopt the tile files instead of pass 2;
         * then with one flipped bit in a .pts file, a .edge file swapped
         * with another tile's, another job's id, a file cut short after the
         * adoption, and a missing file. */
        for (int damage = 0; sums != NULL && damage < 6; damage++) {
            char path[4096], other[4096];
            run_opts r2 = ro;
            t = NULL;
            c = NULL;
            gdt_error_clear(&err);
            r2.id = damage == 3 ? 8 : 7;
            if (open_tiler(pcd, job, &r2, &c, &t, &err) != GDT_OK ||
                gdt_tiler_pass1(t, &err) != GDT_OK) {
                CHECK(0, "reopening the auto job: %s", err.msg);
                finish(t, c);
                break;
            }
            gdt_tiler_tile_path(t, nt / 2, damage == 2 ? "edge" : "pts", path, sizeof path);
            gdt_tiler_tile_path(t, nt / 2 + 1, "edge", other, sizeof other);
            damage_file(damage, path, other);
            if (damage == 0) {
                CHECK(gdt_tiler_adopt_pass2(t, sums, &err) == GDT_OK, "adopt: %s", err.msg);
                check_run(t, job, in, n, merged, nmerged, "auto, adopted");
            } else if (damage == 4) {
                /* a file cut short after the adoption: loading it is a job
                 * error naming it, not an I/O or input error */
                gdt_point_buf a = {0}, b = {0};
                CHECK(gdt_tiler_adopt_pass2(t, sums, &err) == GDT_OK, "adopt: %s", err.msg);
                CHECK(truncate(path, (off_t)sums[2 * (nt / 2)].size - 32) == 0, "truncate %s",
                      path);
                CHECK(gdt_tiler_load_tile(t, nt / 2, &a, &b, &err) == GDT_EJOB &&
                          err.code == 6503 && strstr(err.msg, path) != NULL,
                      "loading a truncated .pts file: %s", err.msg);
                gdt_point_buf_free(&a);
                gdt_point_buf_free(&b);
            } else {
                CHECK(gdt_tiler_adopt_pass2(t, sums, &err) == GDT_EJOB && err.code == 6501 &&
                          strstr(err.msg, damage == 3 ? "tile_" : strrchr(path, '/') + 1) != NULL,
                      "adopting with damage %d: %s", damage, err.msg);
                CHECK(gdt_tiler_tile_count(t) == nt &&
                          gdt_tiler_load_tile(t, 0, &(gdt_point_buf){0}, &(gdt_point_buf){0},
                                              &err) == GDT_EUSAGE,
                      "a refused adoption changed the tiler's state");
                damage_file(damage, path, other); /* undone (a flip or a swap) */
            }
            finish(t, c);
        }
        free(sums);
    }

    /* A density grid forced to coarsen: the counts stay exact (given cell:
     * same tiles as before; auto cell: the voxel still divides the tile). */
    {
        run_opts ro = {64, 13.0, 5, GDT_DUP_FIRST, 0, 64, 1, NULL, 0, 0, 0};
        gdt_cloud *c = NULL;
        gdt_tiler *t;
        snprintf(job, sizeof job, "%s/job-coarse", workdir);
        t = run(pcd, job, &ro, &c);
        if (t != NULL) {
            CHECK(gdt_tiler_get_plan(t)->density_shift >= 4, "density grid did not coarsen (%d)",
                  gdt_tiler_get_plan(t)->density_shift);
            check_run(t, job, in, n, merged, nmerged, "coarse density, given cell");
        }
        finish(t, c);
        ro.cell = 0.0;
        snprintf(job, sizeof job, "%s/job-coarse-auto", workdir);
        t = run(pcd, job, &ro, &c);
        if (t != NULL) {
            const gdt_tile_plan *p = gdt_tiler_get_plan(t);
            CHECK(p->span % (INT64_C(1) << p->density_shift) == 0,
                  "coarse density voxel does not divide the tile");
            check_run(t, job, in, n, merged, nmerged, "coarse density, auto cell");
        }
        finish(t, c);
    }

    /* Progress reports, and a stop request in the middle of pass 2. */
    {
        prog pr;
        run_opts ro = {64, 13.0, 5, GDT_DUP_FIRST, 0, 0, 1, &pr, 0, 0, 0};
        gdt_cloud *c = NULL;
        gdt_tiler *t = NULL;
        gdt_status st;
        memset(&pr, 0, sizeof pr);
        snprintf(job, sizeof job, "%s/job-progress", workdir);
        t = run(pcd, job, &ro, &c);
        CHECK(pr.bad == 0 && pr.calls[1] > 0 && pr.calls[2] > 0 &&
                  pr.calls[3] == gdt_tiler_tile_count(t) && pr.last[1] == n && pr.last[2] == n,
              "progress: %d bad, calls %u %u %u", pr.bad, pr.calls[1], pr.calls[2],
              pr.calls[3]);
        finish(t, c);
        memset(&pr, 0, sizeof pr);
        pr.stop_stage = 2;
        t = NULL;
        c = NULL;
        gdt_error_clear(&err);
        st = open_tiler(pcd, job, &ro, &c, &t, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(t, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass2(t, &err);
        CHECK(st == GDT_EINTERRUPTED && err.code == 1301, "stop request: %d %s", st, err.msg);
        finish(t, c);
        /* The job runs again from the start of pass 2. */
        pr.stop_stage = 0;
        t = run(pcd, job, &ro, &c);
        if (t != NULL)
            check_run(t, job, in, n, merged, nmerged, "after a stop");
        finish(t, c);
        check_no_temporaries(job);
    }

    /* The --dup merge on several workers: the same tile files as on one,
     * one progress call per tile in increasing order, and a stop request
     * in the merge stops it with the job left to run again. */
    {
        prog pr;
        run_opts r1 = {64, 13.0, 5, GDT_DUP_FIRST, 0, 0, 1, NULL, 1, 0, 0};
        run_opts r4 = {64, 13.0, 5, GDT_DUP_FIRST, 0, 0, 1, &pr, 4, 0, 0};
        gdt_cloud *c1 = NULL, *c4 = NULL;
        gdt_tiler *t1, *t4;
        gdt_status st;
        memset(&pr, 0, sizeof pr);
        snprintf(job, sizeof job, "%s/job-workers1", workdir);
        t1 = run(pcd, job, &r1, &c1);
        snprintf(job, sizeof job, "%s/job-workers4", workdir);
        t4 = run(pcd, job, &r4, &c4);
        if (t1 != NULL && t4 != NULL) {
            CHECK(gdt_tiler_tile_count(t4) >= 4, "only %" PRIu64 " tiles",
                  gdt_tiler_tile_count(t4));
            compare_jobs(t1, t4, "4 merge workers against 1");
            CHECK(gdt_tiler_get_stats(t4)->merged_duplicates ==
                      gdt_tiler_get_stats(t1)->merged_duplicates,
                  "merged duplicates differ: %" PRIu64 " and %" PRIu64,
                  gdt_tiler_get_stats(t4)->merged_duplicates,
                  gdt_tiler_get_stats(t1)->merged_duplicates);
            CHECK(pr.bad == 0 && pr.calls[3] == gdt_tiler_tile_count(t4) &&
                      pr.last[3] == gdt_tiler_tile_count(t4),
                  "progress with 4 workers: %d bad, %u calls, last %" PRIu64, pr.bad,
                  pr.calls[3], pr.last[3]);
        }
        finish(t1, c1);
        finish(t4, c4);
        memset(&pr, 0, sizeof pr);
        pr.stop_stage = 3;
        t4 = NULL;
        c4 = NULL;
        gdt_error_clear(&err);
        st = open_tiler(pcd, job, &r4, &c4, &t4, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(t4, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass2(t4, &err);
        CHECK(st == GDT_EINTERRUPTED && err.code == 1301 && pr.calls[3] == 1,
              "stop request in the merge: %d %s (%u calls)", st, err.msg, pr.calls[3]);
        finish(t4, c4);
        pr.stop_stage = 0;
        t4 = run(pcd, job, &r4, &c4);
        if (t4 != NULL)
            check_run(t4, job, in, n, merged, nmerged, "4 workers after a stop");
        finish(t4, c4);
    }

    /* Refused: tile-local range beyond 2^31, a budget below the minimum. */
    {
        gdt_cloud *c = NULL;
        gdt_tiler *t = NULL;
        run_opts ro = {1024, 4194304.0, 0, GDT_DUP_FIRST, 0, 0, 1, NULL, 0, 0, 0};
        gdt_status st;
        snprintf(job, sizeof job, "%s/job-refused", workdir);
        make_dir(job);
        gdt_error_clear(&err);
        st = open_tiler(pcd, job, &ro, &c, &t, &err);
        CHECK(st == GDT_EUSAGE && err.code == 2502, "--cell 2^22 with --tile 1024: %d %s", st,
              err.msg);
        gdt_tiler_destroy(t);
        gdt_cloud_close(c);
        ro.cell = 2097152.0; /* N c = 2^31 exactly: legal with halo 0, not with halo 1 */
        ro.halo = 1;
        gdt_error_clear(&err);
        st = open_tiler(pcd, job, &ro, &c, &t, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(t, &err);
        CHECK(st == GDT_EUSAGE && err.code == 2502, "--halo 1 beyond 2^31: %d %s", st, err.msg);
        gdt_tiler_destroy(t);
        gdt_cloud_close(c);
        ro.halo = 0;
        gdt_error_clear(&err);
        st = open_tiler(pcd, job, &ro, &c, &t, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(t, &err);
        CHECK(st == GDT_OK && gdt_tiler_get_plan(t)->span == (INT64_C(1) << 31),
              "--halo 0 at exactly 2^31: %s", err.msg);
        gdt_tiler_destroy(t);
        gdt_cloud_close(c);
    }
    {
        gdt_cloud *c = NULL;
        gdt_tiler *t = NULL;
        gdt_cloud_opts co;
        gdt_tiler_opts o;
        const char *inputs[1] = {pcd};
        gdt_status st;
        memset(&co, 0, sizeof co);
        co.quantum = 1.0;
        memset(&o, 0, sizeof o);
        o.tile = 64;
        o.halo = -1;
        o.mem_budget = (uint64_t)4 << 20;
        gdt_error_clear(&err);
        st = gdt_cloud_open(&c, inputs, 1, &co, &err);
        if (st == GDT_OK)
            st = gdt_tiler_create(&t, &o, c, &err);
        CHECK(st == GDT_EUSAGE && err.code == 2504, "4 MiB budget: %d %s", st, err.msg);
        gdt_tiler_destroy(t);
        gdt_cloud_close(c);
    }

    /* Budgets that cannot hold the tile table, or one tile with its halo
     * (the tiny test mode waives the minimum budget). */
    {
        uint64_t budgets[2] = {8192, 65536};
        for (int q = 0; q < 2; q++) {
            gdt_cloud *c = NULL;
            gdt_tiler *t = NULL;
            gdt_cloud_opts co;
            gdt_tiler_opts o;
            const char *inputs[1] = {pcd};
            gdt_point_buf pts = {0}, halo = {0};
            gdt_status st;
            memset(&co, 0, sizeof co);
            co.quantum = 1.0;
            memset(&o, 0, sizeof o);
            o.tile = 64;
            o.cell = 13.0;
            o.halo = 5;
            o.test_tiny = 1;
            o.test_nosync = 1;
            o.mem_budget = budgets[q];
            snprintf(job, sizeof job, "%s/job-budget%d", workdir, q);
            make_dir(job);
            o.job_dir = job;
            gdt_error_clear(&err);
            st = gdt_cloud_open(&c, inputs, 1, &co, &err);
            if (st == GDT_OK)
                st = gdt_tiler_create(&t, &o, c, &err);
            if (st == GDT_OK)
                st = gdt_tiler_pass1(t, &err);
            if (q == 0) {
                CHECK(st == GDT_EUSAGE && err.code == 2503, "tile table over budget: %d %s", st,
                      err.msg);
            } else {
                if (st == GDT_OK)
                    st = gdt_tiler_pass2(t, &err);
                for (uint64_t k = 0; st == GDT_OK && k < gdt_tiler_tile_count(t); k++) {
                    st = gdt_tiler_load_tile(t, k, &pts, &halo, &err);
                    if (st == GDT_OK)
                        CHECK((pts.n + halo.n) * sizeof(gdt_point) <= budgets[q] / 2,
                              "a loaded tile exceeds half the budget");
                }
                CHECK(st == GDT_EUSAGE && err.code == 2506 && pts.n == 0 && halo.n == 0,
                      "tile over budget: %d %s", st, err.msg);
            }
            gdt_point_buf_free(&pts);
            gdt_point_buf_free(&halo);
            gdt_tiler_destroy(t);
            gdt_cloud_close(c);
        }
    }

    /* The input changes between the passes (same size and count). */
    {
        gdt_cloud *c = NULL;
        gdt_tiler *t = NULL;
        run_opts ro = {64, 13.0, 5, GDT_DUP_FIRST, 0, 0, 1, NULL, 0, 0, 0};
        gdt_status st;
        char moved[2100];
        snprintf(moved, sizeof moved, "%s/moved.pcd", workdir);
        write_pcd(moved, in, n, 0);
        snprintf(job, sizeof job, "%s/job-changed", workdir);
        make_dir(job);
        gdt_error_clear(&err);
        st = open_tiler(moved, job, &ro, &c, &t, &err);
        if (st == GDT_OK)
            st = gdt_tiler_pass1(t, &err);
        if (st == GDT_OK) {
            write_pcd(moved, in, n, 5 * 64 * 13); /* five tiles east */
            st = gdt_tiler_pass2(t, &err);
        }
        CHECK(st == GDT_EINPUT && err.code == 3501, "changed input: %d %s", st, err.msg);
        gdt_tiler_destroy(t);
        gdt_cloud_close(c);
    }

    free(merged);
    free(in);
    printf("test_tiler: %d checks, %d failures\n", checks, failures);
    return failures == 0 ? 0 : 1;
}
