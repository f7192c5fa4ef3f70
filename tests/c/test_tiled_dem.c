/* test_tiled_dem — a tiled run's DEM rasteriser (tiler/tiled_dem.c) on
 * its own, without the OpenCL core.
 *
 *   test_tiled_dem WORKDIR
 *
 * A jittered 320 x 300 grid of points, cut into two squares per grid cell
 * (a triangulated region, so every cell centre inside it is owned by one
 * face), is one tile of 191,362 faces.  The faces go to tr_dem_tile_faces
 * in chunks of 65,536, as the mesh writer gives them:
 *   - on the caller alone (--threads 1, and alone = 1 with helpers);
 *   - to two helper threads (alone = 0), the caller's chunk overwritten
 *     with out-of-range indices as soon as each call returns (the job must
 *     hold its own copy) and with alone switching between chunks;
 * every way must write the same GeoTIFF bytes.  The tile's points are
 * records as in a .pts file (tl_rec_put), as the mesh writer maps them.
 * Faces naming a vertex outside the tile, placed in two parts of one job,
 * fail with 7663 naming the first in face order, reported by
 * tr_dem_tile_wait (also when the helpers took both parts), and the DEM is
 * then not written; a point outside the tile's square (also one as far
 * away as an int64 goes) fails with 6802 naming the tile's file.
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_check.h"
#include "private/tiled_dem.h"
#include "private/tiler_io.h"

static gdt_checks T = {0, 0};

#define CHECK(cond, ...) GDT_CHECK(&T, cond, __VA_ARGS__)

#define NX 320
#define NY 300
#define STEP 40  /* lattice steps between grid points */
#define CHUNK 65536

typedef struct cloud {
    unsigned char *rec; /* n records, TL_REC bytes each */
    size_t n;
    int32_t *tri;
    size_t nf;
    int64_t min_x, max_x, min_y, max_y;
} cloud;

static void make_cloud(cloud *c)
{
    uint64_t seed = 12345;
    c->n = (size_t)NX * NY;
    c->rec = malloc(c->n * TL_REC);
    c->tri = malloc((size_t)(NX - 1) * (NY - 1) * 6 * sizeof *c->tri);
    c->nf = 0;
    c->min_x = c->min_y = INT64_MAX;
    c->max_x = c->max_y = INT64_MIN;
    if (c->rec == NULL || c->tri == NULL)
        return;
    for (int j = 0; j < NY; j++)
        for (int i = 0; i < NX; i++) {
            gdt_point p;
            memset(&p, 0, sizeof p);
            /* jitter below half a step: the squares stay convex and unflipped */
            p.x = i * STEP + (int)(gdt_splitmix64(&seed) % 15);
            p.y = j * STEP + (int)(gdt_splitmix64(&seed) % 15);
            p.z = 100.0 + 0.25 * (double)(gdt_splitmix64(&seed) % 4000) / 7.0;
            p.ord = (uint64_t)j * NX + (uint64_t)i;
            tl_rec_put(c->rec + (size_t)p.ord * TL_REC, &p);
            if (p.x < c->min_x) c->min_x = p.x;
            if (p.x > c->max_x) c->max_x = p.x;
            if (p.y < c->min_y) c->min_y = p.y;
            if (p.y > c->max_y) c->max_y = p.y;
        }
    for (int j = 0; j + 1 < NY; j++)
        for (int i = 0; i + 1 < NX; i++) {
            int32_t a = j * NX + i, b = a + 1, d = a + NX, e = d + 1;
            int32_t *t = c->tri + 3 * c->nf;
            t[0] = a; t[1] = b; t[2] = e;
            t[3] = a; t[4] = e; t[5] = d;
            c->nf += 2;
        }
}

/* The output index of the tile's first vertex: faces name base + i. */
#define BASE 1000

typedef struct plan {
    gdt_options opts;
    gdt_cloud_info ci;
    gdt_tile_plan pl;
} plan;

static void make_plan(plan *p, const cloud *c, const char *dem, int threads)
{
    memset(p, 0, sizeof *p);
    p->opts.threads = threads;
    p->opts.dem = dem;
    p->opts.dem_res = 0.12; /* 12 lattice steps: about 11 cells per grid square */
    p->opts.dem_nodata = -9999.0;
    p->ci.lattice.sx = p->ci.lattice.sy = 0.01;
    p->ci.lattice.ox = 500000.0;
    p->ci.lattice.oy = 4000000.0;
    p->ci.epsg = 0;
    p->pl.points = c->n;
    p->pl.min_x = c->min_x;
    p->pl.max_x = c->max_x;
    p->pl.min_y = c->min_y;
    p->pl.max_y = c->max_y;
}

/* How the faces are handed over. */
enum { ALONE, HELPERS, MIXED };

/* The tile's square [ORIGIN, ORIGIN + extent)^2 (a tile whose halo reaches
 * below 0); with EXTENT every point of the cloud lies in it. */
#define ORIGIN (-STEP)
#define EXTENT ((NX + 1) * STEP)

/* Rasterises every face of c into a DEM at path, in CHUNK-face calls, the
 * tile's square of side extent at ORIGIN; returns the status of the first
 * failing step (err: its message). */
static gdt_status run(const cloud *c, const int32_t *faces, const char *path, int threads, int mode,
                      int64_t extent, gdt_error *err)
{
    plan p;
    tr_dem *d = NULL;
    tr_dem_tile t = {c->rec, c->n, ORIGIN, ORIGIN, extent, "tile.pts"};
    int32_t *chunk = malloc((size_t)CHUNK * 3 * sizeof *chunk);
    gdt_status st;
    size_t k = 0;

    make_plan(&p, c, path, threads);
    st = chunk == NULL ? GDT_EINTERNAL : tr_dem_create(&d, &p.opts, &p.ci, &p.pl, c->n, NULL, err);
    for (size_t done = 0; st == GDT_OK && done < c->nf; done += CHUNK, k++) {
        size_t m = c->nf - done < CHUNK ? c->nf - done : CHUNK;
        int alone = mode == ALONE || (mode == MIXED && k == 1);
        memcpy(chunk, faces + 3 * done, 3 * m * sizeof *chunk);
        st = tr_dem_tile_faces(d, &t, BASE, chunk, m, alone, err);
        /* the job keeps its own copy: this must change nothing */
        for (size_t i = 0; i < 3 * m; i++)
            chunk[i] = -7;
    }
    if (st == GDT_OK)
        st = tr_dem_tile_wait(d, err);
    if (st == GDT_OK)
        st = tr_dem_build(d, NULL, NULL, err);
    if (st == GDT_OK) {
        st = tr_dem_commit(d, err);
        d = NULL;
    }
    if (d != NULL)
        tr_dem_abort(d);
    free(chunk);
    return st;
}

int main(int argc, char **argv)
{
    cloud c;
    char ref[4096], path[4096];
    unsigned char *want = NULL;
    size_t want_len = 0;
    gdt_error err;
    gdt_status st;
    struct stat sb;

    if (argc != 2) {
        fprintf(stderr, "usage: test_tiled_dem WORKDIR\n");
        return 2;
    }
    mkdir(argv[1], 0755);
    make_cloud(&c);
    if (c.rec == NULL || c.tri == NULL) {
        fprintf(stderr, "out of memory\n");
        return 1;
    }
    for (size_t i = 0; i < 3 * c.nf; i++)
        c.tri[i] += BASE;
    snprintf(ref, sizeof ref, "%s/alone.tif", argv[1]);
    unlink(ref);
    gdt_error_clear(&err);
    st = run(&c, c.tri, ref, 1, ALONE, EXTENT, &err);
    CHECK(st == GDT_OK, "one thread: %s", err.msg);
    want = gdt_check_slurp(ref, &want_len);
    CHECK(want != NULL && want_len > 1000, "%s: no DEM written", ref);

    {
        static const struct {
            int threads, mode;
            const char *name;
        } ways[] = {{3, ALONE, "alone with helpers"},
                    {3, HELPERS, "two helpers"},
                    {2, HELPERS, "one helper"},
                    {3, MIXED, "helpers, the second chunk alone"}};
        for (size_t w = 0; w < sizeof ways / sizeof ways[0]; w++) {
            unsigned char *got;
            size_t len;
            snprintf(path, sizeof path, "%s/way%zu.tif", argv[1], w);
            unlink(path);
            gdt_error_clear(&err);
            st = run(&c, c.tri, path, ways[w].threads, ways[w].mode, EXTENT, &err);
            CHECK(st == GDT_OK, "%s: %s", ways[w].name, err.msg);
            got = gdt_check_slurp(path, &len);
            CHECK(got != NULL && want != NULL && len == want_len &&
                      memcmp(got, want, len) == 0,
                  "%s: DEM bytes differ from one thread's (%zu against %zu bytes)",
                  ways[w].name, len, want_len);
            free(got);
        }
    }

    /* two bad faces in the second chunk's job: parts 3 and 9 (4096 faces a
     * part); the message names the first, whoever rasterised it */
    {
        int32_t *bad = malloc(3 * c.nf * sizeof *bad);
        const size_t f1 = CHUNK + 3 * 4096 + 17, f2 = CHUNK + 9 * 4096 + 5;
        char want_msg[64];
        CHECK(bad != NULL, "out of memory");
        if (bad != NULL) {
            memcpy(bad, c.tri, 3 * c.nf * sizeof *bad);
            bad[3 * f2 + 1] = BASE + (int32_t)c.n + 5;
            bad[3 * f1 + 2] = BASE - 3;
            snprintf(want_msg, sizeof want_msg, "names vertex %d,", BASE - 3);
            for (int threads = 1; threads <= 3; threads++) {
                snprintf(path, sizeof path, "%s/bad%d.tif", argv[1], threads);
                unlink(path);
                gdt_error_clear(&err);
                st = run(&c, bad, path, threads, HELPERS, EXTENT, &err);
                CHECK(st == GDT_EINTERNAL && err.code == 7663 && strstr(err.msg, want_msg) != NULL,
                      "threads %d: status %d, error %d: %s", threads, (int)st, err.code, err.msg);
                CHECK(stat(path, &sb) != 0, "threads %d: a failed DEM was written at %s",
                      threads, path);
            }
            free(bad);
        }
    }
    /* the tile's square too small: the points on its last column lie
     * outside it */
    for (int threads = 1; threads <= 3; threads += 2) {
        snprintf(path, sizeof path, "%s/outside%d.tif", argv[1], threads);
        unlink(path);
        gdt_error_clear(&err);
        st = run(&c, c.tri, path, threads, HELPERS, c.max_x, &err);
        CHECK(st == GDT_EJOB && err.code == 6802 && strstr(err.msg, "tile.pts: point (") != NULL &&
                  strstr(err.msg, "outside its tile") != NULL,
              "threads %d, a point outside the tile: status %d, error %d: %s", threads, (int)st,
              err.code, err.msg);
        CHECK(stat(path, &sb) != 0, "threads %d: a failed DEM was written at %s", threads, path);
    }
    /* a record whose x is as far from the tile as an int64 goes (a damaged
     * file): the same failure, with no overflow on the way */
    {
        unsigned char keep[TL_REC];
        gdt_point p;
        const size_t at = (size_t)NX * 7 + 11;
        memcpy(keep, c.rec + at * TL_REC, TL_REC);
        tl_rec_get(&p, c.rec + at * TL_REC);
        p.x = INT64_MAX;
        tl_rec_put(c.rec + at * TL_REC, &p);
        snprintf(path, sizeof path, "%s/far.tif", argv[1]);
        unlink(path);
        gdt_error_clear(&err);
        st = run(&c, c.tri, path, 1, ALONE, EXTENT, &err);
        CHECK(st == GDT_EJOB && err.code == 6802 && strstr(err.msg, "tile.pts: point (") != NULL,
              "a point at x = INT64_MAX: status %d, error %d: %s", (int)st, err.code, err.msg);
        memcpy(c.rec + at * TL_REC, keep, TL_REC);
    }
    free(want);
    free(c.rec);
    free(c.tri);
    return gdt_check_finish(&T, "test_tiled_dem");
}
