/* plycheck_spill.c — external grouping of records by key (see
 * plycheck_spill.h). */
#include "plycheck_spill.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* Smallest write buffer of a file-mode bucket, bytes. */
#define PCS_MIN_BUF ((size_t)4096)
/* Largest write buffer of a file-mode bucket, bytes. */
#define PCS_MAX_BUF ((size_t)1 << 20)
/* Most buckets of one spill (open descriptors per level). */
#define PCS_MAX_FAN ((size_t)64)
/* Runs up to this length are sorted by insertion. */
#define PCS_SMALL_RUN 16
/* Largest run sorted in one fine distribution pass (records). */
#define PCS_FINE ((size_t)1 << 15)
/* Most slots of a coarse distribution pass. */
#define PCS_COARSE ((size_t)4096)

/* ---- heap accounting ---- */

void *pcs_alloc(pcs_env *env, size_t bytes, gdt_error *err)
{
    void *p = malloc(bytes == 0 ? 1 : bytes);
    if (p == NULL) {
        gdt_error_set(err, GDT_EINTERNAL, 7001, "%s: out of memory (%zu bytes) while checking",
                      env->what, bytes);
        return NULL;
    }
    env->held += bytes;
    if (env->held > env->peak)
        env->peak = env->held;
    return p;
}

void pcs_free(pcs_env *env, void *p, size_t bytes)
{
    if (p == NULL)
        return;
    free(p);
    env->held -= bytes;
}

/* 16 bytes per record, plus the slot counts of pcs_sort: at most 4 bytes
 * per record for the fine pass and, for runs above PCS_FINE, 32 KiB per
 * coarse level (a few levels even for skewed keys): 28 bytes cover both. */
size_t pcs_sort_cap(const pcs_env *env)
{
    return env->budget / 2 / 28;
}

/* Write buffers of one spill may take B/4; each holds >= PCS_MIN_BUF. */
static size_t pcs_fan_max(const pcs_env *env)
{
    size_t f = env->budget / 4 / PCS_MIN_BUF;
    if (f < 2)
        f = 2;
    return f > PCS_MAX_FAN ? PCS_MAX_FAN : f;
}

void pcs_map_init(pcs_map *m, uint64_t kmin, uint64_t kmax, size_t n)
{
    uint64_t span = kmax - kmin;
    unsigned shift = 0;
    while ((span >> shift) > UINT64_C(0xFFFFFFFF))
        shift++;
    uint64_t slots = (span >> shift) + 1; /* <= 2^32 */
    m->base = kmin;
    m->shift = shift;
    /* n <= 2^31: n << 32 fits; t * mult < n 2^32 <= 2^63 for t < slots. */
    m->mult = ((uint64_t)n << 32) / slots;
}

/* ---- temporary files ---- */

static gdt_status pcs_temp_create(pcs_env *env, int *fd, gdt_error *err)
{
    char path[4096];
    int n = snprintf(path, sizeof path, "%s/.gdt-plycheck-XXXXXX", env->temp_dir);
    if (n < 0 || (size_t)n >= sizeof path)
        return gdt_error_set(err, GDT_EIO, 4362,
                             "%s: cannot create a temporary file in %s: path too long", env->what,
                             env->temp_dir);
    int f = mkstemp(path);
    if (f < 0)
        return gdt_error_set(err, GDT_EIO, 4362, "%s: cannot create a temporary file in %s: %s",
                             env->what, env->temp_dir, strerror(errno));
    if (unlink(path) != 0) {
        int e = errno;
        close(f);
        unlink(path);
        return gdt_error_set(err, GDT_EIO, 4362, "%s: cannot unlink the temporary file %s: %s",
                             env->what, path, strerror(e));
    }
    env->spill_files++;
    *fd = f;
    return GDT_OK;
}

static gdt_status pcs_write(pcs_env *env, int fd, const void *p, size_t bytes, gdt_error *err)
{
    const unsigned char *q = p;
    while (bytes > 0) {
        ssize_t w = write(fd, q, bytes);
        if (w < 0 && errno == EINTR)
            continue;
        if (w <= 0)
            return gdt_error_set(err, GDT_EIO, 4363,
                                 "%s: writing a temporary file in %s failed: %s", env->what,
                                 env->temp_dir, w < 0 ? strerror(errno) : "no progress");
        q += w;
        bytes -= (size_t)w;
        env->spill_bytes += (uint64_t)w;
    }
    return GDT_OK;
}

/* Reads exactly bytes at offset off. */
static gdt_status pcs_read(pcs_env *env, int fd, void *p, size_t bytes, uint64_t off,
                           gdt_error *err)
{
    unsigned char *q = p;
    while (bytes > 0) {
        ssize_t r = pread(fd, q, bytes, (off_t)off);
        if (r < 0 && errno == EINTR)
            continue;
        if (r < 0)
            return gdt_error_set(err, GDT_EIO, 4364,
                                 "%s: reading a temporary file in %s failed: %s", env->what,
                                 env->temp_dir, strerror(errno));
        if (r == 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7379,
                                 "%s: a temporary file in %s is shorter than written", env->what,
                                 env->temp_dir);
        q += r;
        bytes -= (size_t)r;
        off += (uint64_t)r;
    }
    return GDT_OK;
}

/* ---- spills ---- */

/* nb == 1 with mem_limit > 0: memory mode; otherwise file-mode buckets. */
static gdt_status pcs_setup(pcs_spill *sp, pcs_env *env, uint64_t kmin, uint64_t kmax, size_t nb,
                            size_t mem_limit, gdt_error *err)
{
    memset(sp, 0, sizeof *sp);
    sp->env = env;
    sp->b = pcs_alloc(env, nb * sizeof *sp->b, err);
    if (sp->b == NULL)
        return GDT_EINTERNAL;
    sp->nb = nb;
    for (size_t k = 0; k < nb; k++) {
        memset(sp->b + k, 0, sizeof sp->b[k]);
        sp->b[k].fd = -1;
    }
    if (nb == 1)
        sp->b[0].limit = mem_limit;
    else
        pcs_map_init(&sp->map, kmin, kmax, nb);
    size_t per = env->budget / 4 / nb;
    if (nb == 1)
        per = env->budget / 16;
    if (per < PCS_MIN_BUF)
        per = PCS_MIN_BUF;
    if (per > PCS_MAX_BUF)
        per = PCS_MAX_BUF;
    sp->buf_recs = per / sizeof(pcs_rec);
    return GDT_OK;
}

gdt_status pcs_spill_init(pcs_spill *sp, pcs_env *env, uint64_t kmin, uint64_t kmax,
                          uint64_t expected, size_t mem_limit, gdt_error *err)
{
    size_t cap = pcs_sort_cap(env);

    if (expected == 0)
        return pcs_setup(sp, env, kmin, kmax, 1, mem_limit > 0 ? mem_limit : 1, err);
    if (expected <= cap) {
        /* Known size that fits: one exact allocation, no regrowth. */
        gdt_status s = pcs_setup(sp, env, kmin, kmax, 1, cap, err);
        if (s != GDT_OK)
            return s;
        sp->b[0].buf = pcs_alloc(env, (size_t)expected * sizeof(pcs_rec), err);
        if (sp->b[0].buf == NULL)
            return GDT_EINTERNAL;
        sp->b[0].cap = (size_t)expected;
        return GDT_OK;
    }
    /* Buckets about 3/4 full on average leave room for uneven key ranges. */
    uint64_t per = (uint64_t)cap * 3 / 4;
    uint64_t nb = (expected + per - 1) / per;
    size_t fan = pcs_fan_max(env);
    if (nb > fan)
        nb = fan;
    if (nb < 2)
        nb = 2;
    return pcs_setup(sp, env, kmin, kmax, (size_t)nb, 0, err);
}

uint64_t pcs_spill_count(const pcs_spill *sp)
{
    uint64_t n = 0;
    for (size_t k = 0; k < sp->nb; k++)
        n += sp->b[k].n;
    return n;
}

/* Writes the buffered records of bk to its file (created when needed). */
static gdt_status pcs_flush(pcs_spill *sp, pcs_bucket *bk, gdt_error *err)
{
    gdt_status s;
    if (bk->fill == 0)
        return GDT_OK;
    if (bk->fd < 0 && (s = pcs_temp_create(sp->env, &bk->fd, err)) != GDT_OK)
        return s;
    s = pcs_write(sp->env, bk->fd, bk->buf, bk->fill * sizeof *bk->buf, err);
    bk->fill = 0;
    return s;
}

gdt_status pcs_bucket_make_room(pcs_spill *sp, pcs_bucket *bk, gdt_error *err)
{
    pcs_env *env = sp->env;
    gdt_status s;

    if (bk->limit > 0 && bk->cap < bk->limit) {
        /* Memory mode: grow geometrically up to the limit. */
        size_t ncap = bk->cap < 512 ? 1024 : 2 * bk->cap;
        if (ncap > bk->limit)
            ncap = bk->limit;
        pcs_rec *nb = pcs_alloc(env, ncap * sizeof *nb, err);
        if (nb == NULL)
            return GDT_EINTERNAL;
        if (bk->fill > 0)
            memcpy(nb, bk->buf, bk->fill * sizeof *nb);
        pcs_free(env, bk->buf, bk->cap * sizeof *bk->buf);
        bk->buf = nb;
        bk->cap = ncap;
        return GDT_OK;
    }
    if (bk->limit > 0) {
        /* Memory mode is full: the bucket moves to a file. */
        if ((s = pcs_flush(sp, bk, err)) != GDT_OK)
            return s;
        pcs_free(env, bk->buf, bk->cap * sizeof *bk->buf);
        bk->buf = NULL;
        bk->cap = 0;
        bk->limit = 0;
    }
    if (bk->buf == NULL) {
        bk->buf = pcs_alloc(env, sp->buf_recs * sizeof *bk->buf, err);
        if (bk->buf == NULL)
            return GDT_EINTERNAL;
        bk->cap = sp->buf_recs;
        bk->fill = 0;
        return GDT_OK;
    }
    return pcs_flush(sp, bk, err);
}

static void pcs_bucket_release(pcs_env *env, pcs_bucket *bk)
{
    if (bk->fd >= 0)
        close(bk->fd);
    bk->fd = -1;
    pcs_free(env, bk->buf, bk->cap * sizeof *bk->buf);
    bk->buf = NULL;
    bk->cap = bk->fill = 0;
}

void pcs_spill_free(pcs_spill *sp)
{
    if (sp->b != NULL) {
        for (size_t k = 0; k < sp->nb; k++)
            pcs_bucket_release(sp->env, sp->b + k);
        pcs_free(sp->env, sp->b, sp->nb * sizeof *sp->b);
    }
    sp->b = NULL;
    sp->nb = 0;
}

/* ---- sorting one bucket in memory ---- */

static void pcs_sift(pcs_rec *r, size_t root, size_t n)
{
    pcs_rec x = r[root];
    for (;;) {
        size_t c = 2 * root + 1;
        if (c >= n)
            break;
        if (c + 1 < n && r[c + 1].key > r[c].key)
            c++;
        if (r[c].key <= x.key)
            break;
        r[root] = r[c];
        root = c;
    }
    r[root] = x;
}

static void pcs_small_sort(pcs_rec *r, size_t n)
{
    if (n <= PCS_SMALL_RUN) {
        for (size_t i = 1; i < n; i++) {
            pcs_rec x = r[i];
            size_t j = i;
            while (j > 0 && r[j - 1].key > x.key) {
                r[j] = r[j - 1];
                j--;
            }
            r[j] = x;
        }
        return;
    }
    for (size_t i = n / 2; i-- > 0;)
        pcs_sift(r, i, n);
    for (size_t end = n - 1; end > 0; end--) {
        pcs_rec x = r[0];
        r[0] = r[end];
        r[end] = x;
        pcs_sift(r, 0, end);
    }
}

/* One in-place distribution pass (American flag sort) of r[0..n) (keys in
 * [kmin, kmax]) over `slots` key-range slots; on return r[start[d] ..
 * start[d+1]) hold the records of slot d.  start: slots + 1 entries, next:
 * slots entries, caller scratch.  Precondition: n < 2^32. */
static void pcs_distribute(pcs_rec *r, size_t n, uint64_t kmin, uint64_t kmax, uint32_t *start,
                           uint32_t *next, size_t slots)
{
    pcs_map m;
    pcs_map_init(&m, kmin, kmax, slots);
    memset(start, 0, (slots + 1) * sizeof *start);
    for (size_t i = 0; i < n; i++)
        start[pcs_map_slot(&m, r[i].key) + 1]++;
    for (size_t d = 0; d < slots; d++)
        start[d + 1] += start[d];
    memcpy(next, start, slots * sizeof *next);
    for (size_t d = 0; d < slots; d++) {
        /* Invariant: r[start[d] .. next[d]) hold records of slot d. */
        while (next[d] < start[d + 1]) {
            pcs_rec x = r[next[d]];
            size_t e = pcs_map_slot(&m, x.key);
            while (e != d) {
                pcs_rec y = r[next[e]];
                r[next[e]++] = x;
                x = y;
                e = pcs_map_slot(&m, x.key);
            }
            r[next[d]++] = x;
        }
    }
}

/* Sorts r[0..n) by key (keys in [kmin, kmax]).  Runs of up to PCS_FINE
 * records (cache-resident) get one distribution pass over about n/2
 * slots, then each slot is sorted on its own; larger runs are first
 * distributed over at most PCS_COARSE slots and each slot is sorted
 * recursively (a slot's key range is a strict part of its parent's, since
 * kmin and kmax always land in different slots, so the recursion ends).
 * fine: scratch of PCS_FINE + 3 entries (fewer when n is smaller).
 * returns GDT_OK or 7001 (the coarse slot arrays are allocated). */
static gdt_status pcs_sort(pcs_env *env, pcs_rec *r, size_t n, uint64_t kmin, uint64_t kmax,
                           uint32_t *fine, gdt_error *err)
{
    if (n < 2 || kmin == kmax)
        return GDT_OK;
    if (n <= PCS_FINE) {
        size_t slots = n / 2 + 1;
        pcs_distribute(r, n, kmin, kmax, fine, fine + slots + 1, slots);
        for (size_t d = 0; d < slots; d++)
            if (fine[d + 1] - fine[d] > 1)
                pcs_small_sort(r + fine[d], fine[d + 1] - fine[d]);
        return GDT_OK;
    }
    size_t slots = n / (PCS_FINE / 4);
    if (slots > PCS_COARSE)
        slots = PCS_COARSE;
    size_t bytes = (2 * slots + 1) * sizeof(uint32_t);
    uint32_t *start = pcs_alloc(env, bytes, err);
    gdt_status s = GDT_OK;
    if (start == NULL)
        return GDT_EINTERNAL;
    pcs_distribute(r, n, kmin, kmax, start, start + slots + 1, slots);
    for (size_t d = 0; d < slots && s == GDT_OK; d++) {
        pcs_rec *g = r + start[d];
        size_t gn = start[d + 1] - start[d];
        if (gn < 2)
            continue;
        uint64_t lo = g[0].key, hi = g[0].key;
        for (size_t i = 1; i < gn; i++) {
            lo = g[i].key < lo ? g[i].key : lo;
            hi = g[i].key > hi ? g[i].key : hi;
        }
        s = pcs_sort(env, g, gn, lo, hi, fine, err);
    }
    pcs_free(env, start, bytes);
    return s;
}

static gdt_status pcs_walk_sorted(const pcs_rec *r, size_t n, pcs_group_fn fn, void *ctx,
                                  gdt_error *err)
{
    size_t i = 0;
    while (i < n) {
        size_t j = i + 1;
        while (j < n && r[j].key == r[i].key)
            j++;
        gdt_status s = fn(ctx, r + i, j - i, j - i, err);
        if (s != GDT_OK)
            return s;
        i = j;
    }
    return GDT_OK;
}

/* Sorts and walks n records held in r (n <= pcs_sort_cap). */
static gdt_status pcs_sort_walk(pcs_env *env, pcs_rec *r, size_t n, uint64_t kmin, uint64_t kmax,
                                pcs_group_fn fn, void *ctx, gdt_error *err)
{
    size_t fn_recs = n < PCS_FINE ? n : PCS_FINE;
    size_t bytes = (fn_recs + 3) * sizeof(uint32_t);
    uint32_t *fine = pcs_alloc(env, bytes, err);
    gdt_status s;

    if (fine == NULL)
        return GDT_EINTERNAL;
    s = pcs_sort(env, r, n, kmin, kmax, fine, err);
    pcs_free(env, fine, bytes);
    if (s != GDT_OK)
        return s;
    return pcs_walk_sorted(r, n, fn, ctx, err);
}

/* Walks the n records of the file fd (key range [kmin, kmax]); closes fd. */
static gdt_status pcs_walk_file(pcs_env *env, int *fd, uint64_t n, uint64_t kmin, uint64_t kmax,
                                pcs_group_fn fn, void *ctx, gdt_error *err)
{
    gdt_status s = GDT_OK;
    size_t cap = pcs_sort_cap(env);
    pcs_rec *r = NULL;
    size_t rbytes = 0;
    pcs_spill sub;

    memset(&sub, 0, sizeof sub);
    if (n <= cap) {
        rbytes = (size_t)n * sizeof *r;
        if ((r = pcs_alloc(env, rbytes, err)) == NULL) {
            s = GDT_EINTERNAL;
            goto fail;
        }
        if ((s = pcs_read(env, *fd, r, rbytes, 0, err)) != GDT_OK)
            goto fail;
        close(*fd);
        *fd = -1;
        s = pcs_sort_walk(env, r, (size_t)n, kmin, kmax, fn, ctx, err);
        goto fail;
    }
    if (kmin == kmax) {
        /* One key in more records than fit: the callback must refuse it. */
        rbytes = 3 * sizeof *r;
        if ((r = pcs_alloc(env, rbytes, err)) == NULL) {
            s = GDT_EINTERNAL;
            goto fail;
        }
        if ((s = pcs_read(env, *fd, r, rbytes, 0, err)) != GDT_OK)
            goto fail;
        s = fn(ctx, r, 3, n, err);
        if (s == GDT_OK)
            s = gdt_error_set(err, GDT_EINTERNAL, 7379,
                              "%s: key %llu occurs %llu times; the check accepted it", env->what,
                              (unsigned long long)kmin, (unsigned long long)n);
        goto fail;
    }
    /* Split by key range into sub-buckets and walk those. */
    env->splits++;
    {
        uint64_t per = (uint64_t)cap * 3 / 4;
        uint64_t nb = (n + per - 1) / per;
        size_t fan = pcs_fan_max(env);
        if (nb > fan)
            nb = fan;
        if (nb < 2)
            nb = 2;
        if ((s = pcs_setup(&sub, env, kmin, kmax, (size_t)nb, 0, err)) != GDT_OK)
            goto fail;
        size_t chunk = env->budget / 16 / sizeof *r;
        if (chunk < 64)
            chunk = 64;
        if (chunk > PCS_MAX_BUF / sizeof *r)
            chunk = PCS_MAX_BUF / sizeof *r;
        rbytes = chunk * sizeof *r;
        if ((r = pcs_alloc(env, rbytes, err)) == NULL) {
            s = GDT_EINTERNAL;
            goto fail;
        }
        for (uint64_t done = 0; done < n;) {
            size_t k = n - done < chunk ? (size_t)(n - done) : chunk;
            if ((s = pcs_read(env, *fd, r, k * sizeof *r, done * sizeof *r, err)) != GDT_OK)
                goto fail;
            for (size_t i = 0; i < k; i++)
                if ((s = pcs_spill_add(&sub, r[i].key, r[i].a, r[i].b, err)) != GDT_OK)
                    goto fail;
            done += k;
        }
        pcs_free(env, r, rbytes);
        r = NULL;
        close(*fd);
        *fd = -1;
        s = pcs_spill_walk(&sub, fn, ctx, err);
    }

fail:
    pcs_free(env, r, rbytes);
    pcs_spill_free(&sub);
    if (*fd >= 0)
        close(*fd);
    *fd = -1;
    return s;
}

gdt_status pcs_spill_walk(pcs_spill *sp, pcs_group_fn fn, void *ctx, gdt_error *err)
{
    pcs_env *env = sp->env;
    gdt_status s = GDT_OK;

    /* Every file-mode bucket goes to its file first: no write buffer stays
     * allocated while buckets are sorted or split (the heap bound). */
    for (size_t k = 0; k < sp->nb; k++) {
        pcs_bucket *bk = sp->b + k;
        if (bk->limit > 0)
            continue;
        if ((s = pcs_flush(sp, bk, err)) != GDT_OK)
            return s;
        pcs_free(env, bk->buf, bk->cap * sizeof *bk->buf);
        bk->buf = NULL;
        bk->cap = 0;
    }
    for (size_t k = 0; k < sp->nb && s == GDT_OK; k++) {
        pcs_bucket *bk = sp->b + k;
        if (bk->n == 0) {
            pcs_bucket_release(env, bk);
            continue;
        }
        if (bk->fd < 0) {
            /* Memory mode: all records are in buf. */
            s = pcs_sort_walk(env, bk->buf, bk->fill, bk->kmin, bk->kmax, fn, ctx, err);
            pcs_bucket_release(env, bk);
            continue;
        }
        s = pcs_walk_file(env, &bk->fd, bk->n, bk->kmin, bk->kmax, fn, ctx, err);
        pcs_bucket_release(env, bk);
    }
    return s;
}
