/* pass2_part.c — pass 2 out of core in shares between processes: each
 * spills its share of the cloud into .raw files of its own (suffix
 * ".p<R>"), and the owner of a tile takes the shares' files, in share
 * order, for the --dup merge: read straight into memory when the tile's
 * records fit, else joined into the tile's .raw file.  Shares are
 * consecutive runs of input order, so either way the merge sees the
 * records a single process spills, in the same order.
 */
#define _GNU_SOURCE 1 /* copy_file_range */
#include "private/tiler_impl.h"
#include "private/tiler_io.h"

#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

gdt_status gdt_tiler_spill_part(gdt_tiler *t, int part, gdt_error *err)
{
    gdt_status st;
    if ((t->state != 1 && t->state != 5) || t->job_dir == NULL || part < 0)
        return gdt_error_set(err, GDT_EUSAGE, 2505,
                             "a share of pass 2 needs the state after pass 1 and a job "
                             "directory");
    snprintf(t->spill_part, sizeof t->spill_part, ".p%d", part);
    for (uint64_t k = 0; k < t->ntiles; k++)
        t->tiles[k].written = 0;
    st = tl_spill_files(t, err);
    t->spill_part[0] = '\0';
    return st;
}

/* Appends the whole of file src (fd in) to out; *bytes grows by its size. */
static gdt_status append_file(int out, const char *dst, int in, const char *src, uint64_t *bytes,
                              gdt_error *err)
{
    unsigned char buf[1 << 16];
    int copy = 1;
    for (;;) {
        ssize_t n;
        if (copy) {
            n = copy_file_range(in, NULL, out, NULL, (size_t)1 << 30, 0);
            if (n < 0 && (errno == EXDEV || errno == ENOSYS || errno == EINVAL ||
                          errno == EOPNOTSUPP)) {
                copy = 0; /* another file system, an old kernel: copy through memory */
                continue;
            }
        } else {
            n = read(in, buf, sizeof buf);
            if (n > 0) {
                gdt_status st = tl_write_all(out, buf, (size_t)n, dst, err);
                if (st != GDT_OK)
                    return st;
            }
        }
        if (n < 0 && errno == EINTR)
            continue;
        if (n < 0)
            return gdt_error_set(err, GDT_EIO, 4503, "cannot copy %s to %s: %s", src, dst,
                                 strerror(errno));
        if (n == 0)
            return GDT_OK;
        *bytes += (uint64_t)n;
    }
}

/* The error of a tile whose shares do not hold pass 1's count. */
static gdt_status count_changed(const gdt_tiler *t, uint64_t k, uint64_t got, gdt_error *err)
{
    return gdt_error_set(err, GDT_EINPUT, 3501,
                         "the input changed between the two passes: tile (%" PRId64 ", %" PRId64
                         ") received %" PRIu64 " points, pass 1 counted %" PRIu64,
                         t->tiles[k].i, t->tiles[k].j, got, t->tiles[k].count);
}

/* Reads the shares' files of tile k (base path raw) into recs, which holds
 * the tile's pass-1 count; the files are removed once all are read.
 * Invariant: got counts the records read so far, never more than count
 * (a longer share is the changed-input error at once). */
static gdt_status read_parts(gdt_tiler *t, uint64_t k, const char *raw, int parts, gdt_point *recs,
                             gdt_error *err)
{
    const uint64_t count = t->tiles[k].count;
    uint64_t got = 0;
    gdt_status st = GDT_OK;
    for (int r = 0; r < parts && st == GDT_OK; r++) {
        char *src = tl_path("%s.p%d", raw, r);
        tl_rfile rf;
        struct stat sb;
        uint64_t nrec;
        size_t n;
        if (src == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        if (stat(src, &sb) != 0) {
            if (errno != ENOENT) /* else that share had no point in this tile */
                st = gdt_error_set(err, GDT_EIO, 4502, "cannot open %s: %s", src,
                                   strerror(errno));
            free(src);
            continue;
        }
        nrec = (uint64_t)sb.st_size / TL_REC;
        if ((uint64_t)sb.st_size % TL_REC != 0 || nrec > count - got)
            st = count_changed(t, k, got + nrec, err);
        if (st == GDT_OK && nrec > 0) {
            st = tl_rfile_open(&rf, src, nrec, t->sz.merge_read_recs, err);
            if (st == GDT_OK) {
                st = tl_rfile_read(&rf, recs + got, (size_t)nrec, &n, err);
                if (st == GDT_OK && n != nrec)
                    st = gdt_error_set(err, GDT_EJOB, 6503, "%s: shorter than written", src);
                tl_rfile_close(&rf);
            }
            got += nrec;
        }
        free(src);
    }
    if (st == GDT_OK && got != count)
        st = count_changed(t, k, got, err);
    for (int r = 0; r < parts && st == GDT_OK; r++) {
        char *src = tl_path("%s.p%d", raw, r);
        if (src == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        unlink(src);
        free(src);
    }
    return st;
}

gdt_status gdt_tiler_take_parts(gdt_tiler *t, uint64_t k, int parts, gdt_point **recs,
                                uint64_t *n, gdt_error *err)
{
    uint64_t count;
    char *raw;
    gdt_status st;

    *recs = NULL;
    *n = 0;
    if ((t->state != 1 && t->state != 5) || t->job_dir == NULL || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no share of pass 2 to take (tile %" PRIu64
                             ")", k);
    count = t->tiles[k].count;
    /* in memory as the merge of a shipped tile takes it: then the join's
     * copy of every record and the merge's reading of the copy are saved;
     * a .raw file that must stay (keep_spill) or a tile whose records and
     * merge table pass half the budget is joined as before */
    if (t->opts.keep_spill || count >= TL_MERGE_CAP_MAX || count == 0 ||
        count * sizeof(gdt_point) + tl_collapse_table_bytes(count) > t->budget / 2)
        return gdt_tiler_join_parts(t, k, parts, err);
    raw = tl_tile_file(t, k, "raw", 1);
    *recs = malloc((size_t)count * sizeof **recs);
    if (raw == NULL || *recs == NULL) {
        free(raw);
        free(*recs);
        *recs = NULL;
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    st = read_parts(t, k, raw, parts, *recs, err);
    free(raw);
    if (st != GDT_OK) {
        free(*recs);
        *recs = NULL;
    } else {
        *n = count;
    }
    return st;
}

gdt_status gdt_tiler_join_parts(gdt_tiler *t, uint64_t k, int parts, gdt_error *err)
{
    char *dst = NULL, *src = NULL;
    uint64_t bytes = 0;
    int out = -1;
    gdt_status st = GDT_OK;

    if ((t->state != 1 && t->state != 5) || t->job_dir == NULL || k >= t->ntiles)
        return gdt_error_set(err, GDT_EUSAGE, 2505, "no share of pass 2 to join (tile %" PRIu64
                             ")", k);
    dst = tl_tile_file(t, k, "raw", !t->opts.keep_spill);
    if (dst == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    out = open(dst, O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666);
    if (out < 0) {
        st = gdt_error_set(err, GDT_EIO, 4502, "cannot create %s: %s", dst, strerror(errno));
        goto done;
    }
    for (int r = 0; r < parts && st == GDT_OK; r++) {
        int in;
        free(src);
        src = tl_path("%s.p%d", dst, r);
        if (src == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            break;
        }
        in = open(src, O_RDONLY | O_CLOEXEC);
        if (in < 0 && errno == ENOENT)
            continue; /* that share had no point in this tile */
        if (in < 0) {
            st = gdt_error_set(err, GDT_EIO, 4502, "cannot open %s: %s", src, strerror(errno));
            break;
        }
        st = append_file(out, dst, in, src, &bytes, err);
        close(in);
        if (st == GDT_OK)
            unlink(src);
    }
    if (st == GDT_OK && close(out) != 0)
        st = gdt_error_set(err, GDT_EIO, 4503, "cannot write %s: %s", dst, strerror(errno));
    out = -1;
    if (st == GDT_OK && bytes != t->tiles[k].count * TL_REC)
        st = count_changed(t, k, bytes / TL_REC, err);
    if (st == GDT_OK)
        t->tiles[k].written = t->tiles[k].count;
done:
    if (out >= 0)
        close(out);
    free(src);
    free(dst);
    return st;
}
