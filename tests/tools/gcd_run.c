/* gcd_run — runs the per-tile core on one point set and reports per-phase
 * figures (the core side of scripts/bench_core.py, and a profiling aid).
 *
 *   gcd_run [--device SPEC] [--grid N] [--path auto|gcd|insert] [--repeat K]
 *           [--check] [--reference] [--no-fp64] [--check-phases] [--profile]
 *           [--gpu-layout] [--copy-out]
 *           (--gen uniform|lidar|grid COUNT SEED | --points FILE | --cloud LAS/PCD)
 *           [--dump-points FILE] [--dump-pcd FILE [--dump-only]] [--json]
 *
 * Points files (also read by tests/tools/cgal_bench.cpp): the 8 bytes
 * "GDTPTS1\n", a little-endian uint64 count, then count pairs of int64 x, y
 * (tile-local lattice coordinates).  --dump-points writes the generated set.
 * --dump-pcd writes it as a binary PCD cloud for gdt-tile: x and y in
 * metres on a 1 cm lattice (x = 0.01 ix), z a smooth terrain of them, all
 * doubles; with --dump-only nothing else is done (no device is opened).
 * --cloud reads a LAS or PCD file like gdt-tile --reference does (every
 * point, duplicates merged keeping the first, input order, coordinates
 * relative to the lower-left corner).
 * --check verifies the output exactly (gdt_check_mesh, gdt_check_delaunay);
 * --reference also runs the CPU reference and compares the triangle sets.
 * --gpu-layout uses the launch sizes and column layout chosen for a GPU on
 * whatever device runs (gdt_core_opts.gpu_layout); --copy-out reads the
 * result back from device buffers, as on a device with memory of its own
 * (gdt_core_opts.copy_out).  The JSON's device_peak_bytes is the most the
 * core's device buffers held at once (gdt_core_device_peak), and
 * tile_bytes_bound what gdt_core_tile_bytes allows for it.
 * --repeat K runs K times and reports the fastest total (with its phases).
 * Output: one line of figures, or one JSON object with --json.
 * Exit: 0 ok, 1 failure, 2 usage, 77 no OpenCL device. */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_cloud.h"
#include "gdt_core.h"
#include "gdt_reference.h"
#include "gen_degenerate.h"
#include "test_gcd_gen.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int write_points(const char *path, const gdt_ipt *p, size_t n)
{
    FILE *f = fopen(path, "wb");
    uint64_t cnt = n;
    int ok = f != NULL && fwrite("GDTPTS1\n", 1, 8, f) == 8 && fwrite(&cnt, 8, 1, f) == 1;
    for (size_t i = 0; ok && i < n; i++) {
        int64_t xy[2] = {p[i].x, p[i].y};
        ok = fwrite(xy, 8, 2, f) == 2;
    }
    if (f != NULL && fclose(f) != 0)
        ok = 0;
    return ok ? 0 : -1;
}

static int write_pcd(const char *path, const gdt_ipt *p, size_t n)
{
    FILE *f = fopen(path, "wb");
    int ok = f != NULL &&
             fprintf(f,
                     "# .PCD v0.7 - gcd_run\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\n"
                     "TYPE F F F\nCOUNT 1 1 1\nWIDTH %zu\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
                     "POINTS %zu\nDATA binary\n",
                     n, n) > 0;
    for (size_t i = 0; ok && i < n; i++) {
        double x = 0.01 * (double)p[i].x, y = 0.01 * (double)p[i].y;
        double xyz[3] = {x, y, 100.0 + 0.02 * x + 3.0 * sin(0.01 * x) * cos(0.013 * y)};
        ok = fwrite(xyz, 8, 3, f) == 3;
    }
    if (f != NULL && fclose(f) != 0)
        ok = 0;
    return ok ? 0 : -1;
}

static gdt_ipt *read_points(const char *path, size_t *n)
{
    FILE *f = fopen(path, "rb");
    char magic[8];
    uint64_t cnt = 0;
    gdt_ipt *p = NULL;
    if (f == NULL || fread(magic, 1, 8, f) != 8 || memcmp(magic, "GDTPTS1\n", 8) != 0 ||
        fread(&cnt, 8, 1, f) != 1 || cnt > ((uint64_t)1 << 28))
        goto fail;
    p = malloc((cnt ? cnt : 1) * sizeof *p);
    for (uint64_t i = 0; p != NULL && i < cnt; i++) {
        int64_t xy[2];
        if (fread(xy, 8, 2, f) != 2) {
            free(p);
            p = NULL;
            break;
        }
        p[i].x = xy[0];
        p[i].y = xy[1];
    }
    *n = (size_t)cnt;
fail:
    if (f != NULL)
        fclose(f);
    return p;
}

static int cmp_ord(const void *a, const void *b)
{
    const gdt_point *p = a, *q = b;
    return (p->ord > q->ord) - (p->ord < q->ord);
}

/* Reads a LAS/PCD cloud like the --reference mode of gdt-tile: every
 * point, duplicates merged (first occurrence), input order, coordinates
 * relative to the lower-left corner. */
static gdt_ipt *read_cloud(const char *path, size_t *n_out)
{
    gdt_cloud *cloud = NULL;
    gdt_cloud_opts co;
    gdt_error err;
    gdt_point *pts = NULL;
    gdt_ipt *out = NULL;
    size_t n = 0, cap = 0, kept = 0;
    const char *paths[1] = {path};

    memset(&co, 0, sizeof co);
    memset(&err, 0, sizeof err);
    if (gdt_cloud_open(&cloud, paths, 1, &co, &err) != GDT_OK)
        goto fail;
    for (;;) {
        size_t got = 0;
        if (cap - n < 65536) {
            gdt_point *g = realloc(pts, (cap + (cap > 65536 ? cap : 65536)) * sizeof *g);
            if (g == NULL)
                goto fail;
            pts = g;
            cap += cap > 65536 ? cap : 65536;
        }
        if (gdt_cloud_read(cloud, pts + n, cap - n, &got, &err) != GDT_OK)
            goto fail;
        if (got == 0)
            break;
        n += got;
    }
    if (gdt_points_dedup(pts, n, GDT_DUP_FIRST, &kept, &err) != GDT_OK)
        goto fail;
    qsort(pts, kept, sizeof *pts, cmp_ord);
    out = malloc((kept ? kept : 1) * sizeof *out);
    if (out == NULL)
        goto fail;
    int64_t mx = kept ? pts[0].x : 0, my = kept ? pts[0].y : 0;
    for (size_t i = 0; i < kept; i++) {
        if (pts[i].x < mx)
            mx = pts[i].x;
        if (pts[i].y < my)
            my = pts[i].y;
    }
    for (size_t i = 0; i < kept; i++) {
        out[i].x = pts[i].x - mx;
        out[i].y = pts[i].y - my;
    }
    *n_out = kept;
    free(pts);
    gdt_cloud_close(cloud);
    return out;
fail:
    if (err.status != GDT_OK)
        gdt_error_print(&err, stderr);
    free(pts);
    gdt_cloud_close(cloud);
    return NULL;
}

static void usage(void)
{
    fprintf(stderr, "usage: gcd_run [--device SPEC] [--grid N] [--path auto|gcd|insert] "
                    "[--repeat K] [--check] [--reference] [--no-fp64] [--check-phases] [--profile] "
                    "[--gpu-layout] [--copy-out] "
                    "(--gen uniform|lidar|grid COUNT SEED | --points FILE | --cloud LAS/PCD) "
                    "[--dump-points FILE] [--dump-pcd FILE [--dump-only]] [--json]\n");
}

int main(int argc, char **argv)
{
    const char *device = NULL, *gen = NULL, *in = NULL, *dump = NULL, *cloud = NULL,
               *dump_pcd = NULL;
    int grid = 4096, repeat = 1, check = 0, reference = 0, json = 0, nofp64 = 0, check_phases = 0,
        profile = 0, gpu_layout = 0, copy_out = 0, dump_only = 0;
    gdt_core_path_choice path = GDT_CORE_PATH_AUTO;
    size_t count = 0, n = 0;
    uint64_t seed = 1;
    gdt_ipt *pts = NULL;
    gdt_core *core = NULL;
    gdt_core_opts o;
    gdt_core_stats best, st;
    gdt_mesh m;
    gdt_error err;
    int rc = 1;

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--device") == 0 && i + 1 < argc)
            device = argv[++i];
        else if (strcmp(argv[i], "--grid") == 0 && i + 1 < argc)
            grid = atoi(argv[++i]);
        else if (strcmp(argv[i], "--repeat") == 0 && i + 1 < argc)
            repeat = atoi(argv[++i]);
        else if (strcmp(argv[i], "--path") == 0 && i + 1 < argc) {
            const char *v = argv[++i];
            path = strcmp(v, "gcd") == 0 ? GDT_CORE_PATH_GCD
                   : strcmp(v, "insert") == 0 ? GDT_CORE_PATH_INSERT
                                               : GDT_CORE_PATH_AUTO;
        } else if (strcmp(argv[i], "--check") == 0)
            check = 1;
        else if (strcmp(argv[i], "--reference") == 0)
            reference = 1;
        else if (strcmp(argv[i], "--no-fp64") == 0)
            nofp64 = 1;
        else if (strcmp(argv[i], "--gpu-layout") == 0)
            gpu_layout = 1;
        else if (strcmp(argv[i], "--copy-out") == 0)
            copy_out = 1;
        else if (strcmp(argv[i], "--check-phases") == 0)
            check_phases = 1;
        else if (strcmp(argv[i], "--profile") == 0)
            profile = 1;
        else if (strcmp(argv[i], "--json") == 0)
            json = 1;
        else if (strcmp(argv[i], "--gen") == 0 && i + 3 < argc) {
            gen = argv[++i];
            count = (size_t)strtoull(argv[++i], NULL, 10);
            seed = strtoull(argv[++i], NULL, 10);
        } else if (strcmp(argv[i], "--points") == 0 && i + 1 < argc)
            in = argv[++i];
        else if (strcmp(argv[i], "--cloud") == 0 && i + 1 < argc)
            cloud = argv[++i];
        else if (strcmp(argv[i], "--dump-points") == 0 && i + 1 < argc)
            dump = argv[++i];
        else if (strcmp(argv[i], "--dump-pcd") == 0 && i + 1 < argc)
            dump_pcd = argv[++i];
        else if (strcmp(argv[i], "--dump-only") == 0)
            dump_only = 1;
        else {
            usage();
            return 2;
        }
    }
    if ((gen != NULL) + (in != NULL) + (cloud != NULL) != 1 || repeat < 1 ||
        (dump_only && dump_pcd == NULL && dump == NULL)) {
        usage();
        return 2;
    }
    if (cloud != NULL) {
        pts = read_cloud(cloud, &n);
        if (pts == NULL) {
            fprintf(stderr, "gcd_run: cannot read %s\n", cloud);
            return 1;
        }
    } else if (in != NULL) {
        pts = read_points(in, &n);
        if (pts == NULL) {
            fprintf(stderr, "gcd_run: cannot read points file %s\n", in);
            return 1;
        }
    } else {
        gen_rng rng;
        gen_seed(&rng, seed);
        if (strcmp(gen, "uniform") == 0) {
            /* the density of a tile: about grid^2/4 points per grid^2 texels */
            pts = gen_uniform(&rng, count, 0, 100 * (int64_t)grid, &n);
        } else if (strcmp(gen, "lidar") == 0) {
            pts = gcd_gen_lidar(&rng, count, 100 * (int64_t)grid, &n);
        } else if (strcmp(gen, "grid") == 0) {
            size_t side = 1;
            while ((side + 1) * (side + 1) <= count)
                side++;
            pts = gen_grid(side, side, 0, 0, 200 * (int64_t)grid / (int64_t)side, &n);
        } else {
            usage();
            return 2;
        }
        if (pts == NULL) {
            fprintf(stderr, "gcd_run: out of memory\n");
            return 1;
        }
    }
    if (dump != NULL && write_points(dump, pts, n) != 0) {
        fprintf(stderr, "gcd_run: cannot write %s\n", dump);
        goto done;
    }
    if (dump_pcd != NULL && write_pcd(dump_pcd, pts, n) != 0) {
        fprintf(stderr, "gcd_run: cannot write %s\n", dump_pcd);
        goto done;
    }
    if (dump_only) {
        rc = 0;
        goto done;
    }
    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = device;
    o.path = path;
    o.force_no_fp64 = nofp64;
    o.gpu_layout = gpu_layout;
    o.copy_out = copy_out;
    o.check_phases = check_phases;
    o.profile = profile;
    if (gdt_core_create(&core, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        rc = err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
        goto done;
    }
    gdt_mesh_init(&m);
    for (int k = 0; k < repeat; k++) {
        if (gdt_core_triangulate(core, pts, n, grid, &m, &st, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            gdt_mesh_free(&m);
            goto done;
        }
        if (k == 0 || st.t_total < best.t_total)
            best = st;
    }
    if (check) {
        if (gdt_check_mesh(NULL, &m, &err) != GDT_OK || gdt_check_delaunay(NULL, &m, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            gdt_mesh_free(&m);
            goto done;
        }
    }
    double t_ref = 0;
    if (reference) {
        gdt_mesh ref;
        char why[512];
        double t0 = now_s();
        gdt_mesh_init(&ref);
        if (gdt_reference_triangulate(NULL, pts, n, &ref, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            gdt_mesh_free(&m);
            gdt_mesh_free(&ref);
            goto done;
        }
        t_ref = now_s() - t0;
        if (gen_same_triangles(&m, &ref, why, sizeof why) != 0) {
            fprintf(stderr, "gcd_run: core differs from the reference: %s\n", why);
            gdt_mesh_free(&m);
            gdt_mesh_free(&ref);
            goto done;
        }
        gdt_mesh_free(&ref);
    }
    if (json) {
        printf("{\"device\": \"%s\", \"points\": %zu, \"grid\": %d, \"path\": \"%s\", "
               "\"path_reason\": \"%s\", \"triangles\": %" PRIu64 ", "
               "\"times_s\": {\"upload\": %.6f, \"phase1\": %.6f, \"phase2\": %.6f, "
               "\"phase3\": %.6f, \"phase4\": %.6f, \"phase5\": %.6f, \"download\": %.6f, "
               "\"total\": %.6f%s%.6f}, "
               "\"kept\": %" PRIu64 ", \"missing_phase1\": %" PRIu64 ", \"debris_texels\": %" PRIu64
               ", \"bad_cases\": %" PRIu64 ", \"shift_iterations\": %" PRIu64
               ", \"delete_iterations\": %" PRIu64 ", \"insert_iterations\": %" PRIu64
               ", \"walk_steps\": %" PRIu64 ", \"flips\": %" PRIu64 ", \"flip_iterations\": %" PRIu64
               ", \"exact_escalations\": %" PRIu64 ", \"tiebreaks\": %" PRIu64
               ", \"device_peak_bytes\": %" PRIu64 ", \"tile_bytes_bound\": %" PRIu64
               ", \"checked\": %s, \"reference_equal\": %s}\n",
               gdt_core_device_name(core), n, grid, best.path, best.path_reason, best.triangles,
               best.t_upload, best.t_phase1, best.t_phase2, best.t_phase3, best.t_phase4,
               best.t_phase5, best.t_download, best.t_total, reference ? ", \"reference\": " : ", \"_\": ",
               t_ref, best.kept, best.missing_phase1, best.debris_texels, best.bad_cases,
               best.shift_iterations, best.delete_iterations, best.insert_iterations,
               best.walk_steps, best.flips + best.insert_flips, best.flip_iterations,
               best.exact_escalations, best.tiebreaks, gdt_core_device_peak(core),
               gdt_core_tile_bytes(grid, n),
               check ? "true" : "false",
               reference ? "true" : "false");
    } else {
        printf("%zu points grid %d path %s (%s): total %.3fs = upload %.3f + p1 %.3f + p2 %.3f + "
               "p3 %.3f + p4 %.3f + p5 %.3f + download %.3f; kept %" PRIu64 " missing %" PRIu64
               " debris %" PRIu64 " bad %" PRIu64 " (shift %" PRIu64 " it, delete %" PRIu64
               " it) insert %" PRIu64 " it, walk %" PRIu64 "; flips %" PRIu64 " (%" PRIu64
               " it) exact %" PRIu64 " ties %" PRIu64 "%s\n",
               n, grid, best.path, best.path_reason, best.t_total, best.t_upload, best.t_phase1,
               best.t_phase2, best.t_phase3, best.t_phase4, best.t_phase5, best.t_download,
               best.kept, best.missing_phase1, best.debris_texels, best.bad_cases,
               best.shift_iterations, best.delete_iterations, best.insert_iterations,
               best.walk_steps, best.flips + best.insert_flips, best.flip_iterations,
               best.exact_escalations, best.tiebreaks, reference ? "; equals the reference" : "");
        if (reference)
            printf("reference %.3fs\n", t_ref);
    }
    gdt_mesh_free(&m);
    if (profile)
        gdt_core_profile_dump(core, stderr);
    rc = 0;
done:
    gdt_core_destroy(core);
    free(pts);
    return rc;
}
