/* test_gcd_flip — Phase 5 of the gCD core (flipping) on its own.
 *
 * Start: the reference triangulation scrambled by many random flips of
 * strictly convex quads (a valid but far from Delaunay triangulation), for
 * random points and the degenerate corpus (grids and circles: every quad
 * co-circular, so the tie-break decides; extreme coordinates: the exact
 * path).  The device must reach exactly the reference triangle set (Thm
 * 4.1: T_{d1,d2} does not depend on the start), with valid links, and the
 * result must not depend on the start (two different scrambles, the second
 * with its triangles stored in spatial order, as the core stores them).
 * Every set goes through three set-ups of the flipping: the device's
 * default (block-local passes, then parallel rounds), the parallel rounds
 * alone, and tiny blocks with tiny queues (many slots deferred from pass
 * to pass, the single-work-item pass, queue overflows, the rounds).
 * Runs with the double filter and with the integer-only path.
 * Exit 77 without an OpenCL device. */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_reference.h"
#include "gen_degenerate.h"
#include "private/gcd_test.h"
#include "private/mesh_ops.h"

/* Random flips of strictly convex quads. */
static uint64_t scramble(gdt_mesh *m, gen_rng *rng, size_t flips)
{
    uint64_t done = 0;
    for (size_t k = 0; k < flips && m->ntris > 0; k++) {
        int32_t t = (int32_t)gen_below(rng, m->ntris);
        int i = (int)gen_below(rng, 3);
        int32_t o = m->opp[3 * (size_t)t + (size_t)i];
        if (o < 0)
            continue;
        int32_t *T = m->tri + 3 * (size_t)t;
        int32_t u = gdt_opp_tri(o);
        int j = gdt_opp_slot(o);
        gdt_ipt c = m->pts[T[i]], a = m->pts[T[(i + 1) % 3]], b = m->pts[T[(i + 2) % 3]];
        gdt_ipt d = m->pts[m->tri[3 * (size_t)u + (size_t)j]];
        if (gdt_orient2d(NULL, d, b, c) <= 0 || gdt_orient2d(NULL, c, a, d) <= 0)
            continue;
        mesh_flip(m->tri, m->opp, t, i);
        done++;
    }
    return done;
}

/* Stores the triangles of m in the order of a coarse row-major grid of
 * their first vertex (links renumbered), like the core's slot order. */
static void spatial_order(gdt_mesh *m)
{
    size_t T = m->ntris;
    int64_t xmin = INT64_MAX, ymin = INT64_MAX, xmax = INT64_MIN, ymax = INT64_MIN;
    int64_t *key = malloc((T ? T : 1) * sizeof *key);
    int32_t *order = malloc((T ? T : 1) * sizeof *order);
    int32_t *newidx = malloc((T ? T : 1) * sizeof *newidx);
    int32_t *tri = malloc(3 * (T ? T : 1) * sizeof *tri);
    int32_t *opp = malloc(3 * (T ? T : 1) * sizeof *opp);
    if (key == NULL || order == NULL || newidx == NULL || tri == NULL || opp == NULL)
        abort();
    for (size_t v = 0; v < m->nverts; v++) {
        xmin = m->pts[v].x < xmin ? m->pts[v].x : xmin;
        ymin = m->pts[v].y < ymin ? m->pts[v].y : ymin;
        xmax = m->pts[v].x > xmax ? m->pts[v].x : xmax;
        ymax = m->pts[v].y > ymax ? m->pts[v].y : ymax;
    }
    int64_t cw = (xmax - xmin) / 64 + 1, ch = (ymax - ymin) / 64 + 1;
    for (size_t k = 0; k < T; k++) {
        gdt_ipt p = m->pts[m->tri[3 * k]];
        key[k] = ((p.y - ymin) / ch) * 64 + (p.x - xmin) / cw;
        order[k] = (int32_t)k;
    }
    /* counting sort by key (64 x 64 cells), stable */
    {
        size_t cnt[64 * 64 + 1];
        memset(cnt, 0, sizeof cnt);
        for (size_t k = 0; k < T; k++)
            cnt[key[k] + 1]++;
        for (size_t c = 1; c <= 64 * 64; c++)
            cnt[c] += cnt[c - 1];
        for (size_t k = 0; k < T; k++)
            order[cnt[key[k]]++] = (int32_t)k;
    }
    for (size_t k = 0; k < T; k++)
        newidx[order[k]] = (int32_t)k;
    for (size_t k = 0; k < T; k++) {
        int32_t o = order[k];
        for (int i = 0; i < 3; i++) {
            int32_t q = m->opp[3 * (size_t)o + (size_t)i];
            tri[3 * k + (size_t)i] = m->tri[3 * (size_t)o + (size_t)i];
            opp[3 * k + (size_t)i] =
                q < 0 ? q : gdt_opp_pack(newidx[gdt_opp_tri(q)], gdt_opp_slot(q));
        }
    }
    memcpy(m->tri, tri, 3 * T * sizeof *tri);
    memcpy(m->opp, opp, 3 * T * sizeof *opp);
    free(key);
    free(order);
    free(newidx);
    free(tri);
    free(opp);
}

/* Flip set-ups: {blocks, smallest block, queue}; SIZE_MAX: the device
 * default. */
static const size_t SETUPS[3][3] = {{SIZE_MAX, 0, 0}, {0, 0, 0}, {100000, 16, 8}};
static const char *const SETUP_NAMES[3] = {"default", "rounds only", "tiny blocks"};

static void run(tctx *t, gdt_core *core, const gdt_ipt *pts, size_t n, gen_rng *rng,
                const char *label)
{
    gdt_mesh ref, m;
    gdt_error err;
    gdt_core_stats st;
    char why[512];

    memset(&err, 0, sizeof err);
    gdt_mesh_init(&ref);
    gdt_mesh_init(&m);
    if (gdt_reference_triangulate(NULL, pts, n, &ref, &err) != GDT_OK) {
        CHECK(t, 0, "%s: reference: %s", label, err.msg);
        goto done;
    }
    for (int run = 0; run < 6; run++) {
        int pass = run % 2, setup = run / 2;
        memset(&st, 0, sizeof st);
        gcd_test_set_flip_blocks(core, SETUPS[setup][0], SETUPS[setup][1], SETUPS[setup][2]);
        if (gdt_mesh_reserve(&m, ref.nverts, ref.ntris, 0, &err) != GDT_OK)
            abort();
        memcpy(m.pts, ref.pts, ref.nverts * sizeof *m.pts);
        memcpy(m.tri, ref.tri, 3 * ref.ntris * sizeof *m.tri);
        memcpy(m.opp, ref.opp, 3 * ref.ntris * sizeof *m.opp);
        m.nverts = ref.nverts;
        m.ntris = ref.ntris;
        uint64_t scr = scramble(&m, rng, 8 * m.ntris + 100);
        if (pass == 1)
            spatial_order(&m);
        if (gcd_test_flip(core, &m, &st, &err) != GDT_OK) {
            CHECK(t, 0, "%s (%s): %s", label, SETUP_NAMES[setup], err.msg);
            continue;
        }
        CHECK(t, gen_same_triangles(&m, &ref, why, sizeof why) == 0,
              "%s (%s, pass %d): differs from the reference: %s", label, SETUP_NAMES[setup],
              pass, why);
        if (gdt_check_mesh(NULL, &m, &err) != GDT_OK)
            CHECK(t, 0, "%s (%s): %s", label, SETUP_NAMES[setup], err.msg);
        CHECK(t, scr == 0 || st.flips > 0, "%s: no flip after %" PRIu64 " scrambling flips",
              label, scr);
        CHECK(t, setup != 1 || scr == 0 || st.flip_iterations > 0,
              "%s: the parallel rounds alone made no round", label);
        fprintf(stderr,
                "%-22s %-11s %d %7zu tris %7" PRIu64 " flips %4" PRIu64 " rounds %7" PRIu64
                " exact %6" PRIu64 " tie\n",
                label, SETUP_NAMES[setup], pass, m.ntris, st.flips, st.flip_iterations,
                st.exact_escalations, st.tiebreaks);
    }
    gcd_test_set_flip_blocks(core, SIZE_MAX, 0, 0);
done:
    gdt_mesh_free(&ref);
    gdt_mesh_free(&m);
}

int main(int argc, char **argv)
{
    tctx t = {0, 0};
    gdt_core *core = NULL;
    gdt_core_opts o;
    gdt_error err;
    gen_rng rng;
    char label[128];
    size_t big = argc > 1 ? (size_t)strtoull(argv[1], NULL, 10) : 100000;

    for (int intpath = 0; intpath < 2; intpath++) {
        memset(&o, 0, sizeof o);
        memset(&err, 0, sizeof err);
        o.device = getenv("GDT_TEST_DEVICE");
        o.force_no_fp64 = intpath;
        if (gdt_core_create(&core, &o, &err) != GDT_OK) {
            gdt_error_print(&err, stderr);
            return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
        }
        fprintf(stderr, "-- %s path\n", intpath ? "integer-only" : "double filter");
        gen_seed(&rng, 99 + (uint64_t)intpath);
        size_t n;
        gdt_ipt *p;
        p = gen_uniform(&rng, intpath ? big / 10 : big, 0, 1000000, &n);
        snprintf(label, sizeof label, "uniform %zu", n);
        run(&t, core, p, n, &rng, label);
        free(p);
        p = gen_uniform(&rng, 3000, 0, 2147483647, &n);
        run(&t, core, p, n, &rng, "uniform full range");
        free(p);
        p = gen_grid(60, 45, 100, 200, 7, &n);
        run(&t, core, p, n, &rng, "grid 60x45");
        free(p);
        p = gen_rotated_grid(25, 3, 4, 1000000, 1000000, &n);
        run(&t, core, p, n, &rng, "rotated grid");
        free(p);
        p = gen_circle(1000000, 1000000, 5525, &n);
        run(&t, core, p, n, &rng, "circle");
        free(p);
        p = gen_thin_circle(&rng, 3000, 1000000, 1000000, 900000, 2, &n);
        run(&t, core, p, n, &rng, "thin circle");
        free(p);
        p = gen_clusters(&rng, 8, 400, 30, &n);
        run(&t, core, p, n, &rng, "clusters");
        free(p);
        p = gen_extremes(&rng, &n);
        run(&t, core, p, n, &rng, "extremes");
        free(p);
        gdt_core_destroy(core);
    }
    return gen_finish(&t, "test_gcd_flip");
}
