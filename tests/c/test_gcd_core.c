/* test_gcd_core — the whole per-tile core against the CPU reference.
 *
 * For grid sizes 256..4096 (smaller ones with --quick) and every generator
 * of the degenerate corpus, random and LiDAR-like point sets: the core's
 * output equals gdt_reference_triangulate's as a canonical triangle set,
 * passes gdt_check_mesh, and is identical across a repeated run and a
 * permutation of the input (mapped back); the triangulation between the
 * phases is verified too (gdt_core_opts.check_phases: symbolic orientation,
 * links, Euler, vertex entries).  Both paths (digital Voronoi and
 * insertion) are forced on some sets; on the smallest grid every set also
 * goes through Phase 5 as the parallel rounds alone (the set-up of non-CPU
 * devices, with the result read back from device buffers as there) and
 * with tiny blocks and queues; duplicate points are refused
 * with GDT_EINPUT.  Without full_grid, the texel follows the points (see
 * texel_case).
 *
 *   test_gcd_core [--quick] [--big N] [--only NAME]
 * Exit 77 without an OpenCL device. */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gdt_core.h"
#include "gdt_reference.h"
#include "gen_degenerate.h"
#include "private/gcd_test.h"
#include "test_gcd_gen.h"

static double now_s(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

typedef struct opts {
    int quick;
    const char *only;
    size_t big;
} opts;

/* Cores with other Phase 5 set-ups (gcd_test_set_flip_blocks), run on the
 * smallest grid. */
typedef struct alt_cores {
    gdt_core *rounds, *tiny;
} alt_cores;

/* One point set through the core: compare with the reference; repeat; and
 * a permuted copy.  path: forced path or AUTO. */
static void run(tctx *t, gdt_core *core, gdt_core *core_ins, const gdt_ipt *pts, size_t n,
                int grid, gen_rng *rng, const char *label, int perm);

/* run(), and on the smallest grid the same set through the other set-ups. */
static void run_all(tctx *t, gdt_core *core, gdt_core *core_ins, const alt_cores *alt,
                    const gdt_ipt *pts, size_t n, int grid, gen_rng *rng, const char *label,
                    int perm)
{
    char l2[160];
    run(t, core, core_ins, pts, n, grid, rng, label, perm);
    if (grid != 256)
        return;
    snprintf(l2, sizeof l2, "%s/rounds", label);
    run(t, alt->rounds, NULL, pts, n, grid, rng, l2, 0);
    snprintf(l2, sizeof l2, "%s/tiny", label);
    run(t, alt->tiny, NULL, pts, n, grid, rng, l2, 0);
}

static void run(tctx *t, gdt_core *core, gdt_core *core_ins, const gdt_ipt *pts, size_t n,
                int grid, gen_rng *rng, const char *label, int perm)
{
    gdt_mesh ref, out, out2;
    gdt_error err;
    gdt_core_stats st, st2;
    char why[512];
    double t0, t_ref, t_core;

    memset(&err, 0, sizeof err);
    gdt_mesh_init(&ref);
    gdt_mesh_init(&out);
    gdt_mesh_init(&out2);
    t0 = now_s();
    if (gdt_reference_triangulate(NULL, pts, n, &ref, &err) != GDT_OK) {
        CHECK(t, 0, "%s: reference: %s", label, err.msg);
        goto done;
    }
    t_ref = now_s() - t0;
    t0 = now_s();
    if (gdt_core_triangulate(core, pts, n, grid, &out, &st, &err) != GDT_OK) {
        CHECK(t, 0, "%s (grid %d): %s", label, grid, err.msg);
        goto done;
    }
    t_core = now_s() - t0;
    CHECK(t, gen_same_triangles(&out, &ref, why, sizeof why) == 0,
          "%s (grid %d, path %s): differs from the reference: %s", label, grid, st.path, why);
    if (gdt_check_mesh(NULL, &out, &err) != GDT_OK)
        CHECK(t, 0, "%s (grid %d): %s", label, grid, err.msg);
    fprintf(stderr,
            "%-26s grid %5d %8zu pts %-6s kept %8" PRIu64 " miss %7" PRIu64 " debris %3" PRIu64
            " bad %5" PRIu64 " ins-it %3" PRIu64 " flips %8" PRIu64 " (%3" PRIu64
            " it) exact %6" PRIu64 " | core %.3fs ref %.3fs\n",
            label, grid, n, st.path, st.kept, st.missing_phase1, st.debris_texels, st.bad_cases,
            st.insert_iterations, st.flips, st.flip_iterations, st.exact_escalations, t_core,
            t_ref);
    /* repeat: identical triangles in the same order */
    if (gdt_core_triangulate(core, pts, n, grid, &out2, &st2, &err) != GDT_OK) {
        CHECK(t, 0, "%s: repeat: %s", label, err.msg);
        goto done;
    }
    CHECK(t, out2.ntris == out.ntris &&
                 (out.ntris == 0 || memcmp(out2.tri, out.tri, 3 * out.ntris * sizeof *out.tri) == 0) &&
                 st2.flips == st.flips && st2.bad_cases == st.bad_cases,
          "%s: a repeated run differs", label);
    /* the other path */
    if (core_ins != NULL) {
        if (gdt_core_triangulate(core_ins, pts, n, grid, &out2, &st2, &err) != GDT_OK) {
            CHECK(t, 0, "%s: insertion path: %s", label, err.msg);
            goto done;
        }
        CHECK(t, gen_same_triangles(&out2, &ref, why, sizeof why) == 0,
              "%s (grid %d, path %s): differs from the reference: %s", label, grid, st2.path,
              why);
        fprintf(stderr,
                "%-26s grid %5d %8zu pts %-6s inserted %7" PRIu64 " ins-it %3" PRIu64
                " walk %8" PRIu64 " ins-flips %8" PRIu64 " flips %8" PRIu64 " | core %.3fs\n",
                label, grid, n, st2.path, st2.inserted, st2.insert_iterations, st2.walk_steps,
                st2.insert_flips, st2.flips, st2.t_total);
    }
    if (perm) {
        gdt_ipt *q = malloc((n ? n : 1) * sizeof *q);
        int64_t *pi = malloc((n ? n : 1) * sizeof *pi);
        if (n > 0)
            memcpy(q, pts, n * sizeof *q);
        gen_shuffle(rng, q, n, pi);
        if (gdt_core_triangulate(core, q, n, grid, &out2, &st2, &err) != GDT_OK) {
            CHECK(t, 0, "%s: permuted: %s", label, err.msg);
        } else {
            /* vertex i of out2 is input point pi[i]: compare as id sets */
            if (gdt_mesh_reserve(&out2, out2.nverts, out2.ntris, 1, &err) == GDT_OK) {
                for (size_t i = 0; i < n; i++)
                    out2.ids[i] = pi[i];
                CHECK(t, gen_same_triangles(&out2, &ref, why, sizeof why) == 0,
                      "%s: permuted input gives another triangulation: %s", label, why);
            }
        }
        free(q);
        free(pi);
    }
done:
    gdt_mesh_free(&ref);
    gdt_mesh_free(&out);
    gdt_mesh_free(&out2);
}

/* The texel a tile's points get without full_grid: never finer than the
 * tile's grid (at most grid texels per side), at least 64 texels along the
 * longer side of the points' bounding box, and in between about 4 texels
 * per point over that box (between 4 and 8 per point after rounding); a
 * full tile gets (nearly) the whole grid.
 * The triangulation stays the reference's. */
static void texel_case(tctx *t, gdt_core *core, const gdt_ipt *pts, size_t n, int grid,
                       const char *label, int want_full)
{
    gdt_mesh ref, out;
    gdt_error err;
    gdt_core_stats st;
    char why[512];
    double per;
    uint32_t side;

    memset(&err, 0, sizeof err);
    gdt_mesh_init(&ref);
    gdt_mesh_init(&out);
    if (gdt_reference_triangulate(NULL, pts, n, &ref, &err) != GDT_OK ||
        gdt_core_triangulate(core, pts, n, grid, &out, &st, &err) != GDT_OK) {
        CHECK(t, 0, "texel %s: %s", label, err.msg);
        goto done;
    }
    CHECK(t, gen_same_triangles(&out, &ref, why, sizeof why) == 0,
          "texel %s: differs from the reference: %s", label, why);
    side = st.grid_w > st.grid_h ? st.grid_w : st.grid_h;
    per = (double)st.grid_w * (double)st.grid_h / (double)n;
    fprintf(stderr, "texel %-24s grid %5d %8zu pts: %u x %u texels of %" PRId64 " (%.2f per point)\n",
            label, grid, n, st.grid_w, st.grid_h, st.cell, per);
    CHECK(t, st.grid_w <= (uint32_t)grid && st.grid_h <= (uint32_t)grid,
          "texel %s: %u x %u texels on a grid of %d", label, st.grid_w, st.grid_h, grid);
    if (want_full)
        CHECK(t, (uint64_t)side * 100 >= (uint64_t)grid * 95,
              "texel %s: a full tile got %u texels per side of %d",
              label, side, grid);
    else
        CHECK(t, side >= 64 && (side <= 66 || (per >= 3.9 && per <= 8.0)),
              "texel %s: %u x %u texels for %zu points (%.2f per point)", label, st.grid_w,
              st.grid_h, n, per);
done:
    gdt_mesh_free(&ref);
    gdt_mesh_free(&out);
}

int main(int argc, char **argv)
{
    tctx t = {0, 0};
    gdt_core *core = NULL, *core_ins = NULL;
    alt_cores alt = {NULL, NULL};
    gdt_core_opts o;
    gdt_error err;
    gen_rng rng;
    opts op = {0, NULL, 200000};
    char label[128];

    for (int i = 1; i < argc; i++) {
        if (strcmp(argv[i], "--quick") == 0)
            op.quick = 1;
        else if (strcmp(argv[i], "--big") == 0 && i + 1 < argc)
            op.big = (size_t)strtoull(argv[++i], NULL, 10);
        else if (strcmp(argv[i], "--only") == 0 && i + 1 < argc)
            op.only = argv[++i];
    }
    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    o.path = GDT_CORE_PATH_GCD;
    /* every phase boundary is verified: a valid triangulation after
     * phases 2, 3 and 4, not only at the end */
    o.check_phases = 1;
    o.full_grid = 1; /* the grid sizes below, whatever the point count */
    if (gdt_core_create(&core, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    /* the rounds core also reads its result back, with the launch sizes and
     * the column layout of a GPU */
    o.copy_out = 1;
    o.gpu_layout = 1;
    if (gdt_core_create(&alt.rounds, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return 1;
    }
    o.copy_out = 0;
    o.gpu_layout = 0;
    if (gdt_core_create(&alt.tiny, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return 1;
    }
    gcd_test_set_flip_blocks(alt.rounds, 0, 0, 0);
    gcd_test_set_flip_blocks(alt.tiny, 1000000, 32, 8);
    o.path = GDT_CORE_PATH_INSERT;
    if (gdt_core_create(&core_ins, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return 1;
    }
    gen_seed(&rng, 31337);
#define ONLY(name) (op.only == NULL || strstr(name, op.only) != NULL)
    static const int grids[] = {256, 1024, 4096};
    for (size_t gi = 0; gi < sizeof grids / sizeof grids[0]; gi++) {
        int g = grids[gi];
        size_t n;
        gdt_ipt *p;
        if (op.quick && g > 256)
            break;
        if (ONLY("uniform")) {
            size_t want = (size_t)g * g / 4 < op.big ? (size_t)g * g / 4 : op.big;
            p = gen_uniform(&rng, want, 0, 5000000, &n);
            snprintf(label, sizeof label, "uniform");
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, label, 1);
            free(p);
        }
        if (ONLY("lidar")) {
            size_t want = (size_t)g * g / 4 < op.big ? (size_t)g * g / 4 : op.big;
            p = gcd_gen_lidar(&rng, want, 3000000, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "lidar-like", 1);
            free(p);
        }
        if (ONLY("grid")) {
            p = gen_grid(300, 200, 1000, 2000, 5, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "grid", 1);
            free(p);
        }
        if (ONLY("rotated")) {
            p = gen_rotated_grid(80, 3, 4, 1000000, 1000000, &n);
            run_all(&t, core, NULL, &alt, p, n, g, &rng, "rotated grid", 0);
            free(p);
        }
        if (ONLY("circle")) {
            p = gen_circle(1000000, 1000000, 5525, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "circle", 1);
            free(p);
            p = gen_thin_circle(&rng, 20000, 1000000, 1000000, 900000, 3, &n);
            run_all(&t, core, NULL, &alt, p, n, g, &rng, "thin circle", 0);
            free(p);
        }
        if (ONLY("collinear")) {
            p = gen_collinear(&rng, 500, 10, 20, 3, 7, 100000, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "collinear", 1);
            free(p);
        }
        if (ONLY("clusters")) {
            p = gen_clusters(&rng, 20, 2000, 300, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "clusters", 1);
            free(p);
        }
        if (ONLY("extremes")) {
            p = gen_extremes(&rng, &n);
            run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, p, n, g, &rng, "extremes", 1);
            free(p);
        }
        if (ONLY("few")) {
            gdt_ipt few[5] = {{10, 10}, {2000000000, 11}, {15, 2000000000}, {40, 40}, {41, 41}};
            for (size_t k = 0; k <= 5; k++) {
                snprintf(label, sizeof label, "%zu points", k);
                run_all(&t, core, gi == 0 ? core_ins : NULL, &alt, few, k, g, &rng, label, 0);
            }
        }
    }
    if (ONLY("texel")) {
        gdt_core *tc = NULL;
        gdt_ipt *p;
        size_t n;
        o.full_grid = 0;
        o.path = GDT_CORE_PATH_AUTO;
        if (gdt_core_create(&tc, &o, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            return 1;
        }
        /* a full tile of 1024 texels: about 1024^2 / 4 points over its square */
        p = gen_uniform(&rng, 1024 * 1024 / 4, 0, 1024 * 50, &n);
        texel_case(&t, tc, p, n, 1024, "full tile", 1);
        free(p);
        /* a sparse tile: 2000 points over the same square */
        p = gen_uniform(&rng, 2000, 0, 1024 * 50, &n);
        texel_case(&t, tc, p, n, 1024, "sparse", 0);
        free(p);
        /* very few points: the 64-texel floor */
        p = gen_uniform(&rng, 100, 0, 1024 * 50, &n);
        texel_case(&t, tc, p, n, 1024, "100 points", 0);
        free(p);
        /* an edge tile, its points in a strip of a sixteenth of the square */
        p = gen_uniform(&rng, 4000, 0, 1024 * 50, &n);
        for (size_t i = 0; i < n; i++)
            p[i].y = p[i].y / 16 + 7;
        gen_dedup(p, &n);
        texel_case(&t, tc, p, n, 1024, "strip", 0);
        free(p);
        gdt_core_destroy(tc);
    }
    if (ONLY("dup")) {
        gdt_ipt d[4] = {{5, 5}, {100, 7}, {5, 5}, {50, 90}};
        gdt_mesh m;
        gdt_mesh_init(&m);
        memset(&err, 0, sizeof err);
        gdt_status s = gdt_core_triangulate(core, d, 4, 256, &m, NULL, &err);
        CHECK(&t, s == GDT_EINPUT && err.code == 3602, "duplicates: status %d code %d (%s)", s,
              err.code, err.msg);
        gdt_mesh_free(&m);
    }
    gdt_core_destroy(core);
    gdt_core_destroy(core_ins);
    gdt_core_destroy(alt.rounds);
    gdt_core_destroy(alt.tiny);
    return gen_finish(&t, "test_gcd_core");
}
