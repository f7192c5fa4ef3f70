/* job.h — the job journal of a tiled run: <job>/job.db, an SQLite database
 * in WAL mode with synchronous=FULL, so a committed record survives a crash
 * or power cut.
 *
 * Tables:
 *   meta(key, value)               "schema", "id" (the job's random 128-bit
 *                                  id, 32 hex digits), "params" (the options
 *                                  and input paths that fix the output, one
 *                                  "key=value" per line), "output" (the
 *                                  output path of the latest run, for
 *                                  --resume; not part of params, so another
 *                                  -o reuses the finished work) and
 *                                  "fingerprint" (per input: size, mtime and
 *                                  a hash of its first and last 64 KiB)
 *   stage(name, done)              "pass2" (the tiler's tile files), "ply"
 *   tile(k, file, size, checksum)  a finished tile: its .tri file
 *   pfile(k, kind, size, checksum) a pass-2 file of tile k (kind
 *                                  GDT_JOB_FILE_PTS or _EDGE), recorded in
 *                                  the transaction that marks "pass2" done;
 *                                  or (GDT_JOB_FILE_GPTS, _GEDGE) a tile's
 *                                  ground subset, recorded as soon as it is
 *                                  written (--ground)
 * Creation: the tables, the schema row and the id are one transaction, so a
 * failure (a full disk) leaves nothing or a complete empty journal; a
 * database without a schema row and without any record, or of another
 * schema without finished work, is taken as new.
 * Protocol: a file is written to a temporary name, fsync'd and renamed
 * first, then recorded in one transaction.  So a record always names a
 * complete file; a file without a record is simply redone.  Every checksum
 * is gdt_hash64_wide over the whole file, seeded with gdt_job_file_seed (the
 * job's id, the tile and the file kind; .tri headers carry the id too): a
 * record of another job, tile or kind never vouches for a file, and a file
 * passes only with exactly the bytes this job wrote.  On resume every
 * recorded file is verified (size and checksum, one read) before it is
 * reused.  These are
 * the only files a rerun takes over: index.vdb (pass 1) and merge.faces
 * (the merge) are written anew by every run, and so is the PLY (the "ply"
 * stage is only a record).
 * Lock: <job>/lock (gdt_job_lock), an flock held for the whole run, with
 * the holder's pid and whether a run of the job made the directory as its
 * content; the kernel drops it when the holder dies, so a stale file never
 * blocks.  It is removed last, after the journal, when a job is done.
 *
 * Message numbers: 4901 cannot open/create, 4902 SQLite write failed
 * (disk full, I/O), 4903 the lock file cannot be created, 6901 not a job
 * database (or another schema, or damaged: an existing journal must pass
 * SQLite's quick_check when opened), 6906 another run holds the job.
 */
#ifndef GDT_JOB_H
#define GDT_JOB_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"

typedef struct gdt_job gdt_job;

/* Opens <dir>/job.db.  With create, makes an empty journal (with a fresh
 * random id) when there is none, or when the database holds no schema row
 * and no record (*is_new = 1); without, a missing journal is GDT_EJOB 6902.
 * A journal this call created and could not complete is removed again.
 * Ownership: *out is new; close with gdt_job_close. */
gdt_status gdt_job_open(gdt_job **out, const char *dir, int create, int *is_new,
                        gdt_error *err);
void gdt_job_close(gdt_job *j);

/* 1 if <dir>/job.db exists. */
int gdt_job_exists(const char *dir);

/* The job's 128-bit id (meta "id"). */
void gdt_job_id(const gdt_job *j, uint64_t id[2]);

/* *has = 1 when the journal records finished work: a stage done, a tile or
 * a pass-2 file.  A journal without any may be taken over by any command. */
gdt_status gdt_job_has_work(gdt_job *j, int *has, gdt_error *err);

/* Takes the exclusive lock of the job directory dir (which must exist):
 * <dir>/lock, created if needed, flock'ed without waiting, then rewritten
 * as "<pid> made|given".  *owned = 1 when made (the caller has just created
 * dir) or the file already said "made": a run of this job created the
 * directory, so its final clean-up may remove it.  *fd: the descriptor to
 * keep open for the run (gdt_job_unlock).
 * returns: GDT_EJOB 6906 (another process holds it: its pid is named),
 *   GDT_EIO 4903. */
gdt_status gdt_job_lock(const char *dir, int made, int *fd, int *owned, gdt_error *err);
/* Releases the lock (fd < 0: nothing).  With remove, the lock file is
 * unlinked first (the job directory is being removed). */
void gdt_job_unlock(const char *dir, int fd, int remove);

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
/* Forgets every tile record, every record of a .pts or .edge file and the
 * "ply" stage (pass 2 is being redone); the ground subsets' records stay:
 * a redone pass 2 writes the same files, so a subset classified before
 * still holds (its file is verified before it is taken). */
gdt_status gdt_job_clear_tiles(gdt_job *j, gdt_error *err);

/* The kinds of files a checksum is bound to. */
enum {
    GDT_JOB_FILE_PTS = 1,
    GDT_JOB_FILE_EDGE = 2,
    GDT_JOB_FILE_TRI = 3,
    GDT_JOB_FILE_BITS = 4,  /* J/ground.bits (its sum's seed; recorded in meta) */
    GDT_JOB_FILE_GPTS = 5,  /* a tile's ground subset .gpts (summed as a .pts file) */
    GDT_JOB_FILE_GEDGE = 6  /* and its .gedge (summed as an .edge file) */
};

/* Record of pass-2 file (k, kind); *found = 0 when there is none. */
gdt_status gdt_job_get_file(gdt_job *j, uint64_t k, int kind, int *found, uint64_t *size,
                            uint64_t *checksum, gdt_error *err);
gdt_status gdt_job_put_file(gdt_job *j, uint64_t k, int kind, uint64_t size, uint64_t checksum,
                            gdt_error *err);

/* The seed of the checksum of file kind of tile k in the job with this id. */
uint64_t gdt_job_file_seed(const uint64_t id[2], uint64_t k, int kind);

/* A 64-bit checksum of n bytes (not cryptographic: detects damage). */
uint64_t gdt_hash64(const void *p, size_t n, uint64_t seed);
/* The same kind of checksum, about four times faster on long buffers
 * (independent lanes); a different function: the tile files' records use it,
 * the input fingerprints keep gdt_hash64.  Equal to gdt_hash_wide_final
 * after gdt_hash_wide_init(seed) and updates with the bytes in any pieces. */
uint64_t gdt_hash64_wide(const void *p, size_t n, uint64_t seed);

/* gdt_hash64_wide computed incrementally (a file as it is written or read):
 * the state holds the four lanes, the bytes of an unfinished 32-byte block
 * and the length so far.  Plain value; no resources. */
typedef struct gdt_hash_wide {
    uint64_t h[4];
    uint64_t n;
    unsigned char part[32];
} gdt_hash_wide;

void gdt_hash_wide_init(gdt_hash_wide *s, uint64_t seed);
void gdt_hash_wide_update(gdt_hash_wide *s, const void *p, size_t n);
/* The checksum of everything so far; the state is not changed. */
uint64_t gdt_hash_wide_final(const gdt_hash_wide *s);

#endif
