/* plycheck_spill.h — external grouping of fixed-size records by key, within
 * a heap budget (the engine of gdt_ply_check, gdt_plycheck.h).
 *
 * Records (pcs_rec: a 64-bit key and two 32-bit payloads) are added in any
 * order; pcs_spill_walk then hands every run of records with equal keys to
 * a callback, runs in increasing key order.  Records stay in memory while
 * they fit; otherwise they are distributed over temporary files by key range
 * (a monotone map, so the buckets are consecutive key intervals and a key
 * never straddles two), and each bucket is sorted in memory in turn.  A
 * bucket larger than the sort budget is split again by key range before it
 * is sorted, recursively; a bucket whose records all share one key is not
 * loaded: its first three records are handed over with the true count.
 *
 * Heap accounting: every buffer goes through pcs_alloc / pcs_free, which
 * keep the bytes held and their peak in the pcs_env.  The sizes follow from
 * pcs_env.budget (B): a sorted bucket takes at most B/2 (16 bytes per record
 * plus the slot counts of the in-memory sort), the write buffers of one spill at
 * most B/4 in total (at least PCS_MIN_BUF bytes per bucket, which bounds the
 * fan-out), and a spill that starts in memory without a size hint at most
 * its mem_limit.
 *
 * Temporary files: created with mkstemp in env->temp_dir and unlinked at
 * once; each lives as long as its descriptor.
 *
 * Not thread-safe per instance.
 */
#ifndef GDT_PLYCHECK_SPILL_H
#define GDT_PLYCHECK_SPILL_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

/* One record.  key orders and groups; a and b are payload. */
typedef struct pcs_rec {
    uint64_t key;
    uint32_t a, b;
} pcs_rec;

/* Shared state of one check: budget, heap accounting, counters. */
typedef struct pcs_env {
    const char *temp_dir; /* directory of temporary files */
    const char *what;     /* file being checked, for messages */
    size_t budget;        /* heap budget B, bytes */
    size_t held, peak;    /* heap bytes held now / at most */
    uint64_t spill_bytes; /* bytes written to temporary files */
    uint64_t spill_files; /* temporary files created */
    uint64_t splits;      /* buckets split again (too large for the sort budget) */
} pcs_env;

/* Monotone map of keys in [kmin, kmax] onto slots [0, n):
 * slot = (((key - kmin) >> shift) * mult) >> 32.  Equal keys share a slot
 * and slot order follows key order. */
typedef struct pcs_map {
    uint64_t base;
    unsigned shift;
    uint64_t mult;
} pcs_map;

/* n in [1, 2^31]; kmin <= kmax. */
void pcs_map_init(pcs_map *m, uint64_t kmin, uint64_t kmax, size_t n);

static inline size_t pcs_map_slot(const pcs_map *m, uint64_t key)
{
    return (size_t)((((key - m->base) >> m->shift) * m->mult) >> 32);
}

/* One bucket: records in the temporary file fd (when fd >= 0) followed by
 * buf[0 .. fill).  In memory mode (fd < 0) buf holds all records and may
 * grow up to limit records before the bucket moves to a file. */
typedef struct pcs_bucket {
    int fd;
    uint64_t n;          /* records in the bucket (file and buffer) */
    uint64_t kmin, kmax; /* key range of its records (n > 0) */
    pcs_rec *buf;
    size_t fill, cap; /* buf holds cap records */
    size_t limit;     /* memory mode: most records held before spilling */
} pcs_bucket;

typedef struct pcs_spill {
    pcs_env *env;
    size_t nb;       /* buckets */
    pcs_map map;     /* key -> bucket (nb > 1) */
    pcs_bucket *b;   /* nb buckets */
    size_t buf_recs; /* write buffer of a file-mode bucket, records */
} pcs_spill;

/* Called for each run of equal keys, in increasing key order: recs[0 ..
 * loaded) are the run's records (loaded == count, except for a run too large
 * for the budget, where loaded == 3 < count).  A callback must fail (return
 * its error) on a run of count >= 3 whenever it is handed loaded < count. */
typedef gdt_status (*pcs_group_fn)(void *ctx, const pcs_rec *recs, size_t loaded, uint64_t count,
                                   gdt_error *err);

/* Heap allocation counted in env; 7001 on failure (err names env->what). */
void *pcs_alloc(pcs_env *env, size_t bytes, gdt_error *err);
void pcs_free(pcs_env *env, void *p, size_t bytes);

/* Largest number of records one sorted bucket may hold. */
size_t pcs_sort_cap(const pcs_env *env);

/* Sets up sp for keys in [kmin, kmax].
 * expected > 0: the exact or estimated record count; the spill stays in
 * memory when it fits one sorted bucket, else it gets as many buckets (up
 * to the fan-out allowed by B/4 of write buffers) as needed.
 * expected == 0: unknown; one bucket in memory up to mem_limit records,
 * moved to one temporary file beyond.
 * Ownership: pcs_spill_free releases everything, also after errors. */
gdt_status pcs_spill_init(pcs_spill *sp, pcs_env *env, uint64_t kmin, uint64_t kmax,
                          uint64_t expected, size_t mem_limit, gdt_error *err);

/* Appends one record (slow path of pcs_spill_add). */
gdt_status pcs_bucket_make_room(pcs_spill *sp, pcs_bucket *bk, gdt_error *err);

static inline gdt_status pcs_spill_add(pcs_spill *sp, uint64_t key, uint32_t a, uint32_t b,
                                       gdt_error *err)
{
    pcs_bucket *bk = sp->nb == 1 ? sp->b : sp->b + pcs_map_slot(&sp->map, key);
    if (bk->fill == bk->cap) {
        gdt_status s = pcs_bucket_make_room(sp, bk, err);
        if (s != GDT_OK)
            return s;
    }
    pcs_rec *r = bk->buf + bk->fill++;
    r->key = key;
    r->a = a;
    r->b = b;
    if (bk->n == 0 || key < bk->kmin)
        bk->kmin = key;
    if (bk->n == 0 || key > bk->kmax)
        bk->kmax = key;
    bk->n++;
    return GDT_OK;
}

/* Total records added. */
uint64_t pcs_spill_count(const pcs_spill *sp);

/* Hands every run of equal keys to fn (see pcs_group_fn), in key order, and
 * releases each bucket once walked.  Stops at the first error of fn or of
 * the files.  No record may be added afterwards. */
gdt_status pcs_spill_walk(pcs_spill *sp, pcs_group_fn fn, void *ctx, gdt_error *err);

/* Closes every file and frees every buffer; sp may be zeroed or half set up. */
void pcs_spill_free(pcs_spill *sp);

#endif
