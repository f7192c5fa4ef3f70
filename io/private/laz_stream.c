/* See laz_stream.h. */
#include "laz_stream.h"

#include <errno.h>
#include <inttypes.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "bytes.h"
#include "fd_io.h"
#include "gdt_grow.h"

#define LZ_PIECE_DEFAULT ((size_t)1 << 20)

enum {
    SLOT_FREE = 0, /* no chunk: a worker may claim the next one that maps here */
    SLOT_BUSY,     /* a worker is decoding slot.chunk */
    SLOT_READY,    /* slot.chunk is decoded */
    SLOT_FAILED,   /* slot.chunk failed: slot.err says why */
    SLOT_BIG       /* slot.chunk is too large for a slot: the consumer decodes it */
};

typedef struct lz_slot {
    int state;
    uint64_t chunk;
    unsigned char *rec; /* count[chunk] records when READY */
    size_t rec_cap;
    uint64_t oob; /* READY: first record outside the bounds, or UINT64_MAX */
    gdt_error err;
} lz_slot;

typedef struct lz_worker {
    struct gdt_laz_stream *s;
    gdt_laz_chunk *dec;
    unsigned char *cbuf; /* the compressed bytes of the chunk being decoded */
    size_t cbuf_cap;
    pthread_t tid;
} lz_worker;

struct gdt_laz_stream {
    gdt_laz_stream_params p;
    gdt_laz_vlr vlr;
    gdt_laz_table tab;
    uint64_t nchunks;    /* table chunks, or 0 with no table */
    double lo[3], hi[3]; /* header bounds widened by one scale step */

    /* The consumer (the caller's thread). */
    gdt_laz_chunk *dec;
    unsigned char *cbuf;
    size_t cbuf_cap;
    unsigned char *piece;
    size_t piece_points;
    uint64_t chunk;      /* the chunk being handed on, or the next one */
    uint64_t chunk_left; /* records of an incremental chunk still to decode */
    uint64_t chunk_done; /* records of an incremental chunk decoded so far */
    int incremental;     /* the consumer is decoding chunk `chunk` itself */
    uint64_t next_start; /* no table: where chunk `chunk` starts */
    uint64_t delivered;
    int warned;
    gdt_status failed;
    gdt_error first; /* the sticky error */
    lz_slot *held;   /* the slot whose records were handed on last */

    /* The workers; nworkers == 0 until the first read, or when none run. */
    int started;
    unsigned nworkers, nslots; /* threads running; slots (2 per worker allocated) */
    unsigned nw;               /* workers allocated (their decoders and buffers) */
    lz_worker *w;
    lz_slot *slots;
    pthread_mutex_t mu;
    pthread_cond_t cv_work; /* a slot became free, or stop */
    pthread_cond_t cv_done; /* a slot became READY, FAILED or BIG */
    uint64_t next_claim;
    /* gdt_laz_stream_seek: chunks end_chunk .. are never decoded, and the
     * stream ends after record end_rec (the first record of end_chunk);
     * nchunks and point_count without a seek */
    uint64_t end_chunk, end_rec;
    int stop; /* close: workers return */
    int halt; /* a chunk failed: no more claims (the consumer stops there) */
};

static gdt_status lz_oom(gdt_error *err)
{
    return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
}

static uint64_t lz_count(const gdt_laz_stream *s, uint64_t k)
{
    if (s->tab.present)
        return s->tab.count[k];
    /* No table: fixed chunks, the last one holds what remains. */
    uint64_t left = s->p.point_count - k * (uint64_t)s->vlr.chunk_size;
    return left < s->vlr.chunk_size ? left : s->vlr.chunk_size;
}

/* Reads the compressed bytes of chunk k into *buf and starts dec on them.
 * With a table the chunk's bytes are exactly the table's; without one
 * every byte up to the end of the point data may be the chunk's, of which
 * at most gdt_laz_stream_bytes_max are read (a chunk that needs more is
 * corrupt: the decoder says so when it runs out). */
static gdt_status lz_begin(const gdt_laz_stream *s, gdt_laz_chunk *dec, unsigned char **buf,
                           size_t *cap, uint64_t k, uint64_t start, gdt_error *err)
{
    uint64_t count = lz_count(s, k), avail, got64;
    size_t got;

    if (s->tab.present) {
        avail = s->tab.bytes[k];
    } else {
        uint64_t most = gdt_laz_stream_bytes_max(count, s->p.record_length);
        avail = start < s->tab.data_end ? s->tab.data_end - start : 0;
        if (avail > most)
            avail = most;
    }
    if (avail > SIZE_MAX - 1 || gdt_grow(buf, cap, (size_t)avail + 1, 1, 4096) != 0)
        return lz_oom(err);
    int e = gdt_fd_pread_all(s->p.fd, *buf, (size_t)avail, start, &got);
    if (e != 0)
        return gdt_error_set(err, GDT_EIO, 4103,
                             "%s: read error at byte %" PRIu64 " (LAZ chunk %" PRIu64 "): %s",
                             s->p.path, start + got, k, strerror(e));
    got64 = got;
    if (got64 < avail)
        return gdt_error_set(err, GDT_EINPUT, 3970,
                             "%s: file ends at byte %" PRIu64 ", inside LAZ chunk %" PRIu64
                             " (it shrank while being read)",
                             s->p.path, start + got64, k);
    return gdt_laz_chunk_start(dec, *buf, (size_t)avail, count, s->p.path, k, err);
}

/* After every record of chunk k: a table chunk must have used exactly its
 * bytes (another count means the table or the chunk is corrupt). */
static gdt_status lz_end(const gdt_laz_stream *s, const gdt_laz_chunk *dec, uint64_t k,
                         gdt_error *err)
{
    uint64_t used = gdt_laz_chunk_used(dec);
    if (s->tab.present && used != s->tab.bytes[k])
        return gdt_error_set(err, GDT_EINPUT, 3971,
                             "%s: LAZ chunk %" PRIu64 " of %" PRIu64 " decodes from %" PRIu64
                             " bytes but the chunk table gives it %" PRIu64
                             ": the chunk or the table is corrupt",
                             s->p.path, k, s->nchunks, used, s->tab.bytes[k]);
    return GDT_OK;
}

/* Index of the first of n records outside the widened header bounds, or
 * UINT64_MAX. */
static uint64_t lz_out_of_bounds(const gdt_laz_stream *s, const unsigned char *rec, size_t n)
{
    for (size_t i = 0; i < n; i++, rec += s->p.record_length) {
        for (int a = 0; a < 3; a++) {
            double v = (double)gdt_le_get_i32(rec + 4 * a) * s->p.scale[a] + s->p.offset[a];
            if (!(v >= s->lo[a] && v <= s->hi[a]))
                return i;
        }
    }
    return UINT64_MAX;
}

/* The once-per-file warning for record i (0-based in the chunk) of chunk k. */
static void lz_warn_bounds(gdt_laz_stream *s, uint64_t k, uint64_t i)
{
    if (s->warned || i == UINT64_MAX)
        return;
    s->warned = 1;
    gdt_log_warn(s->p.log, 3990,
                 "%s: point %" PRIu64 " of LAZ chunk %" PRIu64
                 " lies outside the header bounds by more than one scale step"
                 " (the chunk may be corrupt, or the header bounds wrong); the file gives"
                 " no further warning of this kind",
                 s->p.path, i, k);
}

/* ---- workers ------------------------------------------------------------- */

/* Decodes chunk k whole into sl (called without the lock; sl is the
 * worker's until it publishes the state). */
static gdt_status lz_decode_slot(lz_worker *w, lz_slot *sl, uint64_t k)
{
    const gdt_laz_stream *s = w->s;
    uint64_t count = s->tab.count[k];
    size_t bytes = (size_t)(count * s->p.record_length);
    gdt_status st;

    gdt_error_clear(&sl->err);
    if (gdt_grow(&sl->rec, &sl->rec_cap, bytes, 1, 4096) != 0)
        return lz_oom(&sl->err);
    st = lz_begin(s, w->dec, &w->cbuf, &w->cbuf_cap, k, s->tab.start[k], &sl->err);
    if (st == GDT_OK)
        st = gdt_laz_chunk_read(w->dec, sl->rec, (size_t)count, &sl->err);
    if (st == GDT_OK)
        st = lz_end(s, w->dec, k, &sl->err);
    if (st == GDT_OK)
        sl->oob = lz_out_of_bounds(s, sl->rec, (size_t)count);
    return st;
}

static void *lz_worker_main(void *arg)
{
    lz_worker *w = arg;
    gdt_laz_stream *s = w->s;

    pthread_mutex_lock(&s->mu);
    while (!s->stop && !s->halt && s->next_claim < s->end_chunk) {
        uint64_t k = s->next_claim;
        lz_slot *sl = &s->slots[k % s->nslots];
        if (sl->state != SLOT_FREE) {
            pthread_cond_wait(&s->cv_work, &s->mu);
            continue;
        }
        s->next_claim++;
        sl->chunk = k;
        if (s->tab.count[k] > GDT_LAZ_STREAM_SLOT_MAX / s->p.record_length) {
            sl->state = SLOT_BIG;
            pthread_cond_broadcast(&s->cv_done);
            continue;
        }
        sl->state = SLOT_BUSY;
        pthread_mutex_unlock(&s->mu);
        gdt_status st = lz_decode_slot(w, sl, k);
        pthread_mutex_lock(&s->mu);
        sl->state = st == GDT_OK ? SLOT_READY : SLOT_FAILED;
        if (st != GDT_OK)
            s->halt = 1;
        pthread_cond_broadcast(&s->cv_done);
    }
    pthread_mutex_unlock(&s->mu);
    return NULL;
}

/* Stops and joins the workers (they finish the chunk in hand). */
static void lz_stop_workers(gdt_laz_stream *s)
{
    if (s->nworkers == 0)
        return;
    pthread_mutex_lock(&s->mu);
    s->stop = 1;
    pthread_cond_broadcast(&s->cv_work);
    pthread_mutex_unlock(&s->mu);
    for (unsigned i = 0; i < s->nworkers; i++)
        pthread_join(s->w[i].tid, NULL);
    s->nworkers = 0;
}

/* Starts the workers on the first read.  None start with threads <= 1, no
 * table or one chunk; when the system refuses threads the ones started
 * (possibly none: the consumer then decodes everything) do the work, so
 * the result never depends on it. */
static gdt_status lz_start_workers(gdt_laz_stream *s, gdt_error *err)
{
    unsigned want;

    s->started = 1;
    if (s->p.threads <= 1 || !s->tab.present || s->end_chunk - s->chunk < 2)
        return GDT_OK;
    want = (unsigned)s->p.threads;
    if (want > s->end_chunk - s->chunk)
        want = (unsigned)(s->end_chunk - s->chunk);
    {
        /* the slots' memory: 2 W times the largest chunk a slot takes */
        uint64_t largest = 0, per = GDT_LAZ_STREAM_SLOT_MAX / s->p.record_length;
        for (uint64_t k = 0; k < s->nchunks; k++)
            if (s->tab.count[k] <= per && s->tab.count[k] > largest)
                largest = s->tab.count[k];
        uint64_t fit = GDT_LAZ_STREAM_SLOTS_TOTAL / (2 * (largest * s->p.record_length + 1));
        if (want > fit)
            want = fit > 0 ? (unsigned)fit : 1;
    }
    s->w = calloc(want, sizeof *s->w);
    s->slots = calloc(2 * (size_t)want, sizeof *s->slots);
    if (s->w == NULL || s->slots == NULL)
        return lz_oom(err);
    s->nslots = 2 * want;
    s->nw = want;
    for (unsigned i = 0; i < want; i++) {
        gdt_status st =
            gdt_laz_chunk_new(&s->w[i].dec, &s->vlr, s->p.record_length, s->p.need, err);
        if (st != GDT_OK)
            return st;
        s->w[i].s = s;
    }
    for (unsigned i = 0; i < want; i++) {
        if (pthread_create(&s->w[i].tid, NULL, lz_worker_main, &s->w[i]) != 0)
            break;
        s->nworkers++;
    }
    return GDT_OK;
}

/* ---- the consumer -------------------------------------------------------- */

/* Makes st (recorded in s->first) sticky and stops the workers. */
static gdt_status lz_fail(gdt_laz_stream *s, gdt_status st)
{
    s->failed = st;
    lz_stop_workers(s);
    return st;
}

/* Waits for chunk k's slot; READY: hands its records on; FAILED: the
 * chunk's error; BIG: *big = 1, the consumer decodes it. */
static gdt_status lz_take_slot(gdt_laz_stream *s, uint64_t k, const unsigned char **recs, size_t *n,
                               int *big, gdt_error *err)
{
    lz_slot *sl = &s->slots[k % s->nslots];

    pthread_mutex_lock(&s->mu);
    while (!(sl->chunk == k &&
             (sl->state == SLOT_READY || sl->state == SLOT_FAILED || sl->state == SLOT_BIG)))
        pthread_cond_wait(&s->cv_done, &s->mu);
    pthread_mutex_unlock(&s->mu);
    if (sl->state == SLOT_FAILED) {
        gdt_error_set(err, sl->err.status, sl->err.code, "%s", sl->err.msg);
        return sl->err.status;
    }
    if (sl->state == SLOT_BIG) {
        *big = 1;
        s->held = sl;
        return GDT_OK;
    }
    *recs = sl->rec;
    *n = (size_t)s->tab.count[k];
    lz_warn_bounds(s, k, sl->oob);
    s->held = sl;
    return GDT_OK;
}

/* Gives the slot handed on last back to the workers. */
static void lz_release(gdt_laz_stream *s)
{
    if (s->held == NULL)
        return;
    pthread_mutex_lock(&s->mu);
    s->held->state = SLOT_FREE;
    pthread_cond_broadcast(&s->cv_work);
    pthread_mutex_unlock(&s->mu);
    s->held = NULL;
}

/* The next piece of the chunk the consumer decodes itself. */
static gdt_status lz_piece(gdt_laz_stream *s, const unsigned char **recs, size_t *n, gdt_error *err)
{
    uint64_t k = s->chunk;
    size_t m = s->chunk_left < s->piece_points ? (size_t)s->chunk_left : s->piece_points;
    gdt_status st = gdt_laz_chunk_read(s->dec, s->piece, m, err);
    if (st != GDT_OK)
        return st;
    s->chunk_left -= m;
    if (s->chunk_left == 0) {
        st = lz_end(s, s->dec, k, err);
        if (st != GDT_OK)
            return st;
        if (!s->tab.present)
            s->next_start += gdt_laz_chunk_used(s->dec);
        s->incremental = 0;
        s->chunk++;
    }
    uint64_t oob = lz_out_of_bounds(s, s->piece, m);
    lz_warn_bounds(s, k, oob == UINT64_MAX ? oob : s->chunk_done + oob);
    s->chunk_done += m;
    *recs = s->piece;
    *n = m;
    return GDT_OK;
}

gdt_status gdt_laz_stream_next(gdt_laz_stream *s, const unsigned char **recs, size_t *n,
                               gdt_error *err)
{
    gdt_status st;

    *recs = NULL;
    *n = 0;
    if (s->failed != GDT_OK) {
        gdt_error_set(err, s->first.status, s->first.code, "%s", s->first.msg);
        return s->failed;
    }
    lz_release(s);
    if (s->delivered >= s->end_rec) {
        lz_stop_workers(s);
        return GDT_OK;
    }
    if (!s->started && (st = lz_start_workers(s, &s->first)) != GDT_OK)
        goto fail;
    if (!s->incremental) {
        uint64_t k = s->chunk;
        int big = 0;
        if (s->nworkers > 0) {
            st = lz_take_slot(s, k, recs, n, &big, &s->first);
            if (st != GDT_OK)
                goto fail;
            if (!big) {
                s->chunk++;
                s->delivered += *n;
                return GDT_OK;
            }
        }
        uint64_t start = s->tab.present ? s->tab.start[k] : s->next_start;
        st = lz_begin(s, s->dec, &s->cbuf, &s->cbuf_cap, k, start, &s->first);
        if (st != GDT_OK)
            goto fail;
        s->incremental = 1;
        s->chunk_left = lz_count(s, k);
        s->chunk_done = 0;
    }
    st = lz_piece(s, recs, n, &s->first);
    if (st != GDT_OK)
        goto fail;
    s->delivered += *n;
    return GDT_OK;
fail:
    *recs = NULL;
    *n = 0;
    gdt_error_set(err, s->first.status, s->first.code, "%s", s->first.msg);
    return lz_fail(s, st);
}

/* ---- open / close -------------------------------------------------------- */

/* The table's claims that open can check: no chunk may be larger than its
 * records could ever compress to. */
static gdt_status lz_check_table(const gdt_laz_stream *s, gdt_error *err)
{
    for (uint64_t k = 0; k < s->nchunks; k++) {
        uint64_t most = gdt_laz_stream_bytes_max(s->tab.count[k], s->p.record_length);
        if (s->tab.bytes[k] > most)
            return gdt_error_set(err, GDT_EINPUT, 3972,
                                 "%s: LAZ chunk %" PRIu64 " of %" PRIu64 " claims %" PRIu64
                                 " compressed bytes for %" PRIu64 " points of %u bytes"
                                 " (at most %" PRIu64 " are plausible): the chunk table is"
                                 " corrupt",
                                 s->p.path, k, s->nchunks, s->tab.bytes[k], s->tab.count[k],
                                 s->p.record_length, most);
    }
    return GDT_OK;
}

gdt_status gdt_laz_stream_open(gdt_laz_stream **out, const unsigned char *vlr, size_t vlr_len,
                               const gdt_laz_stream_params *p, gdt_error *err)
{
    gdt_laz_stream *s;
    gdt_status st;

    *out = NULL;
    s = calloc(1, sizeof *s);
    if (s == NULL)
        return lz_oom(err);
    s->p = *p;
    if (pthread_mutex_init(&s->mu, NULL) != 0) {
        free(s);
        return lz_oom(err);
    }
    pthread_cond_init(&s->cv_work, NULL);
    pthread_cond_init(&s->cv_done, NULL);
    for (int a = 0; a < 3; a++) {
        double step = p->scale[a] < 0 ? -p->scale[a] : p->scale[a];
        s->lo[a] = p->min[a] - step;
        s->hi[a] = p->max[a] + step;
    }
    st = gdt_laz_vlr_parse(p->path, vlr, vlr_len, p->point_format, p->record_length, &s->vlr, err);
    if (st == GDT_OK)
        st = gdt_laz_table_read(&s->tab, &s->vlr, p->fd, p->path, p->points_start, p->region_end,
                                p->point_count, p->log, err);
    if (st != GDT_OK)
        goto fail;
    s->nchunks = s->tab.present ? s->tab.nchunks : 0;
    if (!s->tab.present && p->point_count > 0 &&
        (s->vlr.chunk_size == 0 || s->vlr.chunk_size == GDT_LAZ_VARIABLE_CHUNKS)) {
        /* the table reader accepts a missing table only for fixed chunks */
        st = gdt_error_set(err, GDT_EINPUT, 3973,
                           "%s: LAZ point data without a chunk table needs a fixed chunk"
                           " size (the LASzip VLR gives %" PRIu32 ")",
                           p->path, s->vlr.chunk_size);
        goto fail;
    }
    s->next_start = p->points_start + 8;
    s->end_chunk = s->nchunks;
    s->end_rec = p->point_count;
    st = lz_check_table(s, err);
    if (st != GDT_OK)
        goto fail;
    st = gdt_laz_chunk_new(&s->dec, &s->vlr, p->record_length, p->need, err);
    if (st != GDT_OK)
        goto fail;
    {
        size_t pb = p->piece_bytes != 0 ? p->piece_bytes : LZ_PIECE_DEFAULT;
        s->piece_points = pb / p->record_length;
        if (s->piece_points == 0)
            s->piece_points = 1;
        s->piece = malloc(s->piece_points * p->record_length);
        if (s->piece == NULL) {
            st = lz_oom(err);
            goto fail;
        }
    }
    *out = s;
    return GDT_OK;
fail:
    gdt_laz_stream_close(s);
    return st;
}

uint64_t gdt_laz_stream_starts(const gdt_laz_stream *s, uint64_t *out, uint64_t cap)
{
    uint64_t first = 0;
    if (!s->tab.present)
        return 0;
    for (uint64_t k = 0; k < s->nchunks && k < cap; k++) {
        out[k] = first;
        first += s->tab.count[k];
    }
    return s->nchunks;
}

gdt_status gdt_laz_stream_seek(gdt_laz_stream *s, uint64_t first, uint64_t end, gdt_error *err)
{
    uint64_t k = 0, rec = 0;

    if (s->started || s->delivered != 0)
        return gdt_error_set(err, GDT_EINTERNAL, 7102,
                             "%s: seeking to point record %" PRIu64 " after reading",
                             s->p.path, first);
    if (end > s->p.point_count)
        end = s->p.point_count;
    if (first > end)
        first = end;
    if (!s->tab.present) {
        if (first != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7102,
                                 "%s: LAZ without a chunk table cannot start at point record "
                                 "%" PRIu64, s->p.path, first);
        return GDT_OK; /* read from the start; the reader stops at end */
    }
    while (k < s->nchunks && rec + s->tab.count[k] <= first)
        rec += s->tab.count[k++];
    if (rec != first && first != end)
        return gdt_error_set(err, GDT_EINTERNAL, 7102,
                             "%s: point record %" PRIu64 " does not start a LAZ chunk",
                             s->p.path, first);
    s->chunk = k;
    s->next_claim = k;
    s->delivered = first;
    /* the chunks that hold [first, end) */
    s->end_chunk = k;
    s->end_rec = rec;
    while (s->end_chunk < s->nchunks && s->end_rec < end)
        s->end_rec += s->tab.count[s->end_chunk++];
    if (first == end) {
        s->end_chunk = s->chunk;
        s->end_rec = s->delivered;
    }
    return GDT_OK;
}

void gdt_laz_stream_close(gdt_laz_stream *s)
{
    if (s == NULL)
        return;
    lz_stop_workers(s);
    for (unsigned i = 0; i < s->nw; i++) {
        if (s->w[i].dec != NULL)
            gdt_laz_chunk_free(s->w[i].dec);
        free(s->w[i].cbuf);
    }
    for (unsigned i = 0; i < 2 * s->nw; i++)
        free(s->slots[i].rec);
    free(s->w);
    free(s->slots);
    if (s->dec != NULL)
        gdt_laz_chunk_free(s->dec);
    free(s->cbuf);
    free(s->piece);
    gdt_laz_table_free(&s->tab);
    pthread_cond_destroy(&s->cv_work);
    pthread_cond_destroy(&s->cv_done);
    pthread_mutex_destroy(&s->mu);
    free(s);
}

void gdt_laz_stream_describe(const gdt_laz_stream *s, gdt_laz_stream_desc *d)
{
    size_t len = 0;

    memset(d, 0, sizeof *d);
    switch (s->vlr.compressor) {
    case GDT_LAZ_COMPRESSOR_POINTWISE: d->compressor = "pointwise"; break;
    case GDT_LAZ_COMPRESSOR_POINTWISE_CHUNKED: d->compressor = "pointwise chunked"; break;
    case GDT_LAZ_COMPRESSOR_LAYERED_CHUNKED: d->compressor = "layered chunked"; break;
    default: d->compressor = "none"; break;
    }
    for (unsigned i = 0; i < s->vlr.nitems && len < sizeof d->items; i++) {
        const gdt_laz_item *it = &s->vlr.items[i];
        int k;
        if (it->type == GDT_LAZ_BYTE || it->type == GDT_LAZ_BYTE14)
            k = snprintf(d->items + len, sizeof d->items - len, "%s%s v%u (%u bytes)",
                         i ? ", " : "", (gdt_laz_item_name(it->type) != NULL ? gdt_laz_item_name(it->type) : "unknown"), it->version, it->size);
        else
            k = snprintf(d->items + len, sizeof d->items - len, "%s%s v%u", i ? ", " : "",
                         (gdt_laz_item_name(it->type) != NULL ? gdt_laz_item_name(it->type) : "unknown"), it->version);
        if (k < 0)
            break;
        len += (size_t)k;
    }
    d->chunk_size = s->vlr.chunk_size == GDT_LAZ_VARIABLE_CHUNKS ? 0 : s->vlr.chunk_size;
    d->chunks = s->nchunks;
}
