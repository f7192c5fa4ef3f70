/* replay.h — the source records of compressed inputs, kept from the first
 * pass of a cloud for the passes after it.
 *
 * A LAZ input costs far more to decode than to read back: the first pass
 * writes every record it hands on (X Y Z and the attributes, 16 bytes) to a
 * temporary file, and later passes read that instead of decoding the input
 * again.  The points, their order and their coordinates are exactly those
 * of the source (x = X * scale + offset is recomputed the same way), so the
 * output cannot depend on whether a pass replays or decodes.
 *
 * The file is created unlinked (nothing is left behind, whatever happens to
 * the process) in a directory the caller names.  An input's records are
 * usable only once its whole stream was written and flushed
 * (gdt_replay_end); a write that fails (disk full) abandons the replay of
 * that and every later input, never the run: the caller decodes those again.
 *
 * Invariants: ranges of complete inputs are disjoint and in input order;
 * at most one input is being written or read at a time.
 */
#ifndef GDT_REPLAY_H
#define GDT_REPLAY_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_source.h"

typedef struct gdt_replay gdt_replay;

/* Creates the temporary file in dir.  returns GDT_EIO 44xx when it cannot;
 * callers may go on without a replay. */
gdt_status gdt_replay_open(gdt_replay **out, const char *dir, gdt_error *err);

/* Writing: begin input (which must not have been begun before) with the
 * range of its records [lo, hi) the stream holds (0 and its point count for
 * the whole input, a share's records otherwise), append its records in
 * stream order, end it.  A failed write makes append and end
 * no-ops and the input (and later ones) not replayable; they return GDT_OK
 * all the same, the failure is reported by gdt_replay_failed. */
void gdt_replay_begin(gdt_replay *r, size_t input, uint64_t lo, uint64_t hi);
void gdt_replay_append(gdt_replay *r, const gdt_src_point *p, size_t n);
void gdt_replay_end(gdt_replay *r);
/* Drops the input being written (its stream was not read to the end). */
void gdt_replay_abandon(gdt_replay *r);

/* 1 when input's records [lo, hi) are complete in the file. */
int gdt_replay_has(const gdt_replay *r, size_t input, uint64_t lo, uint64_t hi);
/* The reason the replay stopped, or NULL while it works. */
const char *gdt_replay_failed(const gdt_replay *r);

/* Reading: start input (complete: gdt_replay_has), then read records until
 * *n is 0.  Coordinates are rebuilt with the input's scale and offset. */
gdt_status gdt_replay_start(gdt_replay *r, size_t input, const double scale[3],
                            const double offset[3], gdt_error *err);
gdt_status gdt_replay_read(gdt_replay *r, gdt_src_point *buf, size_t cap, size_t *n,
                           gdt_error *err);

/* Closes (and so deletes) the file; r may be NULL. */
void gdt_replay_close(gdt_replay *r);

#endif
