/* test_trim — --max-edge and --concavity (merge/gdt_trim.h) against a
 * brute-force peel, and the tiled computation (tiles' candidates and open
 * edges, merge faces, one graph) against the whole-mesh one.
 *
 * The brute force repeats, until nothing changes: drop every kept face that
 * has an edge longer than L with no kept face on its other side (a hull
 * edge, or the far face already dropped).  Faces by vertices, adjacency by
 * a quadratic search: small meshes only. */
#include <stdlib.h>
#include <string.h>

#include "gdt_check.h"
#include "gdt_mesh.h"
#include "gdt_reference.h"
#include "gdt_trim.h"

static gdt_checks C;

/* The face that has the directed edge b -> a (the other side of a -> b of
 * face f), or -1. */
static long other_side(const uint32_t *tri, size_t nf, uint32_t a, uint32_t b)
{
    for (size_t g = 0; g < nf; g++)
        for (int i = 0; i < 3; i++)
            if (tri[3 * g + i] == b && tri[3 * g + (i + 1) % 3] == a)
                return (long)g;
    return -1;
}

static void brute(const gdt_trim_rule *r, const uint32_t *tri, size_t nf, const gdt_ipt *p,
                  uint8_t *keep)
{
    int changed = 1;
    for (size_t f = 0; f < nf; f++)
        keep[f] = 1;
    while (r->concavity > 0 && changed) {
        changed = 0;
        for (size_t f = 0; f < nf; f++) {
            if (!keep[f])
                continue;
            for (int i = 0; i < 3; i++) {
                uint32_t a = tri[3 * f + i], b = tri[3 * f + (i + 1) % 3];
                long g;
                if (!gdt_trim_longer(r, r->concavity, p[b].x - p[a].x, p[b].y - p[a].y))
                    continue;
                g = other_side(tri, nf, a, b);
                if (g < 0 || !keep[g]) {
                    keep[f] = 0;
                    changed = 1;
                    break;
                }
            }
        }
    }
    for (size_t f = 0; r->max_edge > 0 && f < nf; f++)
        if (gdt_trim_cut(r, p[tri[3 * f]], p[tri[3 * f + 1]], p[tri[3 * f + 2]]))
            keep[f] = 0;
}

/* Random points with empty discs (voids) of random sizes. */
static size_t make_points(gdt_ipt *p, size_t n, uint64_t *seed, int64_t side, int holes)
{
    int64_t hx[8], hy[8], hr[8];
    size_t k = 0;
    for (int h = 0; h < holes; h++) {
        hx[h] = (int64_t)(gdt_splitmix64(seed) % (uint64_t)side);
        hy[h] = (int64_t)(gdt_splitmix64(seed) % (uint64_t)side);
        hr[h] = side / 12 + (int64_t)(gdt_splitmix64(seed) % (uint64_t)(side / 6));
    }
    while (k < n) {
        int64_t x = (int64_t)(gdt_splitmix64(seed) % (uint64_t)side);
        int64_t y = (int64_t)(gdt_splitmix64(seed) % (uint64_t)side);
        int in_hole = 0, dup = 0;
        for (int h = 0; h < holes; h++)
            in_hole |= (x - hx[h]) * (x - hx[h]) + (y - hy[h]) * (y - hy[h]) < hr[h] * hr[h];
        for (size_t i = 0; i < k && !dup; i++)
            dup = p[i].x == x && p[i].y == y;
        if (in_hole || dup)
            continue;
        p[k].x = x;
        p[k].y = y;
        k++;
    }
    return k;
}

/* The tiled computation: faces whose three vertices lie in one vertical
 * strip of the points' x range are that strip's "certified" faces; the
 * others are merge faces.  Vertex ids are renumbered so each strip's
 * vertices are consecutive (as tiles' are), output index = new id. */
static void tiled(const gdt_trim_rule *r, const uint32_t *tri, size_t nf, const gdt_ipt *p,
                  size_t n, int strips, int64_t side, uint8_t *keep)
{
    uint32_t *id = malloc(n * sizeof *id), *inv = malloc(n * sizeof *inv);
    uint64_t *base = calloc((size_t)strips + 1, sizeof *base);
    int *strip = malloc(n * sizeof *strip);
    uint32_t *tf = malloc(3 * nf * sizeof *tf);
    size_t *tfi = malloc(nf * sizeof *tfi);
    gdt_ipt *tp = malloc(n * sizeof *tp);
    uint64_t *mf = malloc(3 * nf * sizeof *mf);
    gdt_ipt *mxy = malloc(3 * nf * sizeof *mxy);
    size_t *mfi = malloc(nf * sizeof *mfi), nm = 0;
    gdt_trim_graph *g = NULL;
    gdt_trim_tile *tt = calloc((size_t)strips, sizeof *tt);
    gdt_error err;
    gdt_status st;

    gdt_error_clear(&err);
    for (size_t i = 0; i < n; i++) {
        strip[i] = (int)(p[i].x * strips / side);
        base[strip[i] + 1]++;
    }
    for (int s = 0; s < strips; s++)
        base[s + 1] += base[s];
    {
        uint64_t *next = malloc((size_t)strips * sizeof *next);
        memcpy(next, base, (size_t)strips * sizeof *next);
        for (size_t i = 0; i < n; i++) {
            id[i] = (uint32_t)next[strip[i]]++;
            inv[id[i]] = (uint32_t)i;
        }
        free(next);
    }
    for (size_t f = 0; f < nf; f++)
        keep[f] = 1;
    st = gdt_trim_graph_create(&g, r, &err);
    GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
    for (int s = 0; s < strips && st == GDT_OK; s++) {
        size_t m = 0, np = (size_t)(base[s + 1] - base[s]);
        for (size_t q = 0; q < np; q++)
            tp[q] = p[inv[base[s] + q]];
        for (size_t f = 0; f < nf; f++) {
            const uint32_t *v = tri + 3 * f;
            if (strip[v[0]] != s || strip[v[1]] != s || strip[v[2]] != s)
                continue;
            for (int i = 0; i < 3; i++)
                tf[3 * m + i] = (uint32_t)(id[v[i]] - base[s]);
            tfi[m++] = f;
        }
        st = gdt_trim_tile_run(&tt[s], r, tf, m, tp, base[s], &err);
        GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
        if (st == GDT_OK)
            st = gdt_trim_graph_add_tile(g, (uint64_t)s, tt[s].open, tt[s].nopen, &err);
        GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
        for (size_t i = 0; i < tt[s].ncut; i++)
            keep[tfi[tt[s].cut[i]]] = 0;
        /* the candidates' verdicts come after resolve: keep the face map */
        for (size_t i = 0; i < tt[s].ncand; i++)
            tt[s].cand[2 * i] = (uint32_t)tfi[tt[s].cand[2 * i]];
    }
    for (size_t f = 0; f < nf; f++) {
        const uint32_t *v = tri + 3 * f;
        if (strip[v[0]] == strip[v[1]] && strip[v[1]] == strip[v[2]])
            continue;
        for (int i = 0; i < 3; i++) {
            mf[3 * nm + i] = id[v[i]];
            mxy[3 * nm + i] = p[v[i]];
        }
        mfi[nm++] = f;
    }
    /* merge faces come in two batches, as rounds do */
    if (st == GDT_OK)
        st = gdt_trim_graph_add_faces(g, mf, mxy, nm / 2, &err);
    if (st == GDT_OK)
        st = gdt_trim_graph_add_faces(g, mf + 3 * (nm / 2), mxy + 3 * (nm / 2), nm - nm / 2,
                                      &err);
    if (st == GDT_OK)
        st = gdt_trim_graph_resolve(g, &err);
    GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
    for (int s = 0; s < strips && st == GDT_OK; s++)
        for (size_t i = 0; i < tt[s].ncand; i++)
            if (gdt_trim_graph_tile_dropped(g, (uint64_t)s, tt[s].cand[2 * i + 1]))
                keep[tt[s].cand[2 * i]] = 0;
    for (size_t i = 0; i < nm && st == GDT_OK; i++)
        if (gdt_trim_graph_face_dropped(g, i))
            keep[mfi[i]] = 0;
    for (int s = 0; s < strips; s++)
        gdt_trim_tile_free(&tt[s]);
    free(tt);
    gdt_trim_graph_destroy(g);
    free(id);
    free(inv);
    free(base);
    free(strip);
    free(tf);
    free(tfi);
    free(tp);
    free(mf);
    free(mxy);
    free(mfi);
}

static void one_case(uint64_t seed, size_t n, int holes, double lm, double lc, int strips)
{
    int64_t side = 1000;
    const uint64_t seed0 = seed;
    gdt_ipt *p = malloc(n * sizeof *p);
    gdt_mesh m;
    gdt_error err;
    gdt_trim_rule r = {lm, lc, 0.01, 0.01};
    uint8_t *k1, *k2, *k3;
    uint32_t *tri;
    size_t nf, diff12 = 0, diff13 = 0, dropped = 0;
    gdt_trim_counts cnt;
    gdt_status st;

    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    n = make_points(p, n, &seed, side, holes);
    st = gdt_reference_triangulate(NULL, p, n, &m, &err);
    GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
    nf = m.ntris;
    tri = malloc(3 * nf * sizeof *tri + 1);
    k1 = malloc(nf + 1);
    k2 = malloc(nf + 1);
    k3 = malloc(nf + 1);
    for (size_t i = 0; i < 3 * nf; i++)
        tri[i] = (uint32_t)m.tri[i];
    st = gdt_trim_mesh(&r, tri, nf, p, k1, &cnt, &err);
    GDT_CHECK(&C, st == GDT_OK, "%s", err.msg);
    brute(&r, tri, nf, p, k2);
    tiled(&r, tri, nf, p, n, strips, side, k3);
    for (size_t f = 0; f < nf; f++) {
        diff12 += k1[f] != k2[f];
        diff13 += k1[f] != k3[f];
        dropped += !k2[f];
    }
    GDT_CHECK(&C, diff12 == 0, "seed %llu L %g/%g: %zu of %zu faces differ from brute force",
              (unsigned long long)seed0, lm, lc, diff12, nf);
    GDT_CHECK(&C, diff13 == 0, "seed %llu L %g/%g, %d strips: %zu faces differ from whole mesh",
              (unsigned long long)seed0, lm, lc, strips, diff13);
    GDT_CHECK(&C, cnt.dropped == dropped && cnt.faces == nf, "counts %llu of %llu, want %zu",
              (unsigned long long)cnt.dropped, (unsigned long long)cnt.faces, dropped);
    free(tri);
    free(k1);
    free(k2);
    free(k3);
    free(p);
    gdt_mesh_free(&m);
}

int main(void)
{
    /* lattice 0.01 on a 1000-step square: 10 units wide; mean spacing of
     * 400 points about 0.5 */
    static const double L[] = {0, 0.3, 0.6, 1.0, 2.0, 100.0};
    int cases = 0, nonempty = 0;
    for (uint64_t seed = 1; seed <= 12; seed++) {
        for (size_t a = 0; a < sizeof L / sizeof L[0]; a++) {
            for (size_t b = 0; b < sizeof L / sizeof L[0]; b++) {
                if (L[a] == 0 && L[b] == 0)
                    continue;
                one_case(seed, 300 + 20 * seed, (int)(seed % 5), L[a], L[b],
                         1 + (int)((seed + a + b) % 5));
                cases++;
            }
        }
    }
    /* the rules must actually drop faces in these cases: a peel through a
     * void reaching the hull, and nothing at a huge L */
    {
        gdt_ipt p[400];
        uint64_t seed = 7;
        size_t n = make_points(p, 400, &seed, 1000, 3);
        gdt_mesh m;
        gdt_error err;
        gdt_trim_rule r = {0, 0.6, 0.01, 0.01};
        uint8_t keep[2000];
        uint32_t tri[6000];
        gdt_trim_counts cnt;
        gdt_mesh_init(&m);
        gdt_error_clear(&err);
        GDT_CHECK(&C, gdt_reference_triangulate(NULL, p, n, &m, &err) == GDT_OK, "%s", err.msg);
        for (size_t i = 0; i < 3 * m.ntris; i++)
            tri[i] = (uint32_t)m.tri[i];
        GDT_CHECK(&C, gdt_trim_mesh(&r, tri, m.ntris, p, keep, &cnt, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&C, cnt.peeled > 0 && cnt.peeled < cnt.faces, "peeled %llu of %llu",
                  (unsigned long long)cnt.peeled, (unsigned long long)cnt.faces);
        nonempty += cnt.peeled > 0;
        r.concavity = 100;
        GDT_CHECK(&C, gdt_trim_mesh(&r, tri, m.ntris, p, keep, &cnt, &err) == GDT_OK, "%s",
                  err.msg);
        GDT_CHECK(&C, cnt.dropped == 0, "dropped %llu at L 100", (unsigned long long)cnt.dropped);
        gdt_mesh_free(&m);
    }
    GDT_CHECK(&C, cases > 0 && nonempty == 1, "%d cases", cases);
    return gdt_check_finish(&C, "test_trim");
}
