/* tiler_run — drives the tiler on a set of inputs, for the Python tests and
 * the benchmark.
 *
 *   tiler_run JOB INPUT... [--tile N] [--cell S] [--halo H] [--dup RULE]
 *             [--mem-budget BYTES] [--quantum Q] [--fd-budget F]
 *             [--density-voxels V] [--keep-spill] [--no-sync] [--plan-only]
 *             [--dump-halo DIR] [--load-all]
 *
 * GDT_TEST_TINY_BUDGET=1 in the environment sets the tiny test budget.
 * Prints the plan (gdt_tile_plan_print), then machine-readable lines:
 *   plan key=value ...
 *   tile k i j x0 y0 raw points edge
 *   halo k i j n            (with --dump-halo: n halo points, written to
 *                            DIR/halo_<i>_<j>.bin as 32-byte records)
 *   time pass1=S pass2=S merge=S load=S
 *   rss pass1=MB pass2=MB load=MB   (peak RSS after each stage)
 *   stats key=value ...
 * --load-all loads every tile and its halo (timed) without writing them.
 * Exit status: the gdt_status of the first failure (0 on success). */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#include "gdt_cloud.h"
#include "gdt_tiler.h"
#include "private/tiler_io.h"

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static double peak_mb(void)
{
    struct rusage ru;
    getrusage(RUSAGE_SELF, &ru);
    return (double)ru.ru_maxrss / 1024.0;
}

static int usage(void)
{
    fprintf(stderr, "usage: tiler_run JOB INPUT... [--tile N] [--cell S] [--halo H] "
                    "[--dup RULE] [--mem-budget B] [--quantum Q] [--fd-budget F] "
                    "[--density-voxels V] [--keep-spill] [--no-sync] [--plan-only] [--dump-halo DIR] "
                    "[--load-all]\n");
    return 2;
}

static int dump_halo(const char *dir, const gdt_tile_desc *d, const gdt_point_buf *h)
{
    char path[4096];
    FILE *f;
    unsigned char rec[32];
    snprintf(path, sizeof path, "%s/halo_%" PRId64 "_%" PRId64 ".bin", dir, d->i, d->j);
    f = fopen(path, "wb");
    if (f == NULL)
        return -1;
    for (size_t k = 0; k < h->n; k++) {
        tl_rec_put(rec, &h->pts[k]);
        if (fwrite(rec, sizeof rec, 1, f) != 1) {
            fclose(f);
            return -1;
        }
    }
    return fclose(f) == 0 ? 0 : -1;
}

int main(int argc, char **argv)
{
    gdt_tiler_opts o;
    gdt_cloud_opts co;
    gdt_log log;
    gdt_error err;
    gdt_cloud *cloud = NULL;
    gdt_tiler *t = NULL;
    gdt_point_buf pts = {0}, halo = {0};
    const char **inputs;
    const char *halo_dir = NULL, *env;
    size_t ninputs = 0;
    int plan_only = 0, load_all = 0;
    double t_load = 0.0, rss1 = 0.0, rss2 = 0.0;
    gdt_status st;

    if (argc < 3)
        return usage();
    memset(&o, 0, sizeof o);
    memset(&co, 0, sizeof co);
    o.tile = 4096;
    o.halo = -1;
    o.job_dir = argv[1];
    gdt_log_init(&log, 0);
    o.log = &log;
    co.log = &log;
    inputs = calloc((size_t)argc, sizeof *inputs);
    if (inputs == NULL)
        return 7;
    for (int i = 2; i < argc; i++) {
        const char *a = argv[i];
        int more = i + 1 < argc;
        if (strcmp(a, "--tile") == 0 && more)
            o.tile = atoi(argv[++i]);
        else if (strcmp(a, "--cell") == 0 && more)
            o.cell = atof(argv[++i]);
        else if (strcmp(a, "--halo") == 0 && more)
            o.halo = atol(argv[++i]);
        else if (strcmp(a, "--dup") == 0 && more) {
            if (gdt_dup_policy_parse(argv[++i], &o.dup) != 0)
                return usage();
        } else if (strcmp(a, "--mem-budget") == 0 && more)
            o.mem_budget = strtoull(argv[++i], NULL, 10);
        else if (strcmp(a, "--quantum") == 0 && more)
            co.quantum = atof(argv[++i]);
        else if (strcmp(a, "--fd-budget") == 0 && more)
            o.fd_budget = (unsigned)atoi(argv[++i]);
        else if (strcmp(a, "--density-voxels") == 0 && more)
            o.density_voxels = (unsigned)atoi(argv[++i]);
        else if (strcmp(a, "--keep-spill") == 0)
            o.keep_spill = 1;
        else if (strcmp(a, "--no-sync") == 0)
            o.test_nosync = 1;
        else if (strcmp(a, "--plan-only") == 0)
            plan_only = 1;
        else if (strcmp(a, "--load-all") == 0)
            load_all = 1;
        else if (strcmp(a, "--dump-halo") == 0 && more)
            halo_dir = argv[++i];
        else if (strcmp(a, "-v") == 0)
            log.verbosity = 1;
        else if (a[0] == '-')
            return usage();
        else
            inputs[ninputs++] = a;
    }
    env = getenv("GDT_TEST_TINY_BUDGET");
    o.test_tiny = env != NULL && strcmp(env, "1") == 0;
    gdt_error_clear(&err);
    st = gdt_cloud_open(&cloud, inputs, ninputs, &co, &err);
    if (st == GDT_OK)
        st = gdt_tiler_create(&t, &o, cloud, &err);
    if (st == GDT_OK)
        st = gdt_tiler_pass1(t, &err);
    if (st != GDT_OK)
        goto done;
    {
        const gdt_tile_plan *p = gdt_tiler_get_plan(t);
        gdt_tile_plan_print(stdout, p);
        printf("plan tile=%d cell=%" PRId64 " halo=%" PRId64 " span=%" PRId64 " i0=%" PRId64
               " j0=%" PRId64 " nx=%" PRId64 " ny=%" PRId64 " tiles=%" PRIu64 " empty=%" PRIu64
               " min=%" PRIu64 " median=%" PRIu64 " max=%" PRIu64 " points=%" PRIu64
               " shift=%d voxels=%" PRIu64 " cell_auto=%d halo_auto=%d\n",
               p->tile, p->cell, p->halo, p->span, p->tile_i0, p->tile_j0, p->nx, p->ny,
               p->tiles, p->empty_tiles, p->min_points, p->median_points, p->max_points,
               p->points, p->density_shift, p->density_voxels, p->cell_auto, p->halo_auto);
    }
    rss1 = peak_mb();
    if (plan_only)
        goto done;
    st = gdt_tiler_pass2(t, &err);
    if (st != GDT_OK)
        goto done;
    rss2 = peak_mb();
    for (uint64_t k = 0; k < gdt_tiler_tile_count(t); k++) {
        gdt_tile_desc d;
        st = gdt_tiler_tile_info(t, k, &d, &err);
        if (st != GDT_OK)
            goto done;
        printf("tile %" PRIu64 " %" PRId64 " %" PRId64 " %" PRId64 " %" PRId64 " %" PRIu64
               " %" PRIu64 " %" PRIu64 "\n",
               k, d.i, d.j, d.x0, d.y0, d.raw_points, d.points, d.edge_points);
        if (halo_dir != NULL || load_all) {
            double t0 = now();
            st = gdt_tiler_load_tile(t, k, &pts, &halo, &err);
            t_load += now() - t0;
            if (st != GDT_OK)
                goto done;
            if (halo_dir != NULL) {
                if (dump_halo(halo_dir, &d, &halo) != 0) {
                    st = gdt_error_set(&err, GDT_EIO, 4999, "cannot write to %s", halo_dir);
                    goto done;
                }
                printf("halo %" PRIu64 " %" PRId64 " %" PRId64 " %zu\n", k, d.i, d.j, halo.n);
            }
        }
    }
    {
        const gdt_tiler_stats *s = gdt_tiler_get_stats(t);
        printf("time pass1=%.6f pass2=%.6f merge=%.6f load=%.6f\n", s->t_pass1, s->t_pass2,
               s->t_merge, t_load);
        printf("rss pass1=%.1f pass2=%.1f load=%.1f\n", rss1, rss2, peak_mb());
        printf("stats points=%" PRIu64 " bucket_records=%" PRIu64 " spill_levels=%u "
               "spill_in_memory=%u merged_duplicates=%" PRIu64 " external_merges=%" PRIu64
               " merge_levels=%u max_tile_points=%" PRIu64 " fd_budget=%u mem_budget=%" PRIu64
               "\n",
               s->points, s->bucket_records, s->spill_levels, s->spill_in_memory,
               s->merged_duplicates, s->external_merges, s->merge_levels, s->max_tile_points,
               s->fd_budget, s->mem_budget);
    }
done:
    if (st != GDT_OK)
        gdt_error_print(&err, stderr);
    gdt_point_buf_free(&pts);
    gdt_point_buf_free(&halo);
    gdt_tiler_destroy(t);
    gdt_cloud_close(cloud);
    free(inputs);
    return (int)st;
}
