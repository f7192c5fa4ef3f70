/* ground_out.c — --ground-out FILE.las: every record of the LAS/LAZ inputs,
 * in input order, with the ground filter's class.
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
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define GO_CHUNK 4096 /* records per read */

gdt_status tr_ground_out_check(const gdt_options *opts, gdt_error *err)
{
    gdt_source_info first;
    gdt_status st = GDT_OK;
    if (opts->ground_out == NULL)
        return GDT_OK;
    for (size_t i = 0; i < opts->ninputs && st == GDT_OK; i++) {
        gdt_source *src = NULL;
        gdt_source_opts so;
        memset(&so, 0, sizeof so);
        st = gdt_source_open(&src, opts->inputs[i], &so, err);
        if (st != GDT_OK)
            break;
        int64_t shift[3];
        if (i == 0)
            first = *gdt_source_get_info(src);
        st = gdt_las_copy_accepts(&first, opts->inputs[i], gdt_source_get_info(src), shift, err);
        gdt_source_close(src);
    }
    return st;
}

/* Copies input path's records into w (onto the lattice of tinfo, the
 * first input's); *ord: the next input ordinal. */
static gdt_status copy_input(const tr_run *c, const char *path, const gdt_source_info *tinfo,
                             int bits_fd, gdt_las_copy *w, uint64_t *ord, gdt_error *err)
{
    int64_t shift[3];
    uint64_t rec = 0;
    const gdt_options *opts = c->opts;
    gdt_source *src = NULL;
    gdt_source_opts so;
    gdt_src_point *pt = NULL;
    unsigned char *raw = NULL, bits[GO_CHUNK / 8 + 2];
    unsigned fmt, rl;
    gdt_status st;

    memset(&so, 0, sizeof so);
    so.log = (gdt_log *)&c->log;
    so.threads = gdt_cli_threads(opts->threads); /* every field decoded: need 0 */
    st = gdt_source_open(&src, path, &so, err);
    if (st != GDT_OK)
        return st;
    fmt = gdt_source_get_info(src)->point_format;
    rl = gdt_source_get_info(src)->record_length;
    st = gdt_las_copy_accepts(tinfo, path, gdt_source_get_info(src), shift, err);
    pt = malloc(GO_CHUNK * sizeof *pt);
    raw = malloc((size_t)GO_CHUNK * rl);
    if (st == GDT_OK && (pt == NULL || raw == NULL))
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    while (st == GDT_OK) {
        size_t n = 0, kept = 0, got = 0;
        uint64_t first = *ord, off;
        st = gdt_source_read_raw(src, pt, raw, GO_CHUNK, &n, err);
        if (st != GDT_OK || n == 0)
            break;
        for (size_t i = 0; i < n; i++)
            kept += gdt_filter_test(&opts->filter, &pt[i]) == GDT_KEEP;
        /* the bits of ordinals [first, first + kept) */
        off = first / 8;
        if (kept > 0) {
            size_t want = (size_t)((first + kept - 1) / 8 - off + 1);
            ssize_t k = pread(bits_fd, bits, want, (off_t)off);
            got = k > 0 ? (size_t)k : 0;
            if (got != want)
                st = gdt_error_set(err, GDT_EIO, 4504, "%s: %s", c->ground_bits,
                                   k < 0 ? strerror(errno) : "shorter than the points");
        }
        for (size_t i = 0; i < n && st == GDT_OK; i++) {
            unsigned char *r = raw + i * rl;
            unsigned cls;
            if (gdt_filter_test(&opts->filter, &pt[i]) != GDT_KEEP)
                continue;
            cls = (bits[*ord / 8 - off] >> (*ord % 8)) & 1u ? 2u : 1u;
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

gdt_status tr_ground_out_write(tr_run *c, gdt_error *err)
{
    const gdt_options *opts = c->opts;
    gdt_las_copy *w = NULL;
    gdt_source *src = NULL;
    gdt_source_opts so;
    uint64_t ord = 0;
    int fd;
    gdt_status st;

    gdt_source_info tinfo;

    memset(&so, 0, sizeof so);
    st = gdt_source_open(&src, opts->inputs[0], &so, err);
    if (st == GDT_OK) {
        tinfo = *gdt_source_get_info(src);
        st = gdt_las_copy_open(&w, opts->ground_out, opts->inputs[0], &tinfo, err);
    }
    gdt_source_close(src);
    if (st != GDT_OK)
        return st;
    fd = open(c->ground_bits, O_RDONLY | O_CLOEXEC);
    if (fd < 0) {
        gdt_las_copy_abort(w);
        return gdt_error_set(err, GDT_EIO, 4504, "cannot open %s: %s", c->ground_bits,
                             strerror(errno));
    }
    for (size_t i = 0; i < opts->ninputs && st == GDT_OK; i++) {
        st = copy_input(c, opts->inputs[i], &tinfo, fd, w, &ord, err);
        if (st == GDT_OK && tr_stopped(c))
            st = gdt_error_set(err, GDT_EINTERRUPTED, 1303,
                               "stopped by a signal while writing %s", opts->ground_out);
    }
    close(fd);
    if (st == GDT_OK && ord != c->plan->points)
        st = gdt_error_set(err, GDT_EINPUT, 3501,
                           "the input changed since pass 1: %" PRIu64 " points kept now, %" PRIu64
                           " then",
                           ord, c->plan->points);
    if (st != GDT_OK) {
        gdt_las_copy_abort(w);
        return st;
    }
    return gdt_las_copy_finish(w, err);
}
