/* test_gcd_voronoi — Phase 1 of the gCD core against brute force.
 *
 * On many random small grids (including tie-heavy site patterns: lattices,
 * symmetric pairs, sites on circles, repeated sites) the device colouring
 * must equal standard flooding computed here by a priority queue with the
 * same key order, key(A, S) = (|A-S|^2, S.x, S.y, index(A)).  The Euclidean
 * colouring under that key is computed too: the corpus must contain grids
 * where the two differ (debris), or the recolouring is not exercised.  Runs
 * with and without row bands in the column pass.
 * Exit 77 without an OpenCL device. */
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>

#include "gen_degenerate.h"
#include "private/gcd_test.h"

typedef struct item {
    int64_t d2;
    uint32_t sx, sy, pix, site;
} item;

static int less(const item *a, const item *b)
{
    if (a->d2 != b->d2)
        return a->d2 < b->d2;
    if (a->sx != b->sx)
        return a->sx < b->sx;
    if (a->sy != b->sy)
        return a->sy < b->sy;
    return a->pix < b->pix;
}

typedef struct heap {
    item *a;
    size_t n, cap;
} heap;

static void push(heap *h, item it)
{
    if (h->n == h->cap) {
        h->cap = h->cap ? 2 * h->cap : 1024;
        h->a = realloc(h->a, h->cap * sizeof *h->a);
        if (h->a == NULL)
            abort();
    }
    size_t i = h->n++;
    while (i > 0 && less(&it, &h->a[(i - 1) / 2])) {
        h->a[i] = h->a[(i - 1) / 2];
        i = (i - 1) / 2;
    }
    h->a[i] = it;
}

static item pop(heap *h)
{
    item top = h->a[0], last = h->a[--h->n];
    size_t i = 0;
    for (;;) {
        size_t l = 2 * i + 1, m = i;
        const item *best = &last;
        if (l < h->n && less(&h->a[l], best))
            m = l, best = &h->a[l];
        if (l + 1 < h->n && less(&h->a[l + 1], best))
            m = l + 1;
        if (m == i)
            break;
        h->a[i] = h->a[m];
        i = m;
    }
    if (h->n > 0)
        h->a[i] = last;
    return top;
}

static item mk(uint32_t pix, uint32_t site, uint32_t W)
{
    item it;
    int64_t x = pix % W, y = pix / W, sx = site % W, sy = site / W;
    it.d2 = (x - sx) * (x - sx) + (y - sy) * (y - sy);
    it.sx = (uint32_t)sx;
    it.sy = (uint32_t)sy;
    it.pix = pix;
    it.site = site;
    return it;
}

/* Standard flooding (Cao, Edelsbrunner, Tan, Section 2). */
static void flood(const uint32_t *sites, size_t ns, uint32_t W, uint32_t H, uint32_t *col)
{
    heap h = {NULL, 0, 0};
    for (size_t i = 0; i < (size_t)W * H; i++)
        col[i] = UINT32_MAX;
    for (size_t i = 0; i < ns; i++)
        push(&h, mk(sites[i], sites[i], W));
    while (h.n > 0) {
        item it = pop(&h);
        if (col[it.pix] != UINT32_MAX)
            continue;
        col[it.pix] = it.site;
        int64_t x = it.pix % W, y = it.pix / W;
        for (int dy = -1; dy <= 1; dy++)
            for (int dx = -1; dx <= 1; dx++) {
                int64_t bx = x + dx, by = y + dy;
                if ((dx | dy) == 0 || bx < 0 || by < 0 || bx >= W || by >= H)
                    continue;
                push(&h, mk((uint32_t)(by * W + bx), it.site, W));
            }
    }
    free(h.a);
}

/* Euclidean colouring: least key over all sites. */
static void euclid(const uint32_t *sites, size_t ns, uint32_t W, uint32_t H, uint32_t *col)
{
    for (uint32_t p = 0; p < W * H; p++) {
        item best = mk(p, sites[0], W);
        for (size_t i = 1; i < ns; i++) {
            item it = mk(p, sites[i], W);
            if (less(&it, &best))
                best = it;
        }
        col[p] = best.site;
    }
}

typedef struct stats {
    int grids, with_debris;
    uint64_t debris_texels;
} stats;

static int run_case(tctx *t, gdt_core *core, uint32_t *sites, size_t ns, uint32_t W,
                    uint32_t H, const char *label, stats *s)
{
    size_t npix = (size_t)W * H;
    uint32_t *dev = malloc(npix * sizeof *dev), *fl = malloc(npix * sizeof *fl);
    uint32_t *eu = malloc(npix * sizeof *eu);
    gdt_error err;
    memset(&err, 0, sizeof err);
    if (dev == NULL || fl == NULL || eu == NULL)
        abort();
    if (gcd_test_voronoi(core, sites, ns, W, H, dev, &err) != GDT_OK) {
        CHECK(t, 0, "%s: %s", label, err.msg);
        free(dev), free(fl), free(eu);
        return -1;
    }
    /* Duplicated sites collapse: the reference takes the distinct texels. */
    flood(sites, ns, W, H, fl);
    if (npix * ns <= 4000000)
        euclid(sites, ns, W, H, eu);
    else
        memcpy(eu, fl, npix * sizeof *eu);
    size_t bad = 0, first = 0, diff = 0;
    for (size_t i = 0; i < npix; i++) {
        if (dev[i] != fl[i] && bad++ == 0)
            first = i;
        diff += eu[i] != fl[i];
    }
    CHECK(t, bad == 0, "%s (%ux%u, %zu sites): %zu texels differ from standard flooding, first "
          "(%zu,%zu): device site (%u,%u), flooding (%u,%u)",
          label, W, H, ns, bad, first % W, first / W, dev[first] % W, dev[first] / W,
          fl[first] % W, fl[first] / W);
    s->grids++;
    s->with_debris += diff > 0;
    s->debris_texels += diff;
    free(dev), free(fl), free(eu);
    return bad == 0 ? 0 : -1;
}

int main(void)
{
    tctx t = {0, 0};
    gdt_core *core = NULL;
    gdt_core_opts o;
    gdt_error err;
    gen_rng rng;
    stats s = {0, 0, 0};
    uint32_t *sites = malloc(70000 * sizeof *sites);

    memset(&o, 0, sizeof o);
    memset(&err, 0, sizeof err);
    o.device = getenv("GDT_TEST_DEVICE");
    if (gdt_core_create(&core, &o, &err) != GDT_OK) {
        gdt_error_print(&err, stderr);
        free(sites);
        return err.status == GDT_EDEVICE && err.code == 5101 ? 77 : 1;
    }
    gen_seed(&rng, 20240611);
    for (int iter = 0; iter < 700; iter++) {
        uint32_t W = (uint32_t)gen_range(&rng, 1, 48), H = (uint32_t)gen_range(&rng, 1, 48);
        size_t ns = 0, maxs = (size_t)W * H;
        int kind = iter % 7;
        char label[64];
        gcd_test_set_bands(core, (iter & 1) ? 1 : (unsigned)gen_range(&rng, 2, 7));
        if (kind == 0) { /* sparse random */
            size_t k = (size_t)gen_range(&rng, 1, 1 + (int64_t)maxs / 8);
            for (size_t i = 0; i < k; i++)
                sites[ns++] = (uint32_t)gen_below(&rng, maxs);
        } else if (kind == 1) { /* dense random with repeats */
            size_t k = (size_t)gen_range(&rng, 1, (int64_t)maxs);
            for (size_t i = 0; i < k; i++)
                sites[ns++] = (uint32_t)gen_below(&rng, maxs);
        } else if (kind == 2) { /* lattice: many equidistant ties */
            uint32_t a = (uint32_t)gen_range(&rng, 1, 6), b = (uint32_t)gen_range(&rng, 1, 6);
            uint32_t ox = (uint32_t)gen_below(&rng, a), oy = (uint32_t)gen_below(&rng, b);
            for (uint32_t y = oy; y < H; y += b)
                for (uint32_t x = ox; x < W; x += a)
                    sites[ns++] = y * W + x;
        } else if (kind == 3) { /* mirror-symmetric pairs */
            size_t k = (size_t)gen_range(&rng, 1, 12);
            for (size_t i = 0; i < k; i++) {
                uint32_t x = (uint32_t)gen_below(&rng, W), y = (uint32_t)gen_below(&rng, H);
                sites[ns++] = y * W + x;
                sites[ns++] = y * W + (W - 1 - x);
                sites[ns++] = (H - 1 - y) * W + x;
            }
        } else if (kind == 4) { /* sites on a circle (sharp Voronoi corners) */
            int64_t cx = gen_range(&rng, 0, W - 1), cy = gen_range(&rng, 0, H - 1);
            int64_t r2 = gen_range(&rng, 1, (int64_t)(W * W + H * H) / 4 + 1);
            for (uint32_t y = 0; y < H; y++)
                for (uint32_t x = 0; x < W; x++) {
                    int64_t d = ((int64_t)x - cx) * ((int64_t)x - cx) +
                                ((int64_t)y - cy) * ((int64_t)y - cy);
                    if (d >= r2 - (int64_t)W / 4 && d <= r2 + 1)
                        sites[ns++] = y * W + x;
                }
            if (ns == 0)
                sites[ns++] = (uint32_t)(cy * W + cx);
        } else if (kind == 6) { /* nearly collinear sites: acute Voronoi corners */
            int64_t x0 = gen_range(&rng, 0, W - 1), y0 = gen_range(&rng, 0, H - 1);
            int64_t dx = gen_range(&rng, -3, 3), dy = gen_range(&rng, -3, 3);
            for (int i = 0; i < 12; i++) {
                int64_t x = x0 + i * dx + gen_range(&rng, -1, 1);
                int64_t y = y0 + i * dy + gen_range(&rng, -1, 1);
                if (x >= 0 && y >= 0 && x < W && y < H)
                    sites[ns++] = (uint32_t)(y * W + x);
            }
        } else { /* few sites far apart: long thin regions */
            size_t k = (size_t)gen_range(&rng, 2, 5);
            for (size_t i = 0; i < k; i++)
                sites[ns++] = (uint32_t)gen_below(&rng, maxs);
        }
        if (ns == 0)
            sites[ns++] = (uint32_t)gen_below(&rng, maxs);
        snprintf(label, sizeof label, "grid %d (kind %d)", iter, kind);
        run_case(&t, core, sites, ns, W, H, label, &s);
    }
    /* A few larger grids. */
    for (int iter = 0; iter < 6; iter++) {
        uint32_t W = 256, H = iter & 1 ? 256 : 96;
        size_t ns = iter < 3 ? 3000 : 400;
        char label[64];
        gcd_test_set_bands(core, iter & 1 ? 1 : 5);
        for (size_t i = 0; i < ns; i++) {
            /* sites on a coarse lattice with jitter: many ties */
            uint32_t x = (uint32_t)(gen_below(&rng, W / 4) * 4 + gen_below(&rng, 2));
            uint32_t y = (uint32_t)(gen_below(&rng, H / 4) * 4 + gen_below(&rng, 2));
            sites[i] = y * W + x;
        }
        snprintf(label, sizeof label, "large grid %d", iter);
        run_case(&t, core, sites, ns, W, H, label, &s);
    }
    fprintf(stderr, "%d grids, %d with debris (%" PRIu64 " debris texels in all)\n", s.grids,
            s.with_debris, s.debris_texels);
    CHECK(&t, s.with_debris >= 10, "only %d grids had debris: the recolouring is not exercised",
          s.with_debris);
    gdt_core_destroy(core);
    free(sites);
    return gen_finish(&t, "test_gcd_voronoi");
}
