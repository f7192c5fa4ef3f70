/* gcd_phase1.c — Phase 1: the exact digital Voronoi diagram of the grid
 * (kernels/gcd_pba.cl) and the debris recolouring of Algorithm A.1 (Qi, Cao
 * & Tan, Appendix A), which makes the colouring equal to standard flooding.
 *
 * design: the banding kernels give the Euclidean colouring under the fixed
 * key order of gcd_pba.cl.  p1_debris lists the texels with no closer
 * same-colour neighbour; each is the closest texel of one debris component
 * (a same-colour component without its site).  Usually there are none.
 * Otherwise, as in the paper, the few debris texels are recoloured on the
 * host: their components are grown through 3x3 neighbourhoods gathered on
 * the device, Algorithm A.1 runs a priority queue over them, and the new
 * colours are scattered back. */
#include "private/gcd_ctx.h"
#include "private/gcd_test.h"

#include <stdlib.h>
#include <string.h>

/* ---- host side of Algorithm A.1 ---- */

typedef struct dbr_set {
    uint32_t *pix;    /* debris texels, in discovery order */
    uint32_t *nb;     /* 9 colours per texel (PBA colouring), row-major 3x3 */
    uint32_t *col;    /* new colour (GCD_EMPTY while uncoloured) */
    size_t n, cap;
    uint32_t *hkey;   /* open addressing: texel -> index + 1 (0 = free) */
    uint32_t *hval;
    size_t hcap;
} dbr_set;

static void dbr_free(dbr_set *s)
{
    free(s->pix);
    free(s->nb);
    free(s->col);
    free(s->hkey);
    free(s->hval);
    memset(s, 0, sizeof *s);
}

static size_t dbr_hash(uint32_t p, size_t cap)
{
    return (size_t)((p * 0x9e3779b1u) ^ (p >> 15)) & (cap - 1);
}

/* Index of texel p in s, or -1. */
static long dbr_find(const dbr_set *s, uint32_t p)
{
    if (s->hcap == 0)
        return -1;
    for (size_t h = dbr_hash(p, s->hcap);; h = (h + 1) & (s->hcap - 1)) {
        if (s->hval[h] == 0)
            return -1;
        if (s->hkey[h] == p)
            return (long)s->hval[h] - 1;
    }
}

static int dbr_add(dbr_set *s, uint32_t p)
{
    if (2 * (s->n + 1) > s->hcap) {
        size_t nc = s->hcap ? 2 * s->hcap : 1024;
        uint32_t *k = calloc(nc, sizeof *k), *v = calloc(nc, sizeof *v);
        if (k == NULL || v == NULL) {
            free(k);
            free(v);
            return -1;
        }
        for (size_t i = 0; i < s->hcap; i++) {
            if (s->hval[i] == 0)
                continue;
            size_t h = dbr_hash(s->hkey[i], nc);
            while (v[h] != 0)
                h = (h + 1) & (nc - 1);
            k[h] = s->hkey[i];
            v[h] = s->hval[i];
        }
        free(s->hkey);
        free(s->hval);
        s->hkey = k;
        s->hval = v;
        s->hcap = nc;
    }
    if (s->n == s->cap) {
        size_t nc = s->cap ? 2 * s->cap : 256;
        uint32_t *a = realloc(s->pix, nc * sizeof *a);
        if (a == NULL)
            return -1;
        s->pix = a;
        a = realloc(s->nb, 9 * nc * sizeof *a);
        if (a == NULL)
            return -1;
        s->nb = a;
        a = realloc(s->col, nc * sizeof *a);
        if (a == NULL)
            return -1;
        s->col = a;
        s->cap = nc;
    }
    size_t h = dbr_hash(p, s->hcap);
    while (s->hval[h] != 0)
        h = (h + 1) & (s->hcap - 1);
    s->hkey[h] = p;
    s->hval[h] = (uint32_t)(s->n + 1);
    s->pix[s->n] = p;
    s->col[s->n] = GCD_EMPTY;
    s->n++;
    return 0;
}

/* key(A, S) of gcd_pba.cl as a comparable tuple. */
typedef struct dbr_item {
    int64_t d2;
    uint32_t sx, sy, pix, colour;
} dbr_item;

static int item_less(const dbr_item *a, const dbr_item *b)
{
    if (a->d2 != b->d2)
        return a->d2 < b->d2;
    if (a->sx != b->sx)
        return a->sx < b->sx;
    if (a->sy != b->sy)
        return a->sy < b->sy;
    return a->pix < b->pix;
}

typedef struct dbr_heap {
    dbr_item *a;
    size_t n, cap;
} dbr_heap;

static int heap_push(dbr_heap *h, dbr_item it)
{
    if (h->n == h->cap) {
        size_t nc = h->cap ? 2 * h->cap : 256;
        dbr_item *g = realloc(h->a, nc * sizeof *g);
        if (g == NULL)
            return -1;
        h->a = g;
        h->cap = nc;
    }
    size_t i = h->n++;
    while (i > 0) {
        size_t p = (i - 1) / 2;
        if (!item_less(&it, &h->a[p]))
            break;
        h->a[i] = h->a[p];
        i = p;
    }
    h->a[i] = it;
    return 0;
}

static dbr_item heap_pop(dbr_heap *h)
{
    dbr_item top = h->a[0], last = h->a[--h->n];
    size_t i = 0;
    for (;;) {
        size_t l = 2 * i + 1, r = l + 1, m = i;
        const dbr_item *best = &last;
        if (l < h->n && item_less(&h->a[l], best))
            m = l, best = &h->a[l];
        if (r < h->n && item_less(&h->a[r], best))
            m = r;
        if (m == i)
            break;
        h->a[i] = h->a[m];
        i = m;
    }
    if (h->n > 0)
        h->a[i] = last;
    return top;
}

static dbr_item make_item(uint32_t pix, uint32_t colour, uint32_t W)
{
    dbr_item it;
    int64_t x = pix % W, y = pix / W, sx = colour % W, sy = colour / W;
    it.d2 = (x - sx) * (x - sx) + (y - sy) * (y - sy);
    it.sx = (uint32_t)sx;
    it.sy = (uint32_t)sy;
    it.pix = pix;
    it.colour = colour;
    return it;
}

/* Neighbour k (0..8, row-major 3x3 from (-1,-1)) of texel p, or GCD_EMPTY
 * outside the grid. */
static uint32_t nb_pixel(uint32_t p, int k, uint32_t W, uint32_t H)
{
    int64_t x = p % W + (k % 3) - 1, y = p / W + (k / 3) - 1;
    if (x < 0 || y < 0 || x >= (int64_t)W || y >= (int64_t)H)
        return GCD_EMPTY;
    return (uint32_t)(y * (int64_t)W + x);
}

static int cmp_u32(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return (x > y) - (x < y);
}

/* Gathers the 3x3 colours of s->pix[from..s->n) into s->nb. */
static gdt_status gather(gdt_core *c, gcd_run *r, dbr_set *s, size_t from, gdt_error *err)
{
    size_t m = s->n - from;
    if (m == 0)
        return GDT_OK;
    if (gcd_buf_need(c, &c->d_aux, 4 * m, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux2, 36 * m, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux.b, 0, s->pix + from, 4 * m, err) != GDT_OK ||
        gcd_args(c->k.p1_gather, err, "buubub", GCD_COLOUR(c), r->W, r->H, &c->d_aux,
                 (unsigned)m, &c->d_aux2) != GDT_OK ||
        gcd_launch(c, c->k.p1_gather, m, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_aux2.b, 0, s->nb + 9 * from, 36 * m, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

/* Debris recolouring (Algorithm A.1) given the list of debris seeds. */
static gdt_status recolour(gdt_core *c, gcd_run *r, uint32_t *seeds, size_t nseeds,
                           gdt_error *err)
{
    dbr_set s;
    dbr_heap h;
    size_t done = 0;
    uint32_t *cols = NULL;
    gdt_status st = GDT_OK;

    memset(&s, 0, sizeof s);
    memset(&h, 0, sizeof h);
    qsort(seeds, nseeds, sizeof *seeds, cmp_u32);
    for (size_t i = 0; i < nseeds; i++) {
        if (dbr_add(&s, seeds[i]) != 0)
            goto oom;
    }
    /* Grow every debris component through same-colour 8-neighbours. */
    while (done < s.n) {
        size_t from = done, to = s.n;
        st = gather(c, r, &s, from, err);
        if (st != GDT_OK)
            goto fail;
        for (size_t i = from; i < to; i++) {
            uint32_t own = s.nb[9 * i + 4];
            for (int k = 0; k < 9; k++) {
                uint32_t q = nb_pixel(s.pix[i], k, r->W, r->H);
                if (k == 4 || q == GCD_EMPTY || s.nb[9 * i + k] != own || dbr_find(&s, q) >= 0)
                    continue;
                if (dbr_add(&s, q) != 0)
                    goto oom;
            }
        }
        done = to;
    }
    /* Algorithm A.1 lines 3-13. */
    for (size_t i = 0; i < s.n; i++) {
        dbr_item a_self;
        for (int k = 0; k < 9; k++) {
            uint32_t q = nb_pixel(s.pix[i], k, r->W, r->H);
            uint32_t col = s.nb[9 * i + k];
            if (k == 4 || q == GCD_EMPTY || col == GCD_EMPTY || dbr_find(&s, q) >= 0)
                continue;
            dbr_item b = make_item(q, col, r->W);
            a_self = make_item(s.pix[i], col, r->W);
            if (item_less(&b, &a_self) && heap_push(&h, a_self) != 0)
                goto oom;
        }
    }
    while (h.n > 0) {
        dbr_item it = heap_pop(&h);
        long ia = dbr_find(&s, it.pix);
        if (s.col[ia] != GCD_EMPTY)
            continue;
        s.col[ia] = it.colour;
        for (int k = 0; k < 9; k++) {
            uint32_t q = nb_pixel(it.pix, k, r->W, r->H);
            long iq;
            if (k == 4 || q == GCD_EMPTY || (iq = dbr_find(&s, q)) < 0 || s.col[iq] != GCD_EMPTY)
                continue;
            dbr_item cq = make_item(q, it.colour, r->W);
            if (item_less(&it, &cq) && heap_push(&h, cq) != 0)
                goto oom;
        }
    }
    for (size_t i = 0; i < s.n; i++) {
        if (s.col[i] == GCD_EMPTY) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7611,
                               "debris recolouring left texel %u uncoloured (%zu debris texels)",
                               s.pix[i], s.n);
            goto fail;
        }
    }
    if (gcd_buf_need(c, &c->d_aux, 4 * s.n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux2, 4 * s.n, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux.b, 0, s.pix, 4 * s.n, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux2.b, 0, s.col, 4 * s.n, err) != GDT_OK ||
        gcd_args(c->k.p1_scatter, err, "bbbu", GCD_COLOUR(c), &c->d_aux, &c->d_aux2,
                 (unsigned)s.n) != GDT_OK ||
        gcd_launch(c, c->k.p1_scatter, s.n, err) != GDT_OK) {
        st = err->status;
        goto fail;
    }
    if (r->st != NULL)
        r->st->debris_texels += s.n;
    goto fail;
oom:
    st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory in the debris recolouring");
fail:
    free(cols);
    free(h.a);
    dbr_free(&s);
    return st;
}

/* d_seed (W x H, GCD_EMPTY or point index) -> d_colour: the standard
 * flooding colouring (texel index of the site of every texel). */
gdt_status gcd_voronoi_from_seeds(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t npix = (size_t)r->W * r->H;
    unsigned bands = c->bands, strip = c->strip;
    size_t nstrips = (r->W + strip - 1) / strip;
    uint32_t ndebris = 0;
    uint32_t *seeds = NULL;
    gdt_status st;

    if (bands > r->H)
        bands = r->H;
    if (bands < 1)
        bands = 1;
    if (gcd_buf_need(c, GCD_NEAR(c), 4 * npix, err) != GDT_OK ||
        gcd_buf_need(c, GCD_COLOUR(c), 4 * npix, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_band_lo, 4 * (size_t)bands * r->W, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_band_hi, 4 * (size_t)bands * r->W, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_band_below, 4 * (size_t)bands * r->W, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_band_above, 4 * (size_t)bands * r->W, err) != GDT_OK)
        return err->status;
    if (bands == 1) {
        if (gcd_fill(c, &c->d_band_below, r->W, GCD_EMPTY, err) != GDT_OK ||
            gcd_fill(c, &c->d_band_above, r->W, GCD_EMPTY, err) != GDT_OK)
            return err->status;
    } else {
        if (gcd_args(c->k.p1_cols_band, err, "buuubb", &c->d_seed, r->W, r->H, bands,
                     &c->d_band_lo, &c->d_band_hi) != GDT_OK ||
            gcd_launch_wg(c, c->k.p1_cols_band, nstrips * bands, c->small_wg, err) != GDT_OK ||
            gcd_args(c->k.p1_cols_link, err, "uubbbb", r->W, bands, &c->d_band_lo,
                     &c->d_band_hi, &c->d_band_below, &c->d_band_above) != GDT_OK ||
            gcd_launch(c, c->k.p1_cols_link, r->W, err) != GDT_OK)
            return err->status;
    }
    if (gcd_args(c->k.p1_cols, err, "buuubbb", &c->d_seed, r->W, r->H, bands, &c->d_band_below,
                 &c->d_band_above, GCD_NEAR(c)) != GDT_OK ||
        gcd_launch_wg(c, c->k.p1_cols, nstrips * bands, c->small_wg, err) != GDT_OK ||
        gcd_args(c->k.p1_rows, err, "buub", GCD_NEAR(c), r->W, r->H, GCD_COLOUR(c)) != GDT_OK ||
        gcd_launch_wg(c, c->k.p1_rows, r->H, c->small_wg, err) != GDT_OK)
        return err->status;

    /* Debris seeds; the list capacity grows until it holds them all. */
    for (uint32_t cap = 4096;; cap = ndebris) {
        if (gcd_buf_need(c, &c->d_list2, 4 * (size_t)cap, err) != GDT_OK ||
            gcd_fill(c, &c->d_small, 1, 0, err) != GDT_OK ||
            gcd_args(c->k.p1_debris, err, "buubub", GCD_COLOUR(c), r->W, r->H, &c->d_list2, cap,
                     &c->d_small) != GDT_OK ||
            gcd_launch_wg(c, c->k.p1_debris, r->H, c->small_wg, err) != GDT_OK ||
            gcd_read_u32(c, &c->d_small, 0, &ndebris, err) != GDT_OK)
            return err->status;
        if (ndebris <= cap)
            break;
    }
    if (ndebris == 0)
        return GDT_OK;
    seeds = malloc(ndebris * sizeof *seeds);
    if (seeds == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    st = gdt_ocl_read(c->ocl, c->d_list2.b, 0, seeds, 4 * (size_t)ndebris, err);
    if (st == GDT_OK)
        st = recolour(c, r, seeds, ndebris, err);
    free(seeds);
    return st;
}

gdt_status gcd_phase1(gdt_core *c, gcd_run *r, gdt_error *err)
{
    size_t npix = (size_t)r->W * r->H;
    size_t nmiss = 0;
    uint32_t kept = 0;

    /* texels of the input points; the lowest index owns a shared texel;
     * border texels belong to the frame */
    if (gcd_buf_need(c, &c->d_seed, 4 * npix, err) != GDT_OK ||
        gcd_buf_need(c, GCD_TEXEL_IN(c), 4 * r->n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_texel, 4 * r->n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_pts, 8 * r->n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_int2in, 4 * r->n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_flags, 4 * (r->n > npix ? r->n : npix), err) != GDT_OK ||
        gcd_fill(c, &c->d_seed, npix, GCD_EMPTY, err) != GDT_OK ||
        gcd_args(c->k.p1_splat, err, "buiiiubb", GCD_PTS_IN(c), (unsigned)r->n, (int)r->xmin,
                 (int)r->ymin, (int)r->cell, r->W, GCD_TEXEL_IN(c), &c->d_seed) != GDT_OK ||
        gcd_launch(c, c->k.p1_splat, r->n, err) != GDT_OK ||
        gcd_args(c->k.p1_frame, err, "buuu", &c->d_seed, r->W, r->H,
                 (unsigned)r->frame_base) != GDT_OK ||
        gcd_launch(c, c->k.p1_frame, r->nframe, err) != GDT_OK ||
        gcd_args(c->k.p1_missing_flags, err, "bbub", GCD_TEXEL_IN(c), &c->d_seed, (unsigned)r->n,
                 &c->d_flags) != GDT_OK ||
        gcd_launch(c, c->k.p1_missing_flags, r->n, err) != GDT_OK ||
        gcd_compact(c, &c->d_flags, r->n, &c->d_list, &nmiss, err) != GDT_OK)
        return err->status;
    /* internal numbering: kept points in texel order, then the missing ones
     * by home chunk (stable: input order within), and the index range of
     * every chunk's missing points (Phase 2 reserves their slots) */
    size_t nchunks = gcd_corner_chunks(r->W, r->H);
    unsigned bits = 8;
    while (bits < 32 && ((size_t)1 << bits) <= nchunks)
        bits += 8;
    if (gcd_args(c->k.p1_occ_flags, err, "buub", &c->d_seed, (unsigned)npix, (unsigned)r->n,
                 &c->d_flags) != GDT_OK ||
        gcd_launch(c, c->k.p1_occ_flags, npix, err) != GDT_OK ||
        gcd_scan(c, &c->d_flags, npix, &kept, err) != GDT_OK ||
        gcd_args(c->k.p1_number_kept, err, "buubb", &c->d_seed, (unsigned)npix, (unsigned)r->n,
                 &c->d_flags, &c->d_int2in) != GDT_OK ||
        gcd_launch(c, c->k.p1_number_kept, npix, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_mkeys, 4 * nmiss + 4, err) != GDT_OK ||
        gcd_args(c->k.p1_missing_keys, err, "bubuub", &c->d_list, (unsigned)nmiss,
                 GCD_TEXEL_IN(c), r->W, r->H, &c->d_mkeys) != GDT_OK ||
        gcd_launch(c, c->k.p1_missing_keys, nmiss, err) != GDT_OK ||
        gcd_radix_sort(c, &c->d_mkeys, &c->d_list, nmiss, bits, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_mrange, 8 * (nchunks + 1), err) != GDT_OK ||
        gcd_fill(c, &c->d_mrange, 2 * (nchunks + 1), 0, err) != GDT_OK ||
        gcd_args(c->k.p1_missing_range, err, "bub", &c->d_mkeys, (unsigned)nmiss,
                 &c->d_mrange) != GDT_OK ||
        gcd_launch(c, c->k.p1_missing_range, nmiss, err) != GDT_OK ||
        gcd_args(c->k.p1_number_missing, err, "buub", &c->d_list, (unsigned)nmiss, kept,
                 &c->d_int2in) != GDT_OK ||
        gcd_launch(c, c->k.p1_number_missing, nmiss, err) != GDT_OK ||
        gcd_args(c->k.p1_permute, err, "bubbbb", &c->d_int2in, (unsigned)r->n, GCD_PTS_IN(c),
                 GCD_TEXEL_IN(c), &c->d_pts, &c->d_texel) != GDT_OK ||
        gcd_launch(c, c->k.p1_permute, r->n, err) != GDT_OK)
        return err->status;
    if ((size_t)kept + nmiss != r->n)
        return gdt_error_set(err, GDT_EINTERNAL, 7612, "%u kept and %zu missing of %zu points",
                             kept, nmiss, r->n);
    r->nmissing = nmiss;
    r->kept = kept;
    if (r->st != NULL) {
        r->st->kept = r->kept;
        r->st->missing_phase1 = nmiss;
    }
    return GDT_OK;
}

/* ---- test entry point ---- */

gdt_status gcd_test_voronoi(gdt_core *c, const uint32_t *sites, size_t nsites, uint32_t W,
                            uint32_t H, uint32_t *colour, gdt_error *err)
{
    gcd_run r;
    size_t npix = (size_t)W * H;

    memset(&r, 0, sizeof r);
    r.W = W;
    r.H = H;
    if (W == 0 || H == 0 || W > 16384 || H > 16384 || nsites == 0)
        return gdt_error_set(err, GDT_EINPUT, 3601, "bad test grid %ux%u with %zu sites", W, H,
                             nsites);
    if (gcd_buf_need(c, &c->d_seed, 4 * npix, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux3, 4 * nsites, err) != GDT_OK ||
        gcd_fill(c, &c->d_seed, npix, GCD_EMPTY, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux3.b, 0, sites, 4 * nsites, err) != GDT_OK ||
        gcd_args(c->k.p1_plant, err, "bub", &c->d_aux3, (unsigned)nsites, &c->d_seed) != GDT_OK ||
        gcd_launch(c, c->k.p1_plant, nsites, err) != GDT_OK ||
        gcd_voronoi_from_seeds(c, &r, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, GCD_COLOUR(c)->b, 0, colour, 4 * npix, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}

void gcd_test_set_bands(gdt_core *c, unsigned bands)
{
    c->bands = bands ? bands : 1;
}
