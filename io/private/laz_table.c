/* laz_table.c — the LASzip chunk table.
 *
 * Layout: the point data starts with the int64 offset of the table (-1: the
 * offset is in the file's last 8 bytes).  The table holds u32 version (0),
 * u32 chunk count, then one arithmetic-coded stream of, per chunk, its point
 * count (variable chunks only; context 0, predicted by the previous count)
 * and its compressed size (context 1, predicted by the previous size), both
 * through one 32-bit integer decompressor with two contexts.
 */
#include <errno.h>
#include <inttypes.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "bytes.h"
#include "laz_arith.h"
#include "laz_chunk.h"

/* The fewest bytes a chunk can have: the raw first record of the smallest
 * point format (POINT10). */
#define LAZ_MIN_CHUNK 20

/* Reads n bytes at off; returns 0, an errno value, or -1 for end of file. */
static int read_at(int fd, void *buf, size_t n, uint64_t off)
{
    unsigned char *p = buf;
    while (n > 0) {
        ssize_t r = pread(fd, p, n, (off_t)off);
        if (r < 0) {
            if (errno == EINTR)
                continue;
            return errno ? errno : EIO;
        }
        if (r == 0)
            return -1;
        p += r;
        n -= (size_t)r;
        off += (uint64_t)r;
    }
    return 0;
}

void gdt_laz_table_free(gdt_laz_table *t)
{
    free(t->start);
    free(t->bytes);
    free(t->count);
    memset(t, 0, sizeof *t);
}

static gdt_status io_fail(gdt_error *err, const char *path, int e)
{
    return gdt_error_set(err, GDT_EIO, 4390, "%s: reading the LAZ chunk table: %s", path,
                         strerror(e));
}

/* No usable table: fine for fixed chunks (the caller scans them), an error
 * for variable ones. */
static gdt_status no_table(gdt_laz_table *t, const gdt_laz_vlr *vlr, const char *path,
                           uint64_t data_end, const char *why, gdt_log *log, gdt_error *err)
{
    if (vlr->chunk_size == GDT_LAZ_VARIABLE_CHUNKS)
        return gdt_error_set(err, GDT_EINPUT, 3910,
                             "%s: LAZ chunk table %s; the file has chunks of variable size, "
                             "whose point counts are only in the table",
                             path, why);
    gdt_log_warn(log, 3911, "%s: LAZ chunk table %s; reading the chunks in order", path, why);
    t->present = 0;
    t->data_end = data_end;
    return GDT_OK;
}

gdt_status gdt_laz_table_read(gdt_laz_table *t, const gdt_laz_vlr *vlr, int fd,
                              const char *path, uint64_t points_start, uint64_t file_end,
                              uint64_t point_count, gdt_log *log, gdt_error *err)
{
    unsigned char word[8], *buf = NULL;
    uint64_t fsize, table_off, chunks0 = points_start + 8, data_end, need, ntab, navail;
    int64_t off;
    struct stat sb;
    int e;
    gdt_status st = GDT_OK;
    gdt_laz_intdec ic;
    gdt_laz_dec d;
    int variable = vlr->chunk_size == GDT_LAZ_VARIABLE_CHUNKS;

    memset(t, 0, sizeof *t);
    memset(&ic, 0, sizeof ic);
    t->present = 1;
    t->data_end = points_start;
    if (point_count == 0)
        return GDT_OK;
    if (fstat(fd, &sb) != 0)
        return io_fail(err, path, errno);
    fsize = (uint64_t)sb.st_size;
    if (chunks0 > file_end || file_end > fsize)
        return gdt_error_set(err, GDT_EINPUT, 3912,
                             "%s: LAZ point data of %" PRIu64 " points has no room for its "
                             "chunk table offset",
                             path, point_count);
    if ((e = read_at(fd, word, 8, points_start)) != 0)
        return e < 0 ? gdt_error_set(err, GDT_EINPUT, 3912, "%s: LAZ point data truncated", path)
                     : io_fail(err, path, e);
    off = (int64_t)gdt_le_get_u64(word);
    if (off == -1) {
        /* Written by a writer that could not seek back. */
        if (fsize < chunks0 + 8 || (e = read_at(fd, word, 8, fsize - 8)) != 0) {
            if (e > 0)
                return io_fail(err, path, e);
            return no_table(t, vlr, path, file_end, "is missing (offset -1, no trailer)", log,
                            err);
        }
        off = (int64_t)gdt_le_get_u64(word);
    }
    if (off < 0 || (uint64_t)off < chunks0 || (uint64_t)off + 8 > fsize)
        return no_table(t, vlr, path, file_end, "is missing (its offset is outside the file)",
                        log, err);
    table_off = (uint64_t)off;
    data_end = table_off < file_end ? table_off : file_end;
    if ((e = read_at(fd, word, 8, table_off)) != 0)
        return io_fail(err, path, e);
    if (gdt_le_get_u32(word) != 0)
        return no_table(t, vlr, path, data_end, "has an unknown version", log, err);
    ntab = gdt_le_get_u32(word + 4);

    /* The chunks the header's count needs; a table with more is cut. */
    need = variable ? ntab : (point_count - 1) / vlr->chunk_size + 1;
    if (!variable && ntab < need)
        return gdt_error_set(err, GDT_EINPUT, 3913,
                             "%s: LAZ chunk table lists %" PRIu64 " chunks of %u points, "
                             "fewer than the %" PRIu64 " points of the header need",
                             path, ntab, (unsigned)vlr->chunk_size, point_count);
    if (need > point_count)
        need = point_count; /* every chunk holds at least one point */
    if (need > (data_end - chunks0) / LAZ_MIN_CHUNK) {
        /* Each chunk holds at least its raw first record, so this many
         * cannot fit: refuse before allocating for them. */
        if (!variable)
            return gdt_error_set(err, GDT_EINPUT, 3913,
                                 "%s: LAZ point data of %" PRIu64 " bytes cannot hold the %" PRIu64
                                 " chunks of %u points the header's %" PRIu64 " points need",
                                 path, data_end - chunks0, need, (unsigned)vlr->chunk_size,
                                 point_count);
        need = (data_end - chunks0) / LAZ_MIN_CHUNK;
    }
    if (ntab == 0)
        return gdt_error_set(err, GDT_EINPUT, 3913,
                             "%s: LAZ chunk table lists no chunk for %" PRIu64 " points", path,
                             point_count);

    /* A coded entry takes at most about 11 bytes; read no more than that
     * from the file. */
    navail = fsize - table_off - 8;
    if (navail > 16 * need + 16)
        navail = 16 * need + 16;
    t->start = malloc((need ? need : 1) * sizeof *t->start);
    t->bytes = malloc((need ? need : 1) * sizeof *t->bytes);
    t->count = malloc((need ? need : 1) * sizeof *t->count);
    buf = malloc(navail ? navail : 1);
    if (!t->start || !t->bytes || !t->count || !buf) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto fail;
    }
    if ((e = read_at(fd, buf, navail, table_off + 8)) != 0) {
        st = e < 0 ? gdt_error_set(err, GDT_EINPUT, 3912, "%s: LAZ chunk table truncated", path)
                   : io_fail(err, path, e);
        goto fail;
    }
    if ((st = gdt_laz_intdec_new(&ic, 32, 2, 8, 0, err)) != GDT_OK)
        goto fail;
    gdt_laz_dec_init(&d, buf, navail);
    {
        uint64_t pos = chunks0, points = 0;
        uint32_t prev_count = 0, prev_bytes = 0;
        uint64_t i;
        for (i = 0; i < need && points < point_count; i++) {
            uint64_t cnt;
            if (variable) {
                prev_count = (uint32_t)gdt_laz_intdec_decode(&ic, &d, gdt_laz_i32(prev_count), 0);
                cnt = prev_count;
            } else {
                cnt = vlr->chunk_size;
            }
            prev_bytes = (uint32_t)gdt_laz_intdec_decode(&ic, &d, gdt_laz_i32(prev_bytes), 1);
            if (d.bad)
                break;
            if (cnt == 0) {
                st = gdt_error_set(err, GDT_EINPUT, 3914,
                                   "%s: LAZ chunk table: chunk %" PRIu64 " holds no point", path,
                                   i);
                goto fail;
            }
            if (prev_bytes < LAZ_MIN_CHUNK) {
                st = gdt_error_set(err, GDT_EINPUT, 3915,
                                   "%s: LAZ chunk table: chunk %" PRIu64 " of %u bytes cannot "
                                   "hold its first record",
                                   path, i, (unsigned)prev_bytes);
                goto fail;
            }
            if (pos + prev_bytes > data_end) {
                st = gdt_error_set(err, GDT_EINPUT, 3915,
                                   "%s: LAZ chunk table: chunk %" PRIu64 " of %u bytes at %" PRIu64
                                   " passes the end of the point data (%" PRIu64 ")",
                                   path, i, (unsigned)prev_bytes, pos, data_end);
                goto fail;
            }
            if (cnt > point_count - points) {
                /* The last chunk of fixed size is short; a variable one
                 * that holds more than the header counts is cut. */
                if (variable)
                    gdt_log_warn(log, 3917,
                                 "%s: LAZ chunk table: chunk %" PRIu64 " holds %" PRIu64
                                 " points, past the header's %" PRIu64 "; reading %" PRIu64,
                                 path, i, cnt, point_count, point_count - points);
                cnt = point_count - points;
            }
            t->start[i] = pos;
            t->bytes[i] = prev_bytes;
            t->count[i] = cnt;
            pos += prev_bytes;
            points += cnt;
        }
        if (d.bad) {
            gdt_laz_intdec_free(&ic);
            free(buf);
            gdt_laz_table_free(t);
            return no_table(t, vlr, path, data_end, "is corrupt", log, err);
        }
        if (points < point_count) {
            st = gdt_error_set(err, GDT_EINPUT, 3913,
                               "%s: LAZ chunk table: %" PRIu64 " chunks hold %" PRIu64
                               " points, fewer than the header's %" PRIu64,
                               path, i, points, point_count);
            goto fail;
        }
        if (i < ntab)
            gdt_log_warn(log, 3916,
                         "%s: LAZ chunk table lists %" PRIu64 " chunks, the header's %" PRIu64
                         " points fill %" PRIu64 "; the others are ignored",
                         path, ntab, point_count, i);
        t->nchunks = i;
        t->data_end = pos;
    }
    gdt_laz_intdec_free(&ic);
    free(buf);
    return GDT_OK;
fail:
    gdt_laz_intdec_free(&ic);
    free(buf);
    gdt_laz_table_free(t);
    return st;
}
