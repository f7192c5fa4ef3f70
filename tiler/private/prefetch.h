/* prefetch.h — reads the cloud one batch ahead on a thread of its own.
 *
 * Pass 2 alternates decoding a batch of points (gdt_cloud_read: file read,
 * LAS/PCD decode, lattice conversion, projection) and sending each point to
 * its tile's file.  tl_prefetch overlaps the two: a reader thread fills one
 * of two buffers while the caller consumes the other.  The batches and
 * their order are exactly those of calling gdt_cloud_read(cap) in a loop,
 * so nothing downstream depends on the prefetch.  When no thread can be
 * started the batches are read on the caller's thread.
 *
 * While a prefetch runs, the cloud belongs to it: the caller must not use
 * the cloud until tl_prefetch_stop.  Errors of gdt_cloud_read come back from
 * tl_prefetch_next, in order (after the batches read before them).
 */
#ifndef GDT_TILER_PREFETCH_H
#define GDT_TILER_PREFETCH_H

#include <stddef.h>

#include "gdt_cloud.h"
#include "gdt_error.h"

typedef struct tl_prefetch tl_prefetch;

/* Starts reading cloud in batches of cap points.  Ownership: *out is
 * allocated here; release it with tl_prefetch_stop.  Errors: GDT_EINTERNAL
 * 7001. */
gdt_status tl_prefetch_start(tl_prefetch **out, gdt_cloud *cloud, size_t cap, gdt_error *err);

/* The next batch: *pts, *n (n = 0: the cloud has ended).  *pts stays valid
 * until the next call or tl_prefetch_stop.  After the end or an error only
 * tl_prefetch_stop may follow. */
gdt_status tl_prefetch_next(tl_prefetch *p, const gdt_point **pts, size_t *n, gdt_error *err);

/* Stops the reader (even in the middle of the cloud), joins it and frees p.
 * p may be NULL. */
void tl_prefetch_stop(tl_prefetch *p);

#endif
