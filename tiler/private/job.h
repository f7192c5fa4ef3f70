/* job.h — the job journal of a tiled run: <job>/job.db, an SQLite database
 * in WAL mode with synchronous=FULL, so a committed record survives a crash
 * or power cut.
 *
 * Tables:
 *   meta(key, value)               "params" (the options and paths that fix
 *                                  the output, one "key=value" per line) and
 *                                  "fingerprint" (per input: size, mtime and
 *                                  a hash of its first and last 64 KiB)
 *   stage(name, done)              "pass2" (the tiler's tile files), "ply"
 *   tile(k, file, size, checksum)  a finished tile: its .tri file
 * Protocol: a file is written to a temporary name, fsync'd and renamed
 * first, then recorded in one transaction.  So a record always names a
 * complete file; a file without a record is simply redone.  On resume the
 * recorded checksum is verified before a file is reused.
 *
 * Message numbers: 4901 cannot open/create, 4902 SQLite write failed
 * (disk full, I/O), 6901 not a job database (or newer schema, or damaged:
 * an existing journal must pass SQLite's quick_check when opened).
 */
#ifndef GDT_JOB_H
#define GDT_JOB_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

typedef struct gdt_job gdt_job;

/* Opens <dir>/job.db.  With create, makes an empty journal when there is
 * none (*is_new = 1); without, a missing journal is GDT_EJOB 6902.
 * Ownership: *out is new; close with gdt_job_close. */
gdt_status gdt_job_open(gdt_job **out, const char *dir, int create, int *is_new,
                        gdt_error *err);
void gdt_job_close(gdt_job *j);

/* 1 if <dir>/job.db exists. */
int gdt_job_exists(const char *dir);

/* *value: malloc'ed copy, or NULL when the key is absent. */
gdt_status gdt_job_get_meta(gdt_job *j, const char *key, char **value, gdt_error *err);
gdt_status gdt_job_set_meta(gdt_job *j, const char *key, const char *value, gdt_error *err);

gdt_status gdt_job_stage_done(gdt_job *j, const char *stage, int *done, gdt_error *err);
gdt_status gdt_job_set_stage(gdt_job *j, const char *stage, int done, gdt_error *err);

/* *found = 0 when tile k has no record. */
gdt_status gdt_job_get_tile(gdt_job *j, uint64_t k, int *found, uint64_t *size,
                            uint64_t *checksum, gdt_error *err);
gdt_status gdt_job_put_tile(gdt_job *j, uint64_t k, const char *file, uint64_t size,
                            uint64_t checksum, gdt_error *err);
/* Groups the following updates into one transaction (one sync). */
gdt_status gdt_job_begin(gdt_job *j, gdt_error *err);
gdt_status gdt_job_commit(gdt_job *j, gdt_error *err);
/* Forgets every tile record and the "ply" stage (pass 2 was redone). */
gdt_status gdt_job_clear_tiles(gdt_job *j, gdt_error *err);

/* A 64-bit checksum of n bytes (not cryptographic: detects damage). */
uint64_t gdt_hash64(const void *p, size_t n, uint64_t seed);
/* The same kind of checksum, about four times faster on long buffers
 * (independent lanes); a different function: the tile files' records use it,
 * the input fingerprints keep gdt_hash64. */
uint64_t gdt_hash64_wide(const void *p, size_t n, uint64_t seed);

#endif
