/* test_merge_stream — the seam merge by rows against the whole triangulation.
 *
 * Each case is a seeded point set cut into square tiles the way the tiled
 * pipeline cuts it: per tile, T_{d1,d2} of its own points (the reference
 * triangulator), certification against its halo (gdt_certify_tile) and its
 * seam (gdt_seam_extract).  Then, with F_row the faces of gdt_merger_round
 * over the rows and F_all those of gdt_merge_seams on all seams at once:
 *   - certified faces + F_row = T_{d1,d2} of all points (the reference on
 *     the whole set), as canonical face sets, each face exactly once;
 *   - F_row and F_all are the same set, with the same hull and counts;
 *   - a second run by rows gives the same face sequence;
 *   - on many rows of tiles the largest band stays far below the seam, and
 *     twice the rows (same width and density) give about the same band.
 * Layouts: uniform strips of 30+ rows, sparse points with empty rows, a void
 * wider than several rows with a lone point inside, co-circular grids,
 * clusters, points on tile borders, collinear sets, tiny sets; halos from 0
 * to wider than a tile.  Also the merger's refusals: 7810 to 7814.
 */
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "gdt_certify.h"
#include "gdt_check.h"

/* The z given to the point at lattice (x, y). */
static double test_z(int64_t x, int64_t y)
{
    return 0.25 * (double)x - 1.5 * (double)y + 1000.0;
}
#include "gdt_reference.h"
#include "gdt_seam.h"

typedef struct pt {
    int64_t x, y;
    int64_t ti, tj; /* tile indices, set before the tile-order sort */
} pt;

typedef struct cloud {
    pt *p;
    size_t n, cap;
} cloud;

static void add(cloud *c, int64_t x, int64_t y)
{
    if (c->n == c->cap) {
        size_t cap = c->cap > 0 ? 2 * c->cap : 1024;
        pt *q = realloc(c->p, cap * sizeof *q);
        if (q == NULL) {
            fprintf(stderr, "out of memory\n");
            exit(2);
        }
        c->p = q;
        c->cap = cap;
    }
    c->p[c->n].x = x;
    c->p[c->n].y = y;
    c->p[c->n].ti = 0;
    c->p[c->n].tj = 0;
    c->n++;
}

static int64_t rnd(uint64_t *s, int64_t lo, int64_t hi)
{
    return lo + (int64_t)(gdt_splitmix64(s) % (uint64_t)(hi - lo));
}

static int64_t floor_div(int64_t a, int64_t b)
{
    int64_t q = a / b;
    return (a % b != 0 && a < 0) ? q - 1 : q;
}

/* Tile order: (j, i), then (y, x) inside a tile. */
static int cmp_tile_order(const void *pa, const void *pb)
{
    const pt *a = pa, *b = pb;
    if (a->tj != b->tj)
        return a->tj < b->tj ? -1 : 1;
    if (a->ti != b->ti)
        return a->ti < b->ti ? -1 : 1;
    if (a->y != b->y)
        return a->y < b->y ? -1 : 1;
    return (a->x > b->x) - (a->x < b->x);
}

static int cmp_face(const void *pa, const void *pb)
{
    const uint64_t *a = pa, *b = pb;
    for (int i = 0; i < 3; i++)
        if (a[i] != b[i])
            return a[i] < b[i] ? -1 : 1;
    return 0;
}

typedef struct faces {
    uint64_t *f;
    size_t n, cap;
} faces;

static void push_face(faces *F, uint64_t a, uint64_t b, uint64_t c)
{
    uint64_t v[3] = {a, b, c};
    int r = 0;
    if (F->n == F->cap) {
        size_t cap = F->cap > 0 ? 2 * F->cap : 1024;
        uint64_t *q = realloc(F->f, 3 * cap * sizeof *q);
        if (q == NULL) {
            fprintf(stderr, "out of memory\n");
            exit(2);
        }
        F->f = q;
        F->cap = cap;
    }
    if (v[1] < v[r])
        r = 1;
    if (v[2] < v[r])
        r = 2;
    for (int i = 0; i < 3; i++)
        F->f[3 * F->n + i] = v[(r + i) % 3];
    F->n++;
}

static void sort_faces(faces *F)
{
    if (F->n > 0)
        qsort(F->f, F->n, 3 * sizeof *F->f, cmp_face);
}

static void seam_append(gdt_seam *dst, const gdt_seam *src)
{
    gdt_seam_vertex *v = realloc(dst->v, (dst->nv + src->nv + 1) * sizeof *v);
    gdt_seam_edge *e = realloc(dst->e, (dst->ne + src->ne + 1) * sizeof *e);
    if (v == NULL || e == NULL) {
        fprintf(stderr, "out of memory\n");
        exit(2);
    }
    dst->v = v;
    dst->e = e;
    if (src->nv > 0)
        memcpy(dst->v + dst->nv, src->v, src->nv * sizeof *v);
    if (src->ne > 0)
        memcpy(dst->e + dst->ne, src->e, src->ne * sizeof *e);
    dst->nv += src->nv;
    dst->ne += src->ne;
    dst->cap_v = dst->nv + 1;
    dst->cap_e = dst->ne + 1;
}

/* The tiled pipeline on c (merge frame: every coordinate in [0, 2^31 - 1])
 * with tile side span and halo width h (lattice steps).  Fills cert (the
 * certified faces), rows[0..*nrows) (the seam of each non-empty row, in
 * order), y_next[r] (south edge of the row after r) and the x range. */
typedef struct tiled {
    faces cert;
    gdt_seam *rows;
    int64_t *y_next;
    size_t nrows;
    int64_t x0, x1; /* the cloud's x range */
    gdt_seam all;
} tiled;

static void tiled_free(tiled *t)
{
    free(t->cert.f);
    for (size_t r = 0; r < t->nrows; r++)
        gdt_seam_free(&t->rows[r]);
    free(t->rows);
    free(t->y_next);
    gdt_seam_free(&t->all);
    memset(t, 0, sizeof *t);
}

/* How tiles certify: keep_percent == 0: gdt_certify_tile against the halo;
 * otherwise each triangle of the tile that is a face of ref (the sorted,
 * canonical faces of the whole set) is certified with that probability.
 * Any subset of the tile's triangles of T qualifies as C for the merge
 * (gdt_seam.h assumes nothing else): random subsets give certified regions
 * with holes, islands and pinches that halo certification rarely makes. */
typedef struct cert_rule {
    unsigned keep_percent;
    uint64_t seed;
    const faces *ref;
} cert_rule;

static int in_ref(const faces *ref, uint64_t a, uint64_t b, uint64_t c)
{
    faces one = {NULL, 0, 0};
    int found;
    push_face(&one, a, b, c);
    found = ref->n > 0 && bsearch(one.f, ref->f, ref->n, 3 * sizeof *ref->f, cmp_face) != NULL;
    free(one.f);
    return found;
}

static int run_tiles(gdt_checks *ck, const char *label, cloud *c, int64_t span, int64_t h,
                     cert_rule *rule, tiled *out)
{
    gdt_certifier *cf = NULL;
    gdt_mesh m;
    gdt_error err;
    gdt_ipt *own = malloc((c->n + 1) * sizeof *own), *halo = malloc((c->n + 1) * sizeof *halo);
    uint8_t *cert = NULL;
    int64_t minx = INT64_MAX, miny = INT64_MAX, maxx = INT64_MIN, maxy = INT64_MIN;
    size_t k = 0;
    int rc = -1;

    memset(out, 0, sizeof *out);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    if (own == NULL || halo == NULL || gdt_certifier_create(&cf, 1, &err) != GDT_OK)
        goto done;
    for (size_t i = 0; i < c->n; i++) {
        minx = c->p[i].x < minx ? c->p[i].x : minx;
        miny = c->p[i].y < miny ? c->p[i].y : miny;
        maxx = c->p[i].x > maxx ? c->p[i].x : maxx;
        maxy = c->p[i].y > maxy ? c->p[i].y : maxy;
    }
    out->x0 = c->n > 0 ? minx : 0;
    out->x1 = c->n > 0 ? maxx : 0;
    out->rows = calloc(c->n + 1, sizeof *out->rows);
    out->y_next = calloc(c->n + 1, sizeof *out->y_next);
    if (out->rows == NULL || out->y_next == NULL)
        goto done;
    while (k < c->n) {
        int64_t ti = c->p[k].ti, tj = c->p[k].tj;
        int64_t x0 = ti * span - h, y0 = tj * span - h, ext = span + 2 * h;
        size_t k1 = k, nh = 0;
        gdt_cert_region r;
        gdt_seam ts = {NULL, 0, 0, NULL, 0, 0};
        gdt_status st;
        while (k1 < c->n && c->p[k1].ti == ti && c->p[k1].tj == tj) {
            own[k1 - k].x = c->p[k1].x - x0;
            own[k1 - k].y = c->p[k1].y - y0;
            k1++;
        }
        for (size_t i = 0; i < c->n; i++)
            if ((i < k || i >= k1) && c->p[i].x >= x0 && c->p[i].x < x0 + ext && c->p[i].y >= y0 &&
                c->p[i].y < y0 + ext) {
                halo[nh].x = c->p[i].x - x0;
                halo[nh].y = c->p[i].y - y0;
                nh++;
            }
        st = gdt_reference_triangulate(NULL, own, k1 - k, &m, &err);
        GDT_CHECK(ck, st == GDT_OK, "%s: tile (%" PRId64 ", %" PRId64 "): GDT-%d %s", label, ti, tj,
                  err.code, err.msg);
        if (st != GDT_OK)
            goto done;
        free(cert);
        cert = malloc(m.ntris + 1);
        if (cert == NULL)
            goto done;
        r.own[0] = h;
        r.own[1] = h;
        r.own[2] = h + span - 1;
        r.own[3] = h + span - 1;
        r.known[0] = 0;
        r.known[1] = 0;
        r.known[2] = ext - 1;
        r.known[3] = ext - 1;
        r.open[GDT_SIDE_WEST] = x0 <= minx;
        r.open[GDT_SIDE_SOUTH] = y0 <= miny;
        r.open[GDT_SIDE_EAST] = x0 + ext - 1 >= maxx;
        r.open[GDT_SIDE_NORTH] = y0 + ext - 1 >= maxy;
        if (rule->keep_percent == 0) {
            st = gdt_certify_tile(cf, &m, halo, nh, &r, cert, NULL, &err);
        } else {
            for (size_t q = 0; q < m.ntris; q++)
                cert[q] = gdt_splitmix64(&rule->seed) % 100 < rule->keep_percent &&
                          in_ref(rule->ref, k + (uint64_t)m.tri[3 * q],
                                 k + (uint64_t)m.tri[3 * q + 1], k + (uint64_t)m.tri[3 * q + 2]);
        }
        if (st == GDT_OK) {
            /* z is carried through the seam to the merge's faces */
            double *z = malloc((k1 - k + 1) * sizeof *z);
            for (size_t i = 0; z != NULL && i < k1 - k; i++)
                z[i] = test_z(c->p[k + i].x, c->p[k + i].y);
            st = z == NULL ? GDT_EINTERNAL
                           : gdt_seam_extract(&ts, &m, cert, z, (uint64_t)k, x0, y0, &err);
            free(z);
        }
        GDT_CHECK(ck, st == GDT_OK, "%s: certify/extract: GDT-%d %s", label, err.code, err.msg);
        if (st != GDT_OK) {
            gdt_seam_free(&ts);
            goto done;
        }
        for (size_t t = 0; t < m.ntris; t++)
            if (cert[t])
                push_face(&out->cert, k + (uint64_t)m.tri[3 * t], k + (uint64_t)m.tri[3 * t + 1],
                          k + (uint64_t)m.tri[3 * t + 2]);
        if (out->nrows == 0 || tj != c->p[k - 1].tj) {
            if (out->nrows > 0)
                out->y_next[out->nrows - 1] = tj * span;
            out->nrows++;
        }
        seam_append(&out->rows[out->nrows - 1], &ts);
        seam_append(&out->all, &ts);
        gdt_seam_free(&ts);
        k = k1;
    }
    rc = 0;
done:
    free(cert);
    free(own);
    free(halo);
    gdt_mesh_free(&m);
    gdt_certifier_destroy(cf);
    return rc;
}

/* Runs the merger over t's rows; faces in order of emission.  Every face's
 * vertex coordinates and z (gdt_merger_face_points, gdt_merger_face_z) must
 * be those its seam vertices carried. */
static int merge_by_rows(gdt_checks *ck, const char *label, const tiled *t, faces *F,
                         gdt_merge_stats *ms)
{
    gdt_merger *m = NULL;
    gdt_error err;
    int rc = -1;

    gdt_error_clear(&err);
    if (gdt_merger_create(&m, t->x0, t->x1, &err) != GDT_OK)
        return -1;
    for (size_t r = 0; r < t->nrows; r++) {
        const uint64_t *f;
        size_t nf;
        gdt_status st =
            gdt_merger_round(m, &t->rows[r], t->y_next[r], r + 1 == t->nrows, &f, &nf, &err);
        GDT_CHECK(ck, st == GDT_OK, "%s: round %zu: GDT-%d %s", label, r, err.code, err.msg);
        if (st != GDT_OK)
            goto done;
        for (size_t i = 0; i < nf; i++) {
            GDT_CHECK(ck, f[3 * i] < f[3 * i + 1] && f[3 * i] < f[3 * i + 2],
                      "%s: face not rotated to its smallest index", label);
            GDT_CHECK(ck, i == 0 || cmp_face(&f[3 * i - 3], &f[3 * i]) < 0,
                      "%s: faces of round %zu not sorted", label, r);
            push_face(F, f[3 * i], f[3 * i + 1], f[3 * i + 2]);
            for (int q = 0; q < 3; q++) {
                gdt_ipt p = gdt_merger_face_points(m)[3 * i + q];
                GDT_CHECK_QUIET_AFTER(ck, 5, gdt_merger_face_z(m)[3 * i + q] == test_z(p.x, p.y),
                                      "%s: round %zu face %zu: z not its vertex's", label, r, i);
            }
        }
    }
    *ms = *gdt_merger_stats(m);
    rc = 0;
done:
    gdt_merger_destroy(m);
    return rc;
}

typedef struct case_result {
    uint64_t seam, band, rounds, deferred;
} case_result;

/* The whole check of one point set (see the file comment). */
static void run_case_rule(gdt_checks *ck, const char *label, cloud *c, int64_t span, int64_t h,
                          unsigned keep_percent, case_result *res)
{
    cert_rule rule = {keep_percent, 0x5eed + keep_percent, NULL};
    tiled t;
    faces rows = {NULL, 0, 0}, rows2 = {NULL, 0, 0}, ref = {NULL, 0, 0}, mine = {NULL, 0, 0};
    uint64_t *all = NULL;
    size_t nall = 0;
    gdt_merge_stats ms_rows, ms_rows2, ms_all;
    gdt_mesh m;
    gdt_error err;
    gdt_ipt *pts = NULL;
    size_t w = 0;

    memset(res, 0, sizeof *res);
    memset(&t, 0, sizeof t);
    gdt_mesh_init(&m);
    gdt_error_clear(&err);
    for (size_t i = 0; i < c->n; i++) {
        c->p[i].ti = floor_div(c->p[i].x, span);
        c->p[i].tj = floor_div(c->p[i].y, span);
    }
    if (c->n > 0)
        qsort(c->p, c->n, sizeof *c->p, cmp_tile_order);
    for (size_t i = 0; i < c->n; i++)
        if (w == 0 || c->p[i].x != c->p[w - 1].x || c->p[i].y != c->p[w - 1].y)
            c->p[w++] = c->p[i];
    c->n = w;
    /* the reference of the whole set: vertex i is point i, i.e. output index i */
    pts = malloc((c->n + 1) * sizeof *pts);
    if (pts == NULL)
        goto done;
    for (size_t i = 0; i < c->n; i++) {
        pts[i].x = c->p[i].x;
        pts[i].y = c->p[i].y;
    }
    if (gdt_reference_triangulate(NULL, pts, c->n, &m, &err) != GDT_OK) {
        GDT_CHECK(ck, 0, "%s: reference: GDT-%d %s", label, err.code, err.msg);
        goto done;
    }
    for (size_t i = 0; i < m.ntris; i++)
        push_face(&ref, (uint64_t)m.tri[3 * i], (uint64_t)m.tri[3 * i + 1],
                  (uint64_t)m.tri[3 * i + 2]);
    sort_faces(&ref);
    rule.ref = &ref;
    if (run_tiles(ck, label, c, span, h, &rule, &t) != 0) {
        GDT_CHECK(ck, 0, "%s: the tile stage failed", label);
        goto done;
    }
    if (merge_by_rows(ck, label, &t, &rows, &ms_rows) != 0 ||
        merge_by_rows(ck, label, &t, &rows2, &ms_rows2) != 0)
        goto done;
    GDT_CHECK(ck,
              rows.n == rows2.n &&
                  (rows.n == 0 || memcmp(rows.f, rows2.f, 3 * rows.n * sizeof *rows.f) == 0),
              "%s: two merges by rows differ", label);
    if (gdt_merge_seams(&t.all, &all, &nall, &ms_all, &err) != GDT_OK) {
        GDT_CHECK(ck, 0, "%s: merge of all seams: GDT-%d %s", label, err.code, err.msg);
        goto done;
    }

    for (size_t i = 0; i < t.cert.n; i++)
        push_face(&mine, t.cert.f[3 * i], t.cert.f[3 * i + 1], t.cert.f[3 * i + 2]);
    for (size_t i = 0; i < rows.n; i++)
        push_face(&mine, rows.f[3 * i], rows.f[3 * i + 1], rows.f[3 * i + 2]);
    sort_faces(&mine);
    GDT_CHECK(ck, mine.n == ref.n, "%s: %zu certified + %zu merged faces, the reference has %zu",
              label, t.cert.n, rows.n, ref.n);
    if (mine.n == ref.n) {
        size_t bad = 0;
        for (size_t i = 0; i < ref.n; i++)
            bad += cmp_face(&mine.f[3 * i], &ref.f[3 * i]) != 0;
        GDT_CHECK(ck, bad == 0, "%s: %zu faces differ from the reference", label, bad);
    }
    sort_faces(&rows);
    GDT_CHECK(ck, rows.n == nall && (nall == 0 || memcmp(rows.f, all, 3 * nall * sizeof *all) == 0),
              "%s: by rows %zu faces, all at once %zu, or the sets differ", label, rows.n, nall);
    GDT_CHECK(ck,
              ms_rows.hull_vertices == ms_all.hull_vertices &&
                  ms_rows.seam_vertices == ms_all.seam_vertices &&
                  ms_rows.barrier_edges == ms_all.barrier_edges && ms_rows.faces == rows.n,
              "%s: counters differ (hull %" PRIu64 " vs %" PRIu64 ", seam %" PRIu64 " vs %" PRIu64
              ")",
              label, ms_rows.hull_vertices, ms_all.hull_vertices, ms_rows.seam_vertices,
              ms_all.seam_vertices);
    GDT_CHECK(ck, ms_rows.rounds == t.nrows && ms_all.rounds == 1,
              "%s: %" PRIu64 " rounds for %zu rows", label, ms_rows.rounds, t.nrows);
    GDT_CHECK(ck,
              ms_rows.max_band_vertices <= ms_rows.seam_vertices &&
                  ms_all.max_band_vertices == ms_all.seam_vertices,
              "%s: band %" PRIu64 " of %" PRIu64, label, ms_rows.max_band_vertices,
              ms_rows.seam_vertices);
    res->seam = ms_rows.seam_vertices;
    res->band = ms_rows.max_band_vertices;
    res->rounds = ms_rows.rounds;
    res->deferred = ms_rows.deferred;
done:
    free(pts);
    free(all);
    free(rows.f);
    free(rows2.f);
    free(ref.f);
    free(mine.f);
    gdt_mesh_free(&m);
    tiled_free(&t);
}

static void run_case(gdt_checks *ck, const char *label, cloud *c, int64_t span, int64_t h,
                     case_result *res)
{
    run_case_rule(ck, label, c, span, h, 0, res);
}

static void gen_uniform(cloud *c, uint64_t *s, size_t n, int64_t x0, int64_t x1, int64_t y0,
                        int64_t y1)
{
    for (size_t i = 0; i < n; i++)
        add(c, rnd(s, x0, x1), rnd(s, y0, y1));
}

/* Many rows: the band must stay a few rows' worth of the seam. */
static void test_tall_strips(gdt_checks *ck)
{
    static const int64_t halos[] = {0, 3, 12};
    for (int k = 0; k < 3; k++) {
        cloud c = {NULL, 0, 0};
        uint64_t s = 100 + (uint64_t)k;
        const int64_t span = 100;
        char label[64];
        case_result r;
        gen_uniform(&c, &s, 3 * 36 * 60, 0, 3 * span, 0, 36 * span); /* 3 x 36 tiles */
        snprintf(label, sizeof label, "tall strip, halo %" PRId64, halos[k]);
        run_case(ck, label, &c, span, halos[k], &r);
        GDT_CHECK(ck, r.rounds >= 30, "%s: %" PRIu64 " rounds", label, r.rounds);
        /* at most about three rows of seam (a row is seam / rounds) */
        GDT_CHECK(ck, r.band > 0 && r.band * r.rounds < 3 * r.seam,
                  "%s: largest band %" PRIu64 " of %" PRIu64 " seam vertices in %" PRIu64 " rows",
                  label, r.band, r.seam, r.rounds);
        free(c.p);
    }
}

/* The band is bounded by the tile size, not by the number of rows: the same
 * strip (width, density, halos) with R and 2R rows of tiles must have about
 * the same largest band.  Hull slivers along the west and east sides have
 * disks reaching far north, but outside the cloud's x range; a finality test
 * blind to that range keeps them pending and the band grows with every row
 * (here by more than a third from R to 2R).  The lattice is fine (tile side
 * 2^16) so that hardly any point lies exactly on the cloud's west or east
 * line: those are hull vertices of every later band (I1 of gdt_seam.h),
 * another effect. */
static void test_band_bounded(gdt_checks *ck)
{
    const int64_t span = INT64_C(1) << 16, rows = 60, cols = 2, per_tile = 40;
    const int64_t halos[] = {0, span / 25};
    for (int k = 0; k < 2; k++) {
        uint64_t band[2] = {0, 0}, seam[2] = {0, 0};
        char label[96];
        for (int q = 0; q < 2; q++) {
            cloud c = {NULL, 0, 0};
            uint64_t s = 400 + (uint64_t)k;
            int64_t nrows = rows << q;
            case_result r;
            gen_uniform(&c, &s, (size_t)(cols * nrows * per_tile), 0, cols * span, 0, nrows * span);
            snprintf(label, sizeof label, "strip of %" PRId64 " rows, halo %" PRId64, nrows,
                     halos[k]);
            run_case(ck, label, &c, span, halos[k], &r);
            GDT_CHECK(ck, r.rounds == (uint64_t)nrows, "%s: %" PRIu64 " rounds", label, r.rounds);
            band[q] = r.band;
            seam[q] = r.seam;
            free(c.p);
        }
        printf("band, halo %" PRId64 ": %" PRIu64 " of %" PRIu64 " seam vertices in %" PRId64
               " rows, %" PRIu64 " of %" PRIu64 " in %" PRId64 " rows\n",
               halos[k], band[0], seam[0], rows, band[1], seam[1], 2 * rows);
        GDT_CHECK(ck, band[0] > 0 && 10 * band[1] < 13 * band[0],
                  "halo %" PRId64 ": the largest band grows with the rows: %" PRIu64 " in %" PRId64
                  " rows, %" PRIu64 " in %" PRId64,
                  halos[k], band[0], rows, band[1], 2 * rows);
    }
}

/* Disks crossing several rows: sparse points, empty rows, a large void. */
static void test_sparse_and_voids(gdt_checks *ck)
{
    case_result r;
    for (int k = 0; k < 4; k++) {
        cloud c = {NULL, 0, 0};
        uint64_t s = 200 + (uint64_t)k;
        char label[64];
        /* a few points per tile row, rows 3..5 empty */
        for (int64_t j = 0; j < 12; j++) {
            if (j >= 3 && j <= 5)
                continue;
            gen_uniform(&c, &s, (size_t)rnd(&s, 1, 5), 0, 500, j * 100, j * 100 + 100);
        }
        snprintf(label, sizeof label, "sparse rows %d", k);
        run_case(ck, label, &c, 100, k, &r);
        free(c.p);
    }
    for (int k = 0; k < 3; k++) {
        cloud c = {NULL, 0, 0}, d = {NULL, 0, 0};
        uint64_t s = 300 + (uint64_t)k;
        char label[64];
        gen_uniform(&d, &s, 6000, 0, 1000, 0, 2000);
        for (size_t i = 0; i < d.n; i++) {
            int64_t dx = d.p[i].x - 500, dy = d.p[i].y - 1000;
            if (dx * dx + dy * dy > 420 * 420)
                add(&c, d.p[i].x, d.p[i].y);
        }
        add(&c, 503, 997); /* a lone point amid the void */
        snprintf(label, sizeof label, "void of 8 rows %d", k);
        run_case(ck, label, &c, 100, 2 * k, &r);
        free(c.p);
        free(d.p);
    }
}

/* Degenerate and awkward sets. */
static void test_layouts(gdt_checks *ck)
{
    case_result r;
    cloud c = {NULL, 0, 0};
    uint64_t s = 7;

    /* co-circular grid, and a rotated one (basis (3, 4), (-4, 3)) */
    for (int64_t y = 0; y < 40; y++)
        for (int64_t x = 0; x < 25; x++)
            add(&c, 5 + 8 * x, 3 + 8 * y);
    run_case(ck, "grid", &c, 64, 0, &r);
    run_case(ck, "grid, halo 9", &c, 64, 9, &r);
    c.n = 0;
    for (int64_t a = -20; a < 20; a++)
        for (int64_t b = -20; b < 20; b++)
            add(&c, 1000 + 3 * a - 4 * b, 1000 + 4 * a + 3 * b);
    run_case(ck, "rotated grid", &c, 50, 1, &r);
    c.n = 0;
    /* clusters and scatter */
    gen_uniform(&c, &s, 300, 0, 2000, 0, 2000);
    for (int k = 0; k < 4; k++) {
        int64_t cx = rnd(&s, 200, 1800), cy = rnd(&s, 200, 1800);
        gen_uniform(&c, &s, 400, cx - 30, cx + 30, cy - 30, cy + 30);
    }
    run_case(ck, "clusters", &c, 128, 4, &r);
    c.n = 0;
    /* points on the tile lines */
    gen_uniform(&c, &s, 800, 0, 400, 0, 400);
    for (int64_t q = 0; q <= 400; q += 10)
        for (int64_t l = 0; l <= 400; l += 100) {
            add(&c, q, l);
            add(&c, l, q);
        }
    run_case(ck, "tile borders", &c, 100, 0, &r);
    run_case(ck, "tile borders, halo 150", &c, 100, 150, &r);
    c.n = 0;
    /* collinear: no triangle anywhere */
    for (int64_t q = 0; q < 500; q++)
        add(&c, 7 * q, 3 * q + 11);
    run_case(ck, "collinear", &c, 64, 2, &r);
    GDT_CHECK(ck, r.band == r.seam, "collinear: every point stays in the band");
    c.n = 0;
    /* a thin horizontal strip over many tiles of one row, then a column */
    for (int64_t q = 0; q < 600; q++) {
        add(&c, 5 * q, 100);
        add(&c, 5 * q + 2, 103);
    }
    run_case(ck, "thin strip", &c, 64, 1, &r);
    c.n = 0;
    for (int64_t q = 0; q < 600; q++) {
        add(&c, 100, 5 * q);
        add(&c, 103, 5 * q + 2);
    }
    run_case(ck, "thin column", &c, 64, 1, &r);
    c.n = 0;
    /* two lattice columns, every y: every point is a hull point and stays in
     * the band, so most rows join the next round untriangulated */
    for (int64_t q = 0; q < 3000; q++) {
        add(&c, 0, q);
        add(&c, 1, q);
    }
    run_case(ck, "two columns", &c, 64, 2, &r);
    GDT_CHECK(ck, r.band == r.seam && r.rounds > 40 && 2 * r.deferred > r.rounds,
              "two columns: band %" PRIu64 " of %" PRIu64 ", %" PRIu64 " of %" PRIu64
              " rounds deferred",
              r.band, r.seam, r.deferred, r.rounds);
    c.n = 0;
    /* tiny sets */
    for (size_t n = 1; n <= 5; n++) {
        char label[32];
        c.n = 0;
        gen_uniform(&c, &s, n, 0, 300, 0, 300);
        snprintf(label, sizeof label, "%zu points", n);
        run_case(ck, label, &c, 64, 0, &r);
    }
    free(c.p);
}

/* Seeded random clouds, tile sizes and halos. */
static void test_random(gdt_checks *ck, int cases)
{
    for (int k = 0; k < cases; k++) {
        cloud c = {NULL, 0, 0};
        uint64_t s = 1000 + (uint64_t)k;
        int64_t span = rnd(&s, 20, 200), ext = rnd(&s, 200, 3000),
                h = rnd(&s, 0, 3) * rnd(&s, 0, 20);
        size_t n = (size_t)rnd(&s, 50, 3000);
        char label[96];
        case_result r;
        gen_uniform(&c, &s, n, 0, ext, 0, ext + rnd(&s, 0, 3000));
        if (rnd(&s, 0, 2) == 0) /* a Gaussian-ish blob: sums of uniforms */
            for (size_t i = 0; i < n / 2; i++)
                add(&c, (rnd(&s, 0, ext) + rnd(&s, 0, ext) + rnd(&s, 0, ext)) / 3,
                    (rnd(&s, 0, ext) + rnd(&s, 0, ext)) / 2);
        snprintf(label, sizeof label, "random %d (tile %" PRId64 ", halo %" PRId64 ")", k, span, h);
        run_case(ck, label, &c, span, h, &r);
        free(c.p);
    }
}

/* Random certified subsets of T: holes and islands of C in every row. */
static void test_random_certification(gdt_checks *ck, int cases)
{
    static const unsigned keep[] = {97, 90, 60, 30};
    for (int k = 0; k < cases; k++) {
        cloud c = {NULL, 0, 0};
        uint64_t s = 5000 + (uint64_t)k;
        int64_t span = rnd(&s, 30, 150);
        char label[96];
        case_result r;
        gen_uniform(&c, &s, (size_t)rnd(&s, 500, 2500), 0, rnd(&s, 100, 1000), 0,
                    rnd(&s, 500, 3000));
        snprintf(label, sizeof label, "random certification %d (tile %" PRId64 ", %u%%)", k, span,
                 keep[k % 4]);
        run_case_rule(ck, label, &c, span, 0, keep[k % 4], &r);
        free(c.p);
    }
}

/* The merger's refusals. */
static void test_errors(gdt_checks *ck)
{
    gdt_seam_vertex v[4] = {{10, 0, 0, 0.0}, {11, 100, 0, 0.0}, {12, 0, 100, 0.0}, {13, 100, 100, 0.0}};
    gdt_seam_edge bogus = {11, 12}, missing = {10, 99};
    gdt_seam row = {v, 4, 4, NULL, 0, 0}, back = {v, 2, 2, NULL, 0, 0};
    gdt_merger *m = NULL;
    const uint64_t *f;
    size_t nf;
    gdt_error err;

    /* 11-12 is the square's diagonal against the tie-break ((1, 1) wins: 10-13) */
    gdt_error_clear(&err);
    row.e = &bogus;
    row.ne = 1;
    GDT_CHECK(ck, gdt_merger_create(&m, 0, 100, &err) == GDT_OK, "create");
    GDT_CHECK(ck,
              gdt_merger_round(m, &row, 0, 1, &f, &nf, &err) == GDT_EINTERNAL && err.code == 7811,
              "a barrier edge missing from DT: GDT-%d %s", err.code, err.msg);
    gdt_merger_destroy(m);

    gdt_error_clear(&err);
    row.e = &missing;
    gdt_merger_create(&m, 0, 100, &err);
    GDT_CHECK(ck,
              gdt_merger_round(m, &row, 0, 1, &f, &nf, &err) == GDT_EINTERNAL && err.code == 7812,
              "an edge naming no band vertex: GDT-%d %s", err.code, err.msg);
    gdt_merger_destroy(m);

    gdt_error_clear(&err);
    row.ne = 0;
    gdt_merger_create(&m, 0, 100, &err);
    GDT_CHECK(ck, gdt_merger_round(m, &row, 50, 0, &f, &nf, &err) == GDT_OK, "round 0: %s",
              err.msg);
    GDT_CHECK(
        ck, gdt_merger_round(m, &back, 500, 0, &f, &nf, &err) == GDT_EINTERNAL && err.code == 7810,
        "ids below an earlier round's: GDT-%d %s", err.code, err.msg);
    gdt_merger_destroy(m);

    gdt_error_clear(&err);
    gdt_merger_create(&m, 0, 100, &err);
    GDT_CHECK(ck, gdt_merger_round(m, &row, 0, 1, &f, &nf, &err) == GDT_OK && nf == 2,
              "the square in one round: %zu faces", nf);
    GDT_CHECK(ck, gdt_merger_stats(m)->hull_vertices == 4, "hull of the square");
    GDT_CHECK(ck,
              gdt_merger_round(m, &row, 0, 1, &f, &nf, &err) == GDT_EINTERNAL && err.code == 7813,
              "a round after the last: GDT-%d %s", err.code, err.msg);
    gdt_merger_destroy(m);

    /* the x range must hold every vertex, and a row must start at or above
     * every earlier y_next: earlier rounds' finality tests assumed both */
    gdt_error_clear(&err);
    GDT_CHECK(ck,
              gdt_merger_create(&m, 5, 4, &err) == GDT_EINTERNAL && err.code == 7814 && m == NULL,
              "x range out of order: GDT-%d %s", err.code, err.msg);
    GDT_CHECK(ck,
              gdt_merger_create(&m, 0, GDT_COORD_MAX + 1, &err) == GDT_EINTERNAL &&
                  err.code == 7814 && m == NULL,
              "x range beyond the lattice: GDT-%d %s", err.code, err.msg);
    for (int k = 0; k < 2; k++) {
        gdt_error_clear(&err);
        gdt_merger_create(&m, k == 0 ? 1 : 0, k == 0 ? 100 : 99, &err);
        GDT_CHECK(
            ck, gdt_merger_round(m, &row, 0, 1, &f, &nf, &err) == GDT_EINTERNAL && err.code == 7814,
            "a vertex %s of the x range: GDT-%d %s", k == 0 ? "west" : "east", err.code, err.msg);
        gdt_merger_destroy(m);
    }
    {
        gdt_seam_vertex low[2] = {{20, 0, 49, 0.0}, {21, 100, 120, 0.0}};
        gdt_seam below = {low, 2, 2, NULL, 0, 0};
        gdt_error_clear(&err);
        gdt_merger_create(&m, 0, 100, &err);
        row.nv = 3;
        GDT_CHECK(ck, gdt_merger_round(m, &row, 50, 0, &f, &nf, &err) == GDT_OK, "round 0: %s",
                  err.msg);
        GDT_CHECK(ck,
                  gdt_merger_round(m, &below, 200, 1, &f, &nf, &err) == GDT_EINTERNAL &&
                      err.code == 7814,
                  "a vertex below the last y_next: GDT-%d %s", err.code, err.msg);
        gdt_merger_destroy(m);
        low[0].y = 50;
        gdt_error_clear(&err);
        gdt_merger_create(&m, 0, 100, &err);
        GDT_CHECK(ck,
                  gdt_merger_round(m, &row, 50, 0, &f, &nf, &err) == GDT_OK &&
                      gdt_merger_round(m, &below, 200, 1, &f, &nf, &err) == GDT_OK,
                  "a vertex on the last y_next: GDT-%d %s", err.code, err.msg);
        gdt_merger_destroy(m);
        row.nv = 4;
    }
}

int main(int argc, char **argv)
{
    gdt_checks ck = {0, 0};
    int cases = argc > 1 ? atoi(argv[1]) : 40;
    test_errors(&ck);
    test_tall_strips(&ck);
    test_band_bounded(&ck);
    test_sparse_and_voids(&ck);
    test_layouts(&ck);
    test_random(&ck, cases);
    test_random_certification(&ck, cases);
    return gdt_check_finish(&ck, "test_merge_stream");
}
