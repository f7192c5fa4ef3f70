/* ground_out.c — --ground-out FILE.las: every record of the LAS/LAZ inputs
 * (or a record made from every point of PCD inputs), in input order, with
 * the ground filter's class.
 *
 * A record the point filter kept has the next input ordinal (the cloud's
 * numbering: the kept records of every input in turn, no gaps), and
 * J/ground.bits holds the class of every ordinal (run_ground.c: a record
 * is ground when its (x, y) is the location of a ground point, so the
 * duplicates the --dup merge folded share their point's class).  Such a
 * record gets class 2 or 1 (formats 0-5: the low 5 bits of the
 * classification byte, its flags kept; 6-10: the class byte); every other
 * byte, and every record the point filter dropped, is copied as read
 * (the integers of an input with another offset shifted onto the first
 * input's lattice).
 */
#include "private/ground_out.h"

#include "gdt_las_copy.h"
#include "gdt_source.h"
#include "private/cli_modes.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define GO_CHUNK 4096 /* records per read */

/* The bits of ordinals [first, first + n) (n <= GO_CHUNK) into bits, whose
 * byte 0 is that of ordinal first (the bit of ordinal o is bit o % 8 of
 * bits[o / 8 - first / 8]). */
static gdt_status read_bits(const tr_run *c, int fd, uint64_t first, size_t n,
                            unsigned char *bits, gdt_error *err)
{
    size_t want, got = 0;
    if (n == 0)
        return GDT_OK;
    want = (size_t)((first + n - 1) / 8 - first / 8 + 1);
    while (got < want) {
        ssize_t k = pread(fd, bits + got, want - got, (off_t)(first / 8 + got));
        if (k < 0 && errno == EINTR)
            continue;
        if (k <= 0)
            return gdt_error_set(err, GDT_EIO, 4504, "%s: %s", c->ground_bits,
                                 k < 0 ? strerror(errno) : "shorter than the points");
        got += (size_t)k;
    }
    return GDT_OK;
}

static unsigned bit_class(const unsigned char *bits, uint64_t first, uint64_t ord)
{
    return (bits[ord / 8 - first / 8] >> (ord % 8)) & 1u ? 2u : 1u;
}

static void put32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v & 0xFFu);
    p[1] = (unsigned char)((v >> 8) & 0xFFu);
    p[2] = (unsigned char)((v >> 16) & 0xFFu);
    p[3] = (unsigned char)(v >> 24);
}

/* The inputs' kind: 1 when every input is PCD (the records are made from
 * the points), 0 when they are LAS/LAZ records of one layout (copied);
 * GDT_EUSAGE 2151 for a mix or layouts that differ. */
static gdt_status inputs_kind(const gdt_options *opts, int *pcd, gdt_error *err)
{
    gdt_source_info first;
    gdt_status st = GDT_OK;
    *pcd = 0;
    for (size_t i = 0; i < opts->ninputs && st == GDT_OK; i++) {
        gdt_source *src = NULL;
        gdt_source_opts so;
        int64_t shift[3];
        memset(&so, 0, sizeof so);
        st = gdt_source_open(&src, opts->inputs[i], &so, err);
        if (st != GDT_OK)
            break;
        if (i == 0) {
            first = *gdt_source_get_info(src);
            *pcd = first.format == GDT_FORMAT_PCD;
        }
        if (*pcd != (gdt_source_get_info(src)->format == GDT_FORMAT_PCD))
            st = gdt_error_set(err, GDT_EUSAGE, 2151,
                               "%s: --ground-out copies LAS records or makes them all from PCD "
                               "points, not both (the first input is %s)",
                               opts->inputs[i], first.format_name);
        else if (!*pcd)
            st = gdt_las_copy_accepts(&first, opts->inputs[i], gdt_source_get_info(src), shift,
                                      err);
        gdt_source_close(src);
    }
    return st;
}

gdt_status tr_ground_out_check(const gdt_options *opts, gdt_error *err)
{
    int pcd = 0;
    return opts->ground_out == NULL ? GDT_OK : inputs_kind(opts, &pcd, err);
}

/* PCD inputs: one LAS 1.2 record of point format 0 per point of the
 * cloud (every point: PCD has no class or return to filter), in input
 * order, on the cloud's lattice: X, Y the lattice integers less the
 * cloud's lowest, Z = z in steps of the quantum from the lowest z (rounded
 * to the nearest), return 1 of 1, class 2 or 1, every other field 0. */
static gdt_status write_from_points(tr_run *c, int bits_fd, gdt_error *err)
{
    const gdt_lattice *L = &gdt_cloud_get_info(c->cloud)->lattice;
    const gdt_tile_plan *pl = c->plan;
    const double zs = c->opts->quantum;
    const double scale[3] = {L->sx, L->sy, zs};
    const double offset[3] = {L->ox + L->sx * (double)pl->min_x,
                              L->oy + L->sy * (double)pl->min_y, pl->min_z};
    gdt_las_copy *w = NULL;
    gdt_point *pts = malloc(GO_CHUNK * sizeof *pts);
    unsigned char *rec = calloc(GO_CHUNK, 20), bits[GO_CHUNK / 8 + 2];
    uint64_t n_all = 0;
    gdt_status st = pts == NULL || rec == NULL
                        ? gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory")
                        : gdt_las_copy_open_new(&w, c->opts->ground_out, scale, offset, err);

    if (st == GDT_OK)
        st = gdt_cloud_rewind(c->cloud, err);
    while (st == GDT_OK) {
        size_t n = 0;
        st = gdt_cloud_read(c->cloud, pts, GO_CHUNK, &n, err);
        if (st != GDT_OK || n == 0)
            break;
        /* the cloud numbers the points it gives in turn, without gaps */
        if (pts[n - 1].ord - pts[0].ord != n - 1)
            st = gdt_error_set(err, GDT_EINTERNAL, 7706, "ordinals %" PRIu64 "..%" PRIu64
                               " for %zu points", pts[0].ord, pts[n - 1].ord, n);
        if (st == GDT_OK)
            st = read_bits(c, bits_fd, pts[0].ord, n, bits, err);
        for (size_t i = 0; i < n && st == GDT_OK; i++) {
            unsigned char *r = rec + 20 * i;
            double zq = nearbyint((pts[i].z - pl->min_z) / zs);
            if (!(zq >= 0.0 && zq <= 2147483647.0))
                st = gdt_error_set(err, GDT_EUSAGE, 2152,
                                   "--ground-out: z %.17g is beyond 2^31 steps of --quantum %g "
                                   "above the lowest z",
                                   pts[i].z, zs);
            if (st != GDT_OK)
                break;
            memset(r, 0, 20);
            put32(r, (uint32_t)(pts[i].x - pl->min_x));
            put32(r + 4, (uint32_t)(pts[i].y - pl->min_y));
            put32(r + 8, (uint32_t)(int32_t)zq);
            r[14] = 0x09u; /* return 1 of 1 */
            r[15] = (unsigned char)bit_class(bits, pts[0].ord, pts[i].ord);
        }
        if (st == GDT_OK)
            st = gdt_las_copy_put(w, rec, n, err);
        n_all += n;
    }
    free(pts);
    free(rec);
    if (st == GDT_OK && n_all != pl->points)
        st = gdt_error_set(err, GDT_EINPUT, 3501,
                           "the input changed since pass 1: %" PRIu64 " points now, %" PRIu64
                           " then",
                           n_all, pl->points);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    return gdt_las_copy_finish(w, err);
}

/* Copies the records of input path that fall in [first, end) of the
 * inputs taken as one sequence (its record r is number *b + r; *b is
 * advanced past it) into w, at w's place (onto the lattice of tinfo, the
 * first input's); *ord: the next input ordinal. */
static gdt_status copy_input(const tr_run *c, const char *path, const gdt_source_info *tinfo,
                             int bits_fd, gdt_las_copy *w, uint64_t *b, uint64_t first,
                             uint64_t end, uint64_t *ord, gdt_error *err)
{
    int64_t shift[3];
    uint64_t rec = 0, count, lo, hi;
    const gdt_options *opts = c->opts;
    gdt_source *src = NULL;
    gdt_source_opts so;
    gdt_src_point *pt = NULL;
    unsigned char *raw = NULL, bits[GO_CHUNK / 8 + 2], kept[GO_CHUNK];
    unsigned fmt, rl;
    gdt_status st;

    memset(&so, 0, sizeof so);
    so.log = (gdt_log *)&c->log;
    so.threads = gdt_cli_threads(opts->threads); /* every field decoded: need 0 */
    st = gdt_source_open(&src, path, &so, err);
    if (st != GDT_OK)
        return st;
    /* this input's part of [first, end), in its own numbering */
    count = gdt_source_get_info(src)->point_count;
    lo = first > *b ? first - *b : 0;
    hi = end - *b < count ? end - *b : count;
    if (end <= *b || lo >= hi) {
        *b += count;
        gdt_source_close(src);
        return GDT_OK;
    }
    *b += count;
    rec = lo;
    fmt = gdt_source_get_info(src)->point_format;
    rl = gdt_source_get_info(src)->record_length;
    st = gdt_las_copy_accepts(tinfo, path, gdt_source_get_info(src), shift, err);
    if (st == GDT_OK && (lo > 0 || hi < count))
        st = gdt_source_seek(src, lo, hi, err);
    pt = malloc(GO_CHUNK * sizeof *pt);
    raw = malloc((size_t)GO_CHUNK * rl);
    if (st == GDT_OK && (pt == NULL || raw == NULL))
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    while (st == GDT_OK && rec < hi) {
        size_t n = 0, nkept = 0;
        const uint64_t ord0 = *ord;
        st = gdt_source_read_raw(src, pt, raw, hi - rec < GO_CHUNK ? (size_t)(hi - rec) : GO_CHUNK,
                                 &n, err);
        if (st != GDT_OK || n == 0)
            break;
        for (size_t i = 0; i < n; i++) {
            kept[i] = gdt_filter_test(&opts->filter, &pt[i]) == GDT_KEEP;
            nkept += kept[i];
        }
        /* the kept records have ordinals [ord0, ord0 + nkept) */
        st = read_bits(c, bits_fd, ord0, nkept, bits, err);
        for (size_t i = 0; i < n && st == GDT_OK; i++) {
            unsigned char *r = raw + i * rl;
            unsigned cls;
            if (!kept[i])
                continue;
            cls = bit_class(bits, ord0, *ord);
            if (fmt >= 6)
                r[16] = (unsigned char)cls;
            else
                r[15] = (unsigned char)((r[15] & 0xE0u) | cls);
            (*ord)++;
        }
        if (st == GDT_OK)
            st = gdt_las_copy_shift(raw, n, rl, shift, path, rec, err);
        if (st == GDT_OK)
            st = gdt_las_copy_put(w, raw, n, err);
        rec += n;
    }
    free(pt);
    free(raw);
    gdt_source_close(src);
    return st;
}

/* The records [first, end) of the inputs taken as one sequence, in order,
 * into w from its record first, with ordinals from ord_base; *kept: the
 * records the point filter kept among them; *records: every input's. */
static gdt_status copy_share(const tr_run *c, const gdt_source_info *tinfo, int bits_fd,
                             gdt_las_copy *w, uint64_t first, uint64_t end, uint64_t ord_base,
                             uint64_t *kept, uint64_t *records, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    uint64_t b = 0, ord = ord_base;
    gdt_status st = gdt_las_copy_seek(w, first, err);
    for (size_t i = 0; i < opts->ninputs && st == GDT_OK; i++) {
        st = copy_input(c, opts->inputs[i], tinfo, bits_fd, w, &b, first, end, &ord, err);
        if (st == GDT_OK && tr_stopped(c))
            st = gdt_error_set(err, GDT_EINTERRUPTED, 1303,
                               "stopped by a signal while writing %s", opts->ground_out);
    }
    *kept = ord - ord_base;
    *records = b;
    return st;
}

/* The first input's header (the copy's template) and J/ground.bits open. */
static gdt_status open_inputs(const tr_run *c, gdt_source_info *tinfo, int *fd, gdt_error *err)
{
    gdt_source *src = NULL;
    gdt_source_opts so;
    gdt_status st;
    memset(&so, 0, sizeof so);
    *fd = -1;
    st = gdt_source_open(&src, c->opts->inputs[0], &so, err);
    if (st == GDT_OK)
        *tinfo = *gdt_source_get_info(src);
    gdt_source_close(src);
    if (st == GDT_OK && (*fd = open(c->ground_bits, O_RDONLY | O_CLOEXEC)) < 0)
        st = gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", c->ground_bits,
                           strerror(errno));
    return st;
}

gdt_status tr_ground_out_part(tr_run *c, const char *tmp, uint64_t points_at, uint64_t first,
                              uint64_t end, uint64_t ord_base, gdt_las_copy_stats *stats,
                              uint64_t *kept, gdt_error *err)
{
    gdt_source_info tinfo;
    gdt_las_copy *w = NULL;
    uint64_t records = 0;
    int fd = -1;
    gdt_status st = open_inputs(c, &tinfo, &fd, err);

    memset(stats, 0, sizeof *stats);
    *kept = 0;
    if (st == GDT_OK)
        st = gdt_las_copy_open_part(&w, tmp, points_at, &tinfo, err);
    if (st == GDT_OK)
        st = copy_share(c, &tinfo, fd, w, first, end, ord_base, kept, &records, err);
    if (fd >= 0)
        close(fd);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    return gdt_las_copy_close_part(w, stats, err);
}

gdt_status tr_ground_out_write(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    const tr_gout_share *sh = c->goshare;
    gdt_las_copy *w = NULL;
    uint64_t kept = 0, records = 0;
    int fd, pcd = 0, shared = 0;
    gdt_status st;
    gdt_source_info tinfo;

    st = inputs_kind(opts, &pcd, err);
    if (st != GDT_OK)
        return st;
    if (pcd) {
        fd = open(c->ground_bits, O_RDONLY | O_CLOEXEC);
        if (fd < 0)
            return gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", c->ground_bits,
                                 strerror(errno));
        st = write_from_points(c, fd, err);
        close(fd);
        return st;
    }
    st = open_inputs(c, &tinfo, &fd, err);
    if (st == GDT_OK)
        st = gdt_las_copy_open(&w, opts->ground_out, opts->inputs[0], &tinfo, err);
    if (st != GDT_OK) {
        if (fd >= 0)
            close(fd);
        return st;
    }
    if (sh != NULL) {
        /* every other process writes its share of the records in place */
        const char *tmp;
        uint64_t at, first = 0, end = 0, base = 0;
        gdt_las_copy_layout(w, &tmp, &at);
        st = sh->begin(sh->ctx, tmp, at, &shared, &first, &end, &base, err);
        if (st == GDT_OK && shared) {
            gdt_las_copy_stats sum;
            uint64_t others = 0;
            gdt_error e2;
            gdt_status s2;
            st = copy_share(c, &tinfo, fd, w, first, end, base, &kept, &records, err);
            gdt_error_clear(&e2);
            s2 = sh->wait(sh->ctx, &sum, &others, &e2); /* also after a failure here */
            if (st == GDT_OK && s2 != GDT_OK) {
                st = s2;
                *err = e2;
            }
            if (st == GDT_OK) {
                gdt_las_copy_add_stats(w, &sum);
                kept += others;
                c->s.ground_out_shared = 1;
                gdt_log_note((gdt_log *)&c->log, "%s: the records written in shares by the ranks",
                             opts->ground_out);
                /* past the last record: the EVLRs follow */
                st = gdt_las_copy_seek(w, records, err);
            }
        }
    }
    if (st == GDT_OK && !shared)
        st = copy_share(c, &tinfo, fd, w, 0, UINT64_MAX, 0, &kept, &records, err);
    close(fd);
    if (st == GDT_OK && kept != c->plan->points)
        st = gdt_error_set(err, GDT_EINPUT, 3501,
                           "the input changed since pass 1: %" PRIu64 " points kept now, %" PRIu64
                           " then",
                           kept, c->plan->points);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    return gdt_las_copy_finish(w, err);
}
