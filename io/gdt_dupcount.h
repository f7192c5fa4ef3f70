/* gdt_dupcount.h — exact out-of-core count of distinct (x, y) lattice points.
 *
 * Used by `gdt-tile --info` to report duplicates on inputs of any size within
 * a fixed memory budget.  Keys are kept in memory as (x, y, count) records;
 * when the buffer fills it is sorted and duplicates collapsed.  While the
 * collapsed records fill less than three quarters of the buffer everything
 * stays in memory (heavily duplicated input never touches the disk).
 * Otherwise the records are hash-partitioned into K spill files in temp_dir
 * (each created with mkstemp on its first write and unlinked at once, so
 * nothing is left behind even after a crash), and every later buffer-full
 * goes the same way.  At finish
 * each partition is read back and collapsed the same way; a partition whose
 * distinct keys still do not fit is re-partitioned with another hash, up to
 * GDT_DUPCOUNT_MAX_LEVEL levels.  The result does not depend on the budget.
 *
 * Memory: the record buffer and one level of K write buffers fill the
 * budget; re-splitting a partition adds one more level of write buffers
 * (1/16 of the budget from 1 MiB up) per level in use.  File descriptors:
 * at most K per level in use (K = 64 from 8 MiB up, 32 from 1 MiB, else 8).
 * Not thread-safe per instance.
 *
 * Message numbers: 2441 (budget too small / bad arguments), 4441 (temporary
 * file cannot be created), 4442 (write failed, e.g. disk full), 4443 (read
 * failed), 7441 (partitioning does not converge), 7442 (misuse: add after
 * finish), 7001 (out of memory).
 */
#ifndef GDT_DUPCOUNT_H
#define GDT_DUPCOUNT_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_DUPCOUNT_DEFAULT_BUDGET ((size_t)64 << 20)
#define GDT_DUPCOUNT_MIN_BUDGET ((size_t)4 << 10)
#define GDT_DUPCOUNT_MAX_LEVEL 12

typedef struct gdt_dupcount_opts {
    size_t mem_budget;   /* bytes; 0 = GDT_DUPCOUNT_DEFAULT_BUDGET; >= GDT_DUPCOUNT_MIN_BUDGET */
    const char *temp_dir; /* spill directory; NULL = $TMPDIR, else /tmp.  Copied. */
    gdt_log *log;        /* notes about spilling; may be NULL */
} gdt_dupcount_opts;

typedef struct gdt_dupcount_result {
    uint64_t points;           /* keys added */
    uint64_t distinct;         /* distinct (x, y) */
    uint64_t duplicates;       /* points - distinct */
    uint64_t max_multiplicity; /* largest number of points sharing one (x, y); 0 if empty */
    uint64_t spilled_records;  /* records written to spill files, all levels (0: in memory) */
    unsigned levels;           /* partition levels used: 0 in memory, 1 spilled once,
                                  2 and more when partitions were re-split */
} gdt_dupcount_result;

typedef struct gdt_dupcount gdt_dupcount;

/* Ownership: *out is new, free with gdt_dupcount_destroy (which also closes
 * any spill file).  returns: GDT_EUSAGE 2441, GDT_EINTERNAL 7001. */
gdt_status gdt_dupcount_create(gdt_dupcount **out, const gdt_dupcount_opts *opts,
                             gdt_error *err);
/* Adds the (x, y) of pts[0..n); z and ord are ignored.
 * returns: GDT_EIO 4441/4442 when spilling fails; errors are sticky. */
gdt_status gdt_dupcount_add(gdt_dupcount *dc, const gdt_point *pts, size_t n, gdt_error *err);
/* Counts.  May be called once; later adds fail with 7442.
 * returns: GDT_EIO 4441..4443, GDT_EINTERNAL 7441. */
gdt_status gdt_dupcount_finish(gdt_dupcount *dc, gdt_dupcount_result *res, gdt_error *err);
/* dc may be NULL. */
void gdt_dupcount_destroy(gdt_dupcount *dc);

#ifdef __cplusplus
}
#endif
#endif
