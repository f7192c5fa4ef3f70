/* test_gcd_phase2 — Phase 2 of the gCD core (dual, hull completion, fake
 * boundary, links) before any flip or shift.
 *
 * For each point set and grid size:
 *  - the triangles without a fake vertex, with the kept points at their
 *    texel corners, form a valid triangulation of their convex hull:
 *    gdt_check_mesh passes (orientation, links, convex hull boundary with
 *    collinear hull points, Euler, every kept point used, connectivity);
 *  - the whole triangulation with the 12 fakes is valid in the symbolic
 *    plane: every triangle counter-clockwise (gcd_orient), every link
 *    mutual, exactly the 12 fake-fake edges on the outer boundary, and
 *    T = 2 (kept + 12) - 14;
 *  - the dual triangles equal a CPU dualisation of the device's Voronoi
 *    colouring (same order), and the links equal gdt_mesh_link's;
 *  - the slots reserved for the missing points (two each) are dead and
 *    nothing links to them; they are dropped before the checks above.
 * Exit 77 without an OpenCL device. */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "gcd_geom.clh"
#include "gen_degenerate.h"
#include "private/gcd_test.h"

#define NF GCD_NFAKE

static gcd_spt spt(const gdt_mesh *m, size_t n, int64_t cx, int64_t cy, int32_t v)
{
    if ((size_t)v >= n && (size_t)v < n + NF)
        return gcd_spt_fake(v - (int32_t)n);
    return gcd_spt_real(m->pts[v].x, m->pts[v].y, cx, cy);
}

/* CPU reference of p2_count/p2_write for one corner. */
static int corner(const uint32_t *col, uint32_t W, uint32_t x, uint32_t y, uint32_t *t)
{
    uint32_t a = col[y * W + x], b = col[y * W + x + 1], c = col[(y + 1) * W + x + 1],
             d = col[(y + 1) * W + x];
    int eq;
    if (a == c || b == d)
        return 0;
    eq = (a == b) + (b == c) + (c == d) + (d == a);
    if (eq == 0) {
        uint32_t v[6] = {a, b, c, a, c, d};
        memcpy(t, v, sizeof v);
        return 2;
    }
    if (eq > 1)
        return 0;
    if (a == b)
        t[0] = a, t[1] = c, t[2] = d;
    else if (b == c)
        t[0] = a, t[1] = b, t[2] = d;
    else
        t[0] = a, t[1] = b, t[2] = c;
    return 1;
}

/* Drops the dead slots of m (tri[3t] < 0), keeping the order of the live
 * ones and renumbering the links; *ndead receives their number, *bad the
 * number of links that named a dead slot. */
static void strip_dead(gdt_mesh *m, size_t *ndead, size_t *bad)
{
    int32_t *newidx = malloc((m->ntris ? m->ntris : 1) * sizeof *newidx);
    size_t live = 0;
    *ndead = 0;
    *bad = 0;
    if (newidx == NULL)
        abort();
    for (size_t t = 0; t < m->ntris; t++)
        newidx[t] = m->tri[3 * t] < 0 ? -1 : (int32_t)live++;
    *ndead = m->ntris - live;
    for (size_t t = 0; t < m->ntris; t++) {
        if (newidx[t] < 0)
            continue;
        for (int i = 0; i < 3; i++) {
            int32_t o = m->opp[3 * t + (size_t)i];
            if (o >= 0 && newidx[gdt_opp_tri(o)] < 0) {
                (*bad)++;
                o = -1;
            } else if (o >= 0) {
                o = gdt_opp_pack(newidx[gdt_opp_tri(o)], gdt_opp_slot(o));
            }
            m->tri[3 * (size_t)newidx[t] + (size_t)i] = m->tri[3 * t + (size_t)i];
            m->opp[3 * (size_t)newidx[t] + (size_t)i] = o;
        }
    }
    m->ntris = live;
    free(newidx);
}

static void run(tctx *t, gdt_core *core, const gdt_ipt *pts, size_t n, int grid, const char *label)
{
    gdt_mesh all, real, ref;
    gdt_error err;
    gdt_core_stats st;
    int64_t centre[2];
    int32_t *map = NULL;
    uint32_t *sites = NULL, *colour = NULL;

    memset(&err, 0, sizeof err);
    memset(&st, 0, sizeof st);
    gdt_mesh_init(&all);
    gdt_mesh_init(&real);
    gdt_mesh_init(&ref);
    if (gcd_test_phase2(core, pts, n, grid, &all, centre, &st, &err) != GDT_OK) {
        CHECK(t, 0, "%s: %s", label, err.msg);
        goto done;
    }
    {
        size_t ndead = 0, deadlinks = 0;
        strip_dead(&all, &ndead, &deadlinks);
        CHECK(t, ndead == 2 * st.missing_phase1 && deadlinks == 0,
              "%s: %zu dead slots (%zu linked) for %" PRIu64 " missing points", label, ndead,
              deadlinks, st.missing_phase1);
    }
    size_t T = all.ntris, nv = all.nverts;
    int32_t nreal = (int32_t)n;

    /* Vertices: kept points, fakes, frame (one per border texel). */
    size_t nframe = nv - n - NF;
    map = malloc(nv * sizeof *map);
    for (size_t v = 0; v < nv; v++)
        map[v] = -1;
    for (size_t i = 0; i < 3 * T; i++)
        map[all.tri[i]] = 0;
    size_t kept = 0, used = 0;
    for (size_t v = 0; v < nv; v++) {
        if (map[v] != 0)
            continue;
        if (v < n)
            kept++;
        if (v < n || v >= n + NF)
            map[v] = (int32_t)used++;
    }
    CHECK(t, kept == st.kept, "%s: %zu points used, %" PRIu64 " kept points", label, kept,
          st.kept);
    CHECK(t, used == kept + nframe, "%s: %zu of %zu frame vertices used", label, used - kept,
          nframe);
    for (int k = 0; k < NF; k++) {
        CHECK(t, map[n + (size_t)k] == 0, "%s: fake %d unused", label, k);
        map[n + (size_t)k] = -2;
    }

    /* Whole triangulation in the symbolic plane. */
    size_t boundary = 0, bad_or = 0, bad_link = 0;
    for (size_t tr = 0; tr < T; tr++) {
        const int32_t *V = all.tri + 3 * tr;
        if (gcd_orient(spt(&all, n, centre[0], centre[1], V[0]), spt(&all, n, centre[0], centre[1], V[1]),
                       spt(&all, n, centre[0], centre[1], V[2])) <= 0 && bad_or++ == 0)
            fprintf(stderr, "%s: triangle %zu (%d %d %d) not counter-clockwise\n", label, tr, V[0],
                    V[1], V[2]);
        for (int i = 0; i < 3; i++) {
            int32_t o = all.opp[3 * tr + i];
            int32_t a = V[(i + 1) % 3], b = V[(i + 2) % 3];
            if (o < 0) {
                boundary++;
                if ((a < nreal || b < nreal) && bad_link++ == 0)
                    fprintf(stderr, "%s: edge %d-%d without neighbour\n", label, a, b);
                continue;
            }
            int32_t u = gdt_opp_tri(o);
            int j = gdt_opp_slot(o);
            const int32_t *U = all.tri + 3 * (size_t)u;
            if ((all.opp[3 * (size_t)u + j] != gdt_opp_pack((int32_t)tr, i) ||
                 U[(j + 1) % 3] != b || U[(j + 2) % 3] != a) &&
                bad_link++ == 0)
                fprintf(stderr, "%s: bad link at triangle %zu slot %d\n", label, tr, i);
        }
    }
    CHECK(t, bad_or == 0, "%s: %zu triangles not counter-clockwise", label, bad_or);
    CHECK(t, bad_link == 0, "%s: %zu bad links", label, bad_link);
    CHECK(t, boundary == NF, "%s: %zu boundary edges, expected %d", label, boundary, NF);
    CHECK(t, T == 2 * (used + NF) - NF - 2, "%s: %zu triangles for %zu vertices", label, T,
          used + NF);

    /* Links: the device's equal gdt_mesh_link's. */
    if (gdt_mesh_reserve(&ref, nv, T, 0, &err) == GDT_OK) {
        memcpy(ref.tri, all.tri, 3 * T * sizeof *ref.tri);
        memcpy(ref.pts, all.pts, nv * sizeof *ref.pts);
        ref.nverts = nv;
        ref.ntris = T;
        if (gdt_mesh_link(&ref, &err) == GDT_OK)
            CHECK(t, memcmp(ref.opp, all.opp, 3 * T * sizeof *ref.opp) == 0,
                  "%s: links differ from gdt_mesh_link", label);
        else
            CHECK(t, 0, "%s: gdt_mesh_link: %s", label, err.msg);
    }

    /* Without the fakes: a triangulation of the frame rectangle. */
    if (gdt_mesh_reserve(&real, used, T, 0, &err) == GDT_OK) {
        size_t nt = 0;
        for (size_t v = 0; v < nv; v++)
            if (map[v] >= 0)
                real.pts[map[v]] = all.pts[v];
        for (size_t tr = 0; tr < T; tr++) {
            const int32_t *V = all.tri + 3 * tr;
            if ((V[0] >= nreal && V[0] < nreal + NF) || (V[1] >= nreal && V[1] < nreal + NF) ||
                (V[2] >= nreal && V[2] < nreal + NF))
                continue;
            for (int i = 0; i < 3; i++)
                real.tri[3 * nt + i] = map[V[i]];
            nt++;
        }
        real.nverts = used;
        real.ntris = nt;
        if (gdt_mesh_link(&real, &err) != GDT_OK || gdt_check_mesh(NULL, &real, &err) != GDT_OK)
            CHECK(t, 0, "%s: real part after phase 2: %s", label, err.msg);
    }

    /* Dual triangles against a CPU dualisation of the device colouring. */
    if (st.dual_triangles > 0) {
        uint32_t W = st.grid_w, H = st.grid_h;
        size_t ns = 0, mism = 0;
        int32_t *owner = malloc((size_t)W * H * sizeof *owner);
        sites = malloc(nv * sizeof *sites);
        colour = malloc((size_t)W * H * sizeof *colour);
        for (size_t i = 0; i < (size_t)W * H; i++)
            owner[i] = -1;
        /* texel of kept point v from its corner position */
        int64_t xmin = INT64_MAX, ymin = INT64_MAX;
        for (size_t v = 0; v < n; v++) {
            if (pts[v].x < xmin)
                xmin = pts[v].x;
            if (pts[v].y < ymin)
                ymin = pts[v].y;
        }
        for (size_t v = 0; v < nv; v++) {
            if (map[v] < 0)
                continue;
            uint32_t tx = (uint32_t)((all.pts[v].x - xmin) / st.cell);
            uint32_t ty = (uint32_t)((all.pts[v].y - ymin) / st.cell);
            if (v >= n + NF)
                CHECK(t, ty * W + tx == gcd_frame_texel((gcd_u32)(v - n - NF), W, H),
                      "%s: frame vertex %zu not at its texel", label, v);
            sites[ns++] = ty * W + tx;
            owner[ty * W + tx] = (int32_t)v;
        }
        if (gcd_test_voronoi(core, sites, ns, W, H, colour, &err) != GDT_OK) {
            CHECK(t, 0, "%s: voronoi: %s", label, err.msg);
        } else {
            size_t o = 0;
            uint32_t tv[6];
            for (uint32_t y = 0; y + 1 < H; y++)
                for (uint32_t x = 0; x + 1 < W; x++) {
                    int k = corner(colour, W, x, y, tv);
                    for (int j = 0; j < 3 * k; j++)
                        if (o * 3 + (size_t)j >= 3 * T || all.tri[3 * o + (size_t)j] != owner[tv[j]])
                            mism++;
                    o += (size_t)k;
                }
            CHECK(t, o == st.dual_triangles && mism == 0,
                  "%s: CPU dual has %zu triangles (%zu mismatches), device %" PRIu64, label, o,
                  mism, st.dual_triangles);
        }
        free(owner);
    }
done:
    free(map);
    free(sites);
    free(colour);
    gdt_mesh_free(&all);
    gdt_mesh_free(&real);
    gdt_mesh_free(&ref);
}

int main(void)
{
    tctx t = {0, 0};
    gdt_core *core = NULL;
    gdt_core_opts o;
    gdt_error err;
    gen_rng rng;
    char label[128];

    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    o.full_grid = 1;
    if (gdt_core_create(&core, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    gen_seed(&rng, 7);
    /* random sets, many grid sizes (coarse grids: many missing points) */
    for (int it = 0; it < 120; it++) {
        size_t n0 = (size_t)gen_range(&rng, 1, it < 100 ? 300 : 20000), n;
        int64_t span = gen_range(&rng, 2, it % 3 == 0 ? 50 : 1000000);
        int grid = 1 << gen_range(&rng, 1, it < 100 ? 7 : 9);
        gdt_ipt *p = gen_uniform(&rng, n0, 1000, 1000 + span, &n);
        snprintf(label, sizeof label, "uniform #%d (%zu points, span %" PRId64 ", grid %d)", it, n,
                 span, grid);
        run(&t, core, p, n, grid, label);
        free(p);
    }
    /* the degenerate corpus */
    for (int g = 2; g <= 256; g *= 4) {
        size_t n;
        gdt_ipt *p;
        p = gen_grid(30, 20, 5, 7, 3, &n);
        snprintf(label, sizeof label, "grid 30x20 (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_rotated_grid(12, 3, 4, 5000, 5000, &n);
        snprintf(label, sizeof label, "rotated grid (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_circle(100000, 100000, 5525, &n);
        snprintf(label, sizeof label, "circle (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_thin_circle(&rng, 2000, 500000, 500000, 300000, 3, &n);
        snprintf(label, sizeof label, "thin circle (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_collinear(&rng, 50, 10, 20, 3, 7, 1000, &n);
        snprintf(label, sizeof label, "collinear (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_clusters(&rng, 5, 200, 40, &n);
        snprintf(label, sizeof label, "clusters (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
        p = gen_extremes(&rng, &n);
        snprintf(label, sizeof label, "extremes (grid %d)", g);
        run(&t, core, p, n, g, label);
        free(p);
    }
    for (size_t k = 1; k <= 4; k++) {
        gdt_ipt p[4] = {{10, 10}, {20, 11}, {15, 30}, {40, 40}};
        snprintf(label, sizeof label, "%zu points", k);
        run(&t, core, p, k, 64, label);
    }
    gdt_core_destroy(core);
    return gen_finish(&t, "test_gcd_phase2");
}
