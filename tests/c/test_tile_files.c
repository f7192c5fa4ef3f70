/* test_tile_files — the direct I/O of the tile files (tiler/tiled_files.c
 * over io/direct_io.c).
 *
 *   test_tile_files WORKDIR
 *
 * Files of lengths around the block size and the reader's buffer are
 * written with tr_write_direct, starting in direct mode and in buffered
 * mode, and read back with tr_dread in pieces of many sizes (one byte, a
 * 12-byte record, odd sizes, more than the buffer), by a reader in direct
 * mode, one in buffered mode (as on a file system that refuses O_DIRECT)
 * and one that leaves direct mode mid-file; every byte must come back, the
 * reader must report the end exactly, and the writer must leave direct
 * mode after the tail.  A reader of a missing file fails with 4805.
 * tr_write_atomic writes the same bytes directly and through the page
 * cache.  The removal of a job's tile files in shares (tr_remove_tile_share,
 * one per MPI rank, each unlinking on several threads) removes each tile
 * file in exactly one share, every share some, and nothing else.
 */
#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

#include "gdt_check.h"
#include "private/stages.h"
#include "private/tiled_files.h"

static gdt_checks T = {0, 0};

#define CHECK(cond, ...) GDT_CHECK(&T, cond, __VA_ARGS__)

/* len random bytes in *buf (aligned for direct I/O) and len + 1 bytes of
 * room in *back; 0 (both NULL) when memory runs out, a failed check. */
static int random_buffers(size_t len, uint64_t *seed, unsigned char **buf, unsigned char **back)
{
    void *aligned = NULL;
    *buf = NULL;
    *back = malloc(len + 1);
    if (*back != NULL && posix_memalign(&aligned, GDT_DIO_BLOCK, len + 1) == 0)
        *buf = aligned;
    if (*buf == NULL) {
        CHECK(0, "%s", "out of memory");
        free(*back);
        *back = NULL;
        return 0;
    }
    for (size_t i = 0; i < len; i++)
        (*buf)[i] = (unsigned char)gdt_splitmix64(seed);
    return 1;
}

static void one_file(const char *dir, size_t len, int start_direct, uint64_t *seed)
{
    char path[4200];
    unsigned char *buf, *back;
    static const size_t pieces[] = {1, 12, 13, 4095, 4096, 4097, 65536 * 12, 3 << 20};
    int direct = 0, fd;
    gdt_error err;

    gdt_error_clear(&err);
    snprintf(path, sizeof path, "%s/f_%zu_%d", dir, len, start_direct);
    if (!random_buffers(len, seed, &buf, &back))
        return;
    fd = start_direct ? gdt_dio_create(path, 0644, &direct) : -1;
    if (!start_direct)
        fd = creat(path, 0644);
    CHECK(fd >= 0, "%s: cannot create: %s", path, strerror(errno));
    if (fd >= 0) {
        CHECK(tr_write_direct(fd, &direct, buf, len, path, &err) == GDT_OK, "%s", err.msg);
        CHECK(direct == 0, "len %zu: the writer is still in direct mode", len);
        close(fd);
    }
    /* mode 0: the reader as opened (direct where the file system allows
     * it); 1: buffered from the start, as on a file system that refuses
     * O_DIRECT; 2: leaving direct mode after the first piece; 3: opened
     * for a file read through the page cache */
    for (int mode = 0; mode < 4; mode++) {
        for (size_t p = 0; p < sizeof pieces / sizeof pieces[0]; p++) {
            tr_dread r;
            size_t at = 0, got = 0;
            gdt_status st = tr_dread_open(&r, path, TR_DREAD_BYTES, mode == 3, &err);
            CHECK(st == GDT_OK, "%s", err.msg);
            if (st != GDT_OK)
                continue;
            if (pieces[p] < 12 && len > 65536) {
                tr_dread_close(&r);
                continue; /* byte by byte only on the small files */
            }
            if (mode == 0 && p == 0 && len == 0 && !r.direct)
                printf("note: this file system refuses O_DIRECT; the reader is buffered\n");
            if (mode == 1 && r.direct)
                CHECK(gdt_dio_end(r.fd, &r.direct) == 0, "%s", "cannot leave direct mode");
            if (mode == 3)
                CHECK(!r.direct, "len %zu: a reader opened for the page cache is direct", len);
            do {
                size_t want = pieces[p] < len + 1 - at ? pieces[p] : len + 1 - at;
                st = tr_dread_bytes(&r, back + at, want, &got, &err);
                at += got;
                if (mode == 2 && r.direct)
                    CHECK(gdt_dio_end(r.fd, &r.direct) == 0, "%s", "cannot leave direct mode");
                if (got < want)
                    break;
            } while (st == GDT_OK && at <= len);
            CHECK(st == GDT_OK, "%s", err.msg);
            CHECK(at == len, "len %zu, mode %d, pieces of %zu: read %zu bytes", len, mode,
                  pieces[p], at);
            CHECK(memcmp(back, buf, len) == 0, "len %zu, mode %d, pieces of %zu: bytes differ",
                  len, mode, pieces[p]);
            st = tr_dread_bytes(&r, back, 1, &got, &err);
            CHECK(st == GDT_OK && got == 0, "len %zu, mode %d: a byte after the end", len, mode);
            CHECK(mode == 0 || !r.direct, "len %zu, mode %d: still direct", len, mode);
            tr_dread_close(&r);
        }
    }
    {
        struct stat sb;
        CHECK(stat(path, &sb) == 0 && (size_t)sb.st_size == len, "len %zu: file size %lld",
              len, (long long)sb.st_size);
    }
    unlink(path);
    free(buf);
    free(back);
}

/* tr_write_atomic, direct or through the page cache, read back both ways:
 * the same bytes at the final name, no temporary left. */
static void atomic_file(const char *dir, size_t len, uint64_t *seed)
{
    char path[4200], tmp[4300];
    unsigned char *buf, *back;
    gdt_error err;
    snprintf(path, sizeof path, "%s/atomic.tri", dir);
    snprintf(tmp, sizeof tmp, "%s.tmp", path);
    if (!random_buffers(len, seed, &buf, &back))
        return;
    for (int cached = 0; cached < 2; cached++) {
        gdt_error_clear(&err);
        CHECK(tr_write_atomic(path, buf, len, 1, cached, &err) == GDT_OK, "%s", err.msg);
        CHECK(access(tmp, F_OK) != 0, "len %zu, cached %d: the temporary is left", len, cached);
        for (int rc = 0; rc < 2; rc++) {
            tr_dread r;
            size_t got = 0;
            gdt_status st = tr_dread_open(&r, path, TR_DREAD_BYTES, rc, &err);
            CHECK(st == GDT_OK, "%s", err.msg);
            if (st != GDT_OK)
                continue;
            st = tr_dread_bytes(&r, back, len + 1, &got, &err);
            CHECK(st == GDT_OK && got == len && memcmp(back, buf, len) == 0,
                  "len %zu, written cached %d, read cached %d: %zu bytes back", len, cached, rc,
                  got);
            tr_dread_close(&r);
        }
        unlink(path);
    }
    free(buf);
    free(back);
}

/* The name of the i-th file of a job's tiles/ in removal_shares. */
static void job_file(char *buf, size_t n, int i)
{
    switch (i % 4) {
    case 0: snprintf(buf, n, "tile_%d_%d.pts", i / 4, i % 7); break;
    case 1: snprintf(buf, n, "tile_%d_%d.tri", i / 4, i % 7); break;
    case 2: snprintf(buf, n, "bucket_%d_%d", i / 4, i % 7); break;
    default: snprintf(buf, n, "merge_%d_%d.x", i / 4, i % 7); break;
    }
}

/* tr_remove_tile_share in parts shares over a directory of tile files and
 * a file of the user's. */
static void removal_shares(const char *dir, int parts)
{
    enum { NFILES = 120 };
    char tiles[4200], name[4400], mine[4400];
    int present[NFILES], removed_by[NFILES];
    snprintf(tiles, sizeof tiles, "%s/tiles_%d", dir, parts);
    CHECK(mkdir(tiles, 0755) == 0, "%s: %s", tiles, strerror(errno));
    for (int i = 0; i < NFILES; i++) {
        int fd;
        char base[64];
        job_file(base, sizeof base, i);
        snprintf(name, sizeof name, "%s/%s", tiles, base);
        fd = creat(name, 0644);
        CHECK(fd >= 0, "%s: %s", name, strerror(errno));
        if (fd >= 0)
            close(fd);
        present[i] = 1;
        removed_by[i] = -1;
    }
    snprintf(mine, sizeof mine, "%s/notes.txt", tiles);
    {
        int fd = creat(mine, 0644);
        if (fd >= 0)
            close(fd);
    }
    for (int p = 0; p < parts; p++) {
        int n = 0;
        tr_remove_tile_share(tiles, p, parts);
        for (int i = 0; i < NFILES; i++) {
            char base[64];
            job_file(base, sizeof base, i);
            snprintf(name, sizeof name, "%s/%s", tiles, base);
            if (present[i] && access(name, F_OK) != 0) {
                present[i] = 0;
                removed_by[i] = p;
                n++;
            }
        }
        CHECK(parts == 1 || n > 0, "share %d of %d removed nothing", p, parts);
        CHECK(parts > 1 || n == NFILES, "one share removed %d of %d files", n, NFILES);
        /* a share run again finds nothing of its own */
        tr_remove_tile_share(tiles, p, parts);
    }
    for (int i = 0; i < NFILES; i++)
        CHECK(removed_by[i] >= 0, "%d shares: file %d was never removed", parts, i);
    CHECK(access(mine, F_OK) == 0, "%d shares: a file not of the job was removed", parts);
    unlink(mine);
    rmdir(tiles);
}

int main(int argc, char **argv)
{
    static const size_t lens[] = {0,    1,     64,   4095,  4096,          4097,
                                  8191, 8192,  12289, (1 << 20) - 1, 1 << 20, (1 << 20) + 1,
                                  (3 << 20) + 4096 + 77};
    char dir[4096];
    uint64_t seed = 7;
    tr_dread r;
    gdt_error err;

    if (argc != 2) {
        fprintf(stderr, "usage: test_tile_files WORKDIR\n");
        return 2;
    }
    snprintf(dir, sizeof dir, "%s/tile_files.%ld", argv[1], (long)getpid());
    if (mkdir(dir, 0755) != 0) {
        fprintf(stderr, "%s: %s\n", dir, strerror(errno));
        return 1;
    }
    for (size_t i = 0; i < sizeof lens / sizeof lens[0]; i++)
        for (int d = 0; d < 2; d++)
            one_file(dir, lens[i], d, &seed);
    for (size_t i = 0; i < sizeof lens / sizeof lens[0]; i++)
        atomic_file(dir, lens[i], &seed);
    for (int parts = 1; parts <= 4; parts++)
        removal_shares(dir, parts);
    gdt_error_clear(&err);
    for (int cached = 0; cached < 2; cached++) {
        gdt_error_clear(&err);
        CHECK(tr_dread_open(&r, "/nonexistent/tile.tri", TR_DREAD_BYTES, cached, &err) ==
                      GDT_EIO &&
                  err.code == 4805,
              "missing file (cached %d): status %d code %d", cached, (int)err.status, err.code);
        tr_dread_close(&r);
    }
    rmdir(dir);
    return gdt_check_finish(&T, "test_tile_files");
}
