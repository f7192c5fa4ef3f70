/* laz_decode — decodes every chunk of a LAZ file with the LASzip decoder of
 * io/private/laz_chunk.h and writes the uncompressed point records to
 * stdout, for comparison with other decoders.
 *
 *   laz_decode [--need all|xyz,class,flags] FILE
 *
 * It reads just enough of the LAS header and VLRs to find the LASzip VLR and
 * the point data.  With a chunk table every chunk is decoded from its own
 * bytes and must use them exactly; without one the chunks are read in
 * order, each starting where the previous one ended.  The header's point
 * count wins over the table's.  Exit status: the
 * gdt_status of the first failure (its message on stderr), else 0.
 */
#include <errno.h>
#include <fcntl.h>
#include <inttypes.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_error.h"
#include "private/bytes.h"
#include "private/laz_chunk.h"

#define BATCH 4096 /* records per gdt_laz_chunk_read call */

typedef struct lasfile {
    unsigned char *buf;
    uint64_t size;
    unsigned point_format, record_length;
    uint64_t points_start, point_count, file_end;
    const unsigned char *vlr;
    size_t vlr_len;
} lasfile;

static gdt_status load(lasfile *f, int fd, const char *path, gdt_error *err)
{
    struct stat sb;
    unsigned header_size, nvlr, minor;
    uint64_t pos;

    if (fstat(fd, &sb) != 0)
        return gdt_error_set(err, GDT_EIO, 4391, "%s: %s", path, strerror(errno));
    f->size = (uint64_t)sb.st_size;
    f->buf = malloc(f->size ? f->size : 1);
    if (!f->buf)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    for (uint64_t got = 0; got < f->size;) {
        ssize_t r = pread(fd, f->buf + got, f->size - got, (off_t)got);
        if (r <= 0)
            return gdt_error_set(err, GDT_EIO, 4391, "%s: %s", path,
                                 r < 0 ? strerror(errno) : "short read");
        got += (uint64_t)r;
    }
    if (f->size < 227 || memcmp(f->buf, "LASF", 4) != 0)
        return gdt_error_set(err, GDT_EINPUT, 3930, "%s: not a LAS file", path);
    minor = f->buf[25];
    header_size = gdt_le_get_u16(f->buf + 94);
    f->points_start = gdt_le_get_u32(f->buf + 96);
    nvlr = gdt_le_get_u32(f->buf + 100);
    f->point_format = f->buf[104] & 0x3F;
    f->record_length = gdt_le_get_u16(f->buf + 105);
    f->point_count = gdt_le_get_u32(f->buf + 107);
    f->file_end = f->size;
    if (minor >= 4 && header_size >= 375 && f->size >= 375) {
        uint64_t evlr = gdt_le_get_u64(f->buf + 235);
        uint64_t n64 = gdt_le_get_u64(f->buf + 247);
        if (gdt_le_get_u32(f->buf + 243) > 0 && evlr >= f->points_start && evlr < f->file_end)
            f->file_end = evlr;
        if (f->point_count == 0)
            f->point_count = n64;
    }
    if (f->points_start > f->size || header_size > f->points_start)
        return gdt_error_set(err, GDT_EINPUT, 3930, "%s: bad point data offset", path);
    pos = header_size;
    for (unsigned i = 0; i < nvlr; i++) {
        unsigned len;
        if (pos + 54 > f->points_start)
            return gdt_error_set(err, GDT_EINPUT, 3930, "%s: VLR %u passes the point data",
                                 path, i);
        len = gdt_le_get_u16(f->buf + pos + 20);
        if (pos + 54 + len > f->points_start)
            return gdt_error_set(err, GDT_EINPUT, 3930, "%s: VLR %u passes the point data",
                                 path, i);
        if (memcmp(f->buf + pos + 2, "laszip encoded", 15) == 0 &&
            gdt_le_get_u16(f->buf + pos + 18) == 22204) {
            f->vlr = f->buf + pos + 54;
            f->vlr_len = len;
        }
        pos += 54 + (uint64_t)len;
    }
    if (!f->vlr)
        return gdt_error_set(err, GDT_EINPUT, 3930, "%s: no LASzip VLR", path);
    return GDT_OK;
}

static gdt_status emit(const unsigned char *rec, size_t n, gdt_error *err)
{
    if (n && fwrite(rec, 1, n, stdout) != n)
        return gdt_error_set(err, GDT_EIO, 4391, "writing the records: %s", strerror(errno));
    return GDT_OK;
}

/* Decodes npoints from data[0 .. avail) as chunk ci and writes them. */
static gdt_status one_chunk(gdt_laz_chunk *c, const lasfile *f, const char *path,
                            const unsigned char *data, size_t avail, uint64_t npoints,
                            uint64_t ci, unsigned char *rec, gdt_error *err)
{
    gdt_status st = gdt_laz_chunk_start(c, data, avail, npoints, path, ci, err);
    for (uint64_t done = 0; st == GDT_OK && done < npoints;) {
        size_t n = npoints - done < BATCH ? (size_t)(npoints - done) : BATCH;
        if ((st = gdt_laz_chunk_read(c, rec, n, err)) == GDT_OK)
            st = emit(rec, n * f->record_length, err);
        done += n;
    }
    return st;
}

static unsigned parse_need(const char *s)
{
    unsigned need = 0;
    char buf[128], *tok, *save = NULL;
    if (strcmp(s, "all") == 0)
        return GDT_LAZ_NEED_ALL;
    snprintf(buf, sizeof buf, "%s", s);
    for (tok = strtok_r(buf, ",", &save); tok; tok = strtok_r(NULL, ",", &save)) {
        if (strcmp(tok, "xyz") == 0)
            need |= GDT_LAZ_NEED_XYZ;
        else if (strcmp(tok, "class") == 0)
            need |= GDT_LAZ_NEED_CLASS;
        else if (strcmp(tok, "flags") == 0)
            need |= GDT_LAZ_NEED_FLAGS;
        else
            return 0;
    }
    return need;
}

int main(int argc, char **argv)
{
    gdt_error err;
    gdt_log log;
    gdt_laz_vlr vlr;
    gdt_laz_table tab;
    gdt_laz_chunk *c = NULL;
    lasfile f;
    unsigned need = GDT_LAZ_NEED_ALL;
    unsigned char *rec = NULL;
    const char *path;
    gdt_status st;
    int fd, argi = 1;

    gdt_error_clear(&err);
    gdt_log_init(&log, 0);
    memset(&f, 0, sizeof f);
    memset(&tab, 0, sizeof tab);
    if (argc == 4 && strcmp(argv[1], "--need") == 0) {
        need = parse_need(argv[2]);
        argi = 3;
    }
    if (argi != argc - 1 || need == 0) {
        fprintf(stderr, "usage: laz_decode [--need all|xyz,class,flags] FILE\n");
        return GDT_EUSAGE;
    }
    path = argv[argi];
    fd = open(path, O_RDONLY);
    if (fd < 0) {
        gdt_error_set(&err, GDT_EIO, 4391, "%s: %s", path, strerror(errno));
        gdt_error_print(&err, stderr);
        return GDT_EIO;
    }
    if ((st = load(&f, fd, path, &err)) != GDT_OK ||
        (st = gdt_laz_vlr_parse(path, f.vlr, f.vlr_len, f.point_format, f.record_length, &vlr,
                                &err)) != GDT_OK ||
        (st = gdt_laz_table_read(&tab, &vlr, fd, path, f.points_start, f.file_end,
                                 f.point_count, &log, &err)) != GDT_OK ||
        (st = gdt_laz_chunk_new(&c, &vlr, f.record_length, need, &err)) != GDT_OK)
        goto done;
    rec = malloc((size_t)BATCH * f.record_length);
    if (!rec) {
        st = gdt_error_set(&err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    if (tab.present) {
        for (uint64_t i = 0; i < tab.nchunks; i++) {
            if ((st = one_chunk(c, &f, path, f.buf + tab.start[i], tab.bytes[i], tab.count[i], i,
                                rec, &err)) != GDT_OK)
                goto done;
            /* A chunk must use its bytes exactly; the last one may hold
             * more points than the header's count lets us read. */
            if (i + 1 < tab.nchunks ? gdt_laz_chunk_used(c) != tab.bytes[i]
                                    : gdt_laz_chunk_used(c) > tab.bytes[i]) {
                st = gdt_error_set(&err, GDT_EINPUT, 3931,
                                   "%s: LAZ chunk %" PRIu64 " used %zu of its %" PRIu64 " bytes",
                                   path, i, gdt_laz_chunk_used(c), tab.bytes[i]);
                goto done;
            }
        }
    } else {
        uint64_t pos = f.points_start + 8, left = f.point_count;
        for (uint64_t i = 0; left > 0; i++) {
            uint64_t n = left < vlr.chunk_size ? left : vlr.chunk_size;
            if (pos >= tab.data_end) {
                st = gdt_error_set(&err, GDT_EINPUT, 3931,
                                   "%s: LAZ point data ends before chunk %" PRIu64, path, i);
                goto done;
            }
            if ((st = one_chunk(c, &f, path, f.buf + pos, (size_t)(tab.data_end - pos), n, i,
                                rec, &err)) != GDT_OK)
                goto done;
            pos += gdt_laz_chunk_used(c);
            left -= n;
        }
    }
    if (fflush(stdout) != 0)
        st = gdt_error_set(&err, GDT_EIO, 4391, "writing the records: %s", strerror(errno));
done:
    if (st != GDT_OK)
        gdt_error_print(&err, stderr);
    gdt_laz_chunk_free(c);
    gdt_laz_table_free(&tab);
    free(rec);
    free(f.buf);
    close(fd);
    return st;
}
