/* replay.c — see replay.h.
 *
 * File layout: records of REPLAY_REC bytes, little-endian: int32 X, Y, Z,
 * then cls, ret, nret, flags; input i occupies [first[i], first[i] + count[i])
 * records.  Writes go through one buffer of REPLAY_BUF bytes; reads
 * through the same buffer (a cloud never writes and reads at once).
 */
#define _GNU_SOURCE 1 /* O_TMPFILE, mkostemp */
#include "replay.h"

#include "bytes.h"
#include "fd_io.h"
#include "gdt_grow.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define REPLAY_REC 16u
#define REPLAY_BUF ((size_t)1 << 20)

typedef struct replay_range {
    uint64_t first, count;
    uint64_t lo, hi;          /* the input's records it holds: [lo, hi) */
    int complete;
} replay_range;

struct gdt_replay {
    int fd;
    unsigned char *buf;
    size_t buf_len;           /* bytes buffered (writing) or held (reading) */
    size_t buf_pos;           /* reading: next byte of buf */
    replay_range *in;         /* per input, grown as inputs begin */
    size_t nin, cap;
    size_t writing;           /* input being written, or SIZE_MAX */
    uint64_t end;             /* records in the file */
    char failed[160];         /* "" while the replay works */
    /* reading */
    size_t reading;
    uint64_t next, stop;      /* record indices */
    double scale[3], offset[3];
};

gdt_status gdt_replay_open(gdt_replay **out, const char *dir, gdt_error *err)
{
    gdt_replay *r = calloc(1, sizeof *r);
    *out = NULL;
    if (r == NULL || (r->buf = malloc(REPLAY_BUF)) == NULL) {
        free(r);
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    }
    r->writing = r->reading = SIZE_MAX;
#ifdef O_TMPFILE
    r->fd = open(dir, O_TMPFILE | O_RDWR | O_CLOEXEC, 0600);
#else
    r->fd = -1;
#endif
    if (r->fd < 0) {
        /* No O_TMPFILE on this file system: a named file, unlinked at once. */
        size_t len = strlen(dir) + 32;
        char *tmpl = malloc(len);
        if (tmpl != NULL) {
            snprintf(tmpl, len, "%s/replay-XXXXXX", dir);
            r->fd = mkostemp(tmpl, O_CLOEXEC);
            if (r->fd >= 0)
                unlink(tmpl);
            free(tmpl);
        }
    }
    if (r->fd < 0) {
        int e = errno;
        free(r->buf);
        free(r);
        return gdt_error_set(err, GDT_EIO, 4601,
                             "cannot create a temporary file in %s for decoded points: %s", dir,
                             strerror(e));
    }
    *out = r;
    return GDT_OK;
}

static void replay_fail(gdt_replay *r, const char *what, int e)
{
    if (r->failed[0] == '\0')
        snprintf(r->failed, sizeof r->failed, "%s: %s", what, strerror(e));
    if (r->writing != SIZE_MAX)
        r->in[r->writing].count = 0;
    r->writing = SIZE_MAX;
    r->buf_len = 0;
}

static void replay_flush(gdt_replay *r)
{
    if (r->buf_len == 0)
        return;
    int e = gdt_fd_write_all(r->fd, r->buf, r->buf_len, -1);
    if (e != 0) {
        replay_fail(r, "writing decoded points", e);
        return;
    }
    r->buf_len = 0;
}

void gdt_replay_begin(gdt_replay *r, size_t input, uint64_t lo, uint64_t hi)
{
    if (r->failed[0] != '\0' || r->writing != SIZE_MAX || r->reading != SIZE_MAX)
        return;
    if (input >= r->nin) {
        size_t old = r->cap;
        if (gdt_grow(&r->in, &r->cap, input + 1, sizeof *r->in, 8) != 0) {
            replay_fail(r, "recording an input", ENOMEM);
            return;
        }
        memset(r->in + old, 0, (r->cap - old) * sizeof *r->in);
        r->nin = input + 1;
    }
    if (r->in[input].complete || r->in[input].count != 0)
        return; /* begun before: never write an input twice */
    r->in[input].first = r->end;
    r->in[input].count = 0;
    r->in[input].lo = lo;
    r->in[input].hi = hi;
    r->writing = input;
}

void gdt_replay_append(gdt_replay *r, const gdt_src_point *p, size_t n)
{
    if (r->writing == SIZE_MAX)
        return;
    for (size_t i = 0; i < n; i++) {
        if (REPLAY_BUF - r->buf_len < REPLAY_REC) {
            replay_flush(r);
            if (r->writing == SIZE_MAX)
                return;
        }
        unsigned char *b = r->buf + r->buf_len;
        gdt_le_put_u32(b, (uint32_t)p[i].X);
        gdt_le_put_u32(b + 4, (uint32_t)p[i].Y);
        gdt_le_put_u32(b + 8, (uint32_t)p[i].Z);
        b[12] = p[i].cls;
        b[13] = p[i].ret;
        b[14] = p[i].nret;
        b[15] = p[i].flags;
        r->buf_len += REPLAY_REC;
    }
    r->in[r->writing].count += n;
    r->end += n;
}

void gdt_replay_end(gdt_replay *r)
{
    if (r->writing == SIZE_MAX)
        return;
    replay_flush(r);
    if (r->writing == SIZE_MAX)
        return;
    r->in[r->writing].complete = 1;
    r->writing = SIZE_MAX;
}

void gdt_replay_abandon(gdt_replay *r)
{
    if (r->writing == SIZE_MAX)
        return;
    /* The records already written stay in the file, unused: later inputs
     * start after them (end is not moved back), so ranges never overlap. */
    replay_flush(r);
    if (r->writing != SIZE_MAX)
        r->in[r->writing].count = 0;
    r->writing = SIZE_MAX;
}

int gdt_replay_has(const gdt_replay *r, size_t input, uint64_t lo, uint64_t hi)
{
    return r != NULL && input < r->nin && r->in[input].complete && r->in[input].lo == lo &&
           r->in[input].hi == hi;
}

const char *gdt_replay_failed(const gdt_replay *r)
{
    return r != NULL && r->failed[0] != '\0' ? r->failed : NULL;
}

gdt_status gdt_replay_start(gdt_replay *r, size_t input, const double scale[3],
                            const double offset[3], gdt_error *err)
{
    if (input >= r->nin || !r->in[input].complete || r->writing != SIZE_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7601,
                             "decoded points of input %zu are not available", input + 1);
    r->reading = input;
    r->next = r->in[input].first;
    r->stop = r->in[input].first + r->in[input].count;
    r->buf_len = r->buf_pos = 0;
    memcpy(r->scale, scale, sizeof r->scale);
    memcpy(r->offset, offset, sizeof r->offset);
    return GDT_OK;
}

gdt_status gdt_replay_read(gdt_replay *r, gdt_src_point *buf, size_t cap, size_t *n,
                           gdt_error *err)
{
    *n = 0;
    if (r->reading == SIZE_MAX)
        return gdt_error_set(err, GDT_EINTERNAL, 7601, "no decoded input is being read");
    while (*n < cap && r->next < r->stop) {
        if (r->buf_pos == r->buf_len) {
            uint64_t left = (r->stop - r->next) * REPLAY_REC;
            size_t want = left < REPLAY_BUF ? (size_t)left : REPLAY_BUF;
            ssize_t got = pread(r->fd, r->buf, want, (off_t)(r->next * REPLAY_REC));
            if (got < 0 && errno == EINTR)
                continue;
            if (got < 0)
                return gdt_error_set(err, GDT_EIO, 4602,
                                     "cannot read back decoded points (temporary file): %s",
                                     strerror(errno));
            if (got < (ssize_t)REPLAY_REC)
                return gdt_error_set(err, GDT_EIO, 4603,
                                     "the temporary file of decoded points is shorter than "
                                     "written");
            r->buf_len = (size_t)got - (size_t)got % REPLAY_REC;
            r->buf_pos = 0;
        }
        const unsigned char *b = r->buf + r->buf_pos;
        gdt_src_point *p = &buf[*n];
        p->X = gdt_le_get_i32(b);
        p->Y = gdt_le_get_i32(b + 4);
        p->Z = gdt_le_get_i32(b + 8);
        p->x = (double)p->X * r->scale[0] + r->offset[0];
        p->y = (double)p->Y * r->scale[1] + r->offset[1];
        p->z = (double)p->Z * r->scale[2] + r->offset[2];
        p->cls = b[12];
        p->ret = b[13];
        p->nret = b[14];
        p->flags = b[15];
        r->buf_pos += REPLAY_REC;
        r->next++;
        (*n)++;
    }
    if (r->next == r->stop && *n == 0)
        r->reading = SIZE_MAX;
    return GDT_OK;
}

void gdt_replay_close(gdt_replay *r)
{
    if (r == NULL)
        return;
    if (r->fd >= 0)
        close(r->fd);
    free(r->buf);
    free(r->in);
    free(r);
}
