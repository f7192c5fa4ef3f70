/* gdt_tiler.h — the out-of-core tiler: one cloud in, tiles the core can take.
 *
 * The tiler reads the cloud twice and holds only bounded buffers; its memory
 * depends on --tile and --mem-budget, never on the number of input points.
 *
 * Tile geometry (all in lattice units, see gdt_cloud.h):
 *  - A texel is c x c lattice steps (c >= 1, an integer), a tile is N x N
 *    texels, so a tile spans T = N * c steps.  Tile (i, j) is the half-open
 *    box [i*T, (i+1)*T) x [j*T, (j+1)*T): the tile grid is anchored at the
 *    lattice origin, tile lines are lattice lines, and point (x, y) lies in
 *    tile (floor(x / T), floor(y / T)).  Every point is in exactly one tile.
 *  - The halo width is h = H * c steps (H texels).  The halo box of a tile is
 *    [x0 - h, x0 + T + h) x [y0 - h, y0 + T + h); the halo H_T is every
 *    deduplicated point of another tile inside that box.  So every cloud
 *    point p with x0 - h <= p.x <= x0 + T + h - 1 (and the same in y) is in
 *    the tile or in its halo: that closed box is the region the tile stage
 *    knows completely.
 *  - Tile-local coordinates are x - (x0 - h), y - (y0 - h); they lie in
 *    [0, T + 2h - 1].  The predicates need them in [0, 2^31 - 1], so the
 *    tiler refuses (N + 2H) * c > 2^31 (GDT_EUSAGE 2502).
 *
 * Choices (pass 1):
 *  - The density grid counts points per V x V-step voxel, V = 2^shift: the
 *    smallest power of two for which the cloud has at most density_voxels
 *    occupied voxels and a small OpenVDB tree (rules in density.c).  It is
 *    a function of the point set only.
 *  - --cell auto: the occupied area is measured on the density grid (at the
 *    finest level whose occupied voxels hold 16 points on average), and
 *    c = sqrt(area / points) / 2, so that a tile of the occupied part holds
 *    about N^2/4 points, rounded (in ratio) to a multiple of max(1, V / N)
 *    (V: density voxel) so that tile counts are exact sums of density
 *    voxels; then lowered by such multiples while the densest tile holds
 *    more than N^2/4 points, down to c / sqrt 2 at most (about twice the
 *    tiles): the tile stage's memory follows the densest tile.  A given --cell S (CRS units) becomes c = S / sx steps,
 *    rounded to the nearest integer >= 1 (with a note when it is not one).
 *  - --halo auto: H = ceil(8 s / c) texels, s = the median point spacing
 *    over occupied density voxels, clamped to [1, N/2] and to the 2^31
 *    limit.  --halo 0 is legal.
 *
 * The index (OpenVDB, see gdt_vdb_index.h) is saved as <job>/index.vdb at
 * the end of pass 1: grid "tile_points" (one active voxel per non-empty tile
 * holding its point count, duplicates included) and grid "density" (a finer
 * grid of V x V-step voxels, V = 2^shift).  Pass 2 verifies that it wrote
 * exactly those counts, so the saved file holds the counts pass 2 wrote.
 *
 * Files under <job>/tiles/ (records: 32 bytes, little-endian int64 x,
 * int64 y, IEEE double z, uint64 ord; no header):
 *   tile_<i>_<j>.raw   pass 2: every point of the tile, in input order
 *                      (kept only with opts.keep_spill; otherwise it is
 *                      tile_<i>_<j>.raw.tmp, removed after the merge; not
 *                      written at all when half the memory budget holds
 *                      every record and the merge's hash tables)
 *   tile_<i>_<j>.pts   the tile's points after the --dup merge, sorted by
 *                      ordinal (the lowest ordinal of each (x, y) group)
 *   tile_<i>_<j>.edge  the subset of .pts within h of the tile's border
 *                      (the only points any other tile's halo can hold);
 *                      within max(h, opts.edge_min) until a subset replaces
 *                      the files (gdt_tiler_take_subsets)
 *   tile_<i>_<j>.gpts, .gedge  a subset of the tile's points and its edge
 *                      (gdt_tiler_write_subset), until taken
 * <i>, <j> are the decimal tile indices (may be negative).  Each kept file
 * is written to a temporary name and renamed; pass 2 is done only once all
 * of them are durable (gdt_tiler_sync_files), and a later run takes a file
 * back only against its recorded checksum.  Intermediate files
 * (*.tmp: buckets, merge partitions and runs) are removed when done, and
 * pass 2 first removes whatever an interrupted run left.  The bytes of every file depend only on the
 * inputs and the options tile, cell, halo and dup: not on the memory
 * budget, the descriptor budget or the test knobs.
 *
 * Tile order: non-empty tiles sorted by (j, i) (rows from south to north,
 * west to east in each row); index k in 0 .. tiles-1 names a tile in every
 * function below.
 *
 * Memory (--mem-budget B, 0 = auto = max(256 MiB, 64 N^2 bytes)): pass 1
 * holds one read buffer and the density histogram (at most
 * opts.density_voxels voxels, about 90 bytes each; its OpenVDB grid, built at
 * the end of the pass, at most GDT_TILER_DENSITY_TREE_BYTES of nodes: the
 * voxel grows until both hold); pass 2 holds min(B/4, 64 MiB) of write
 * buffers (touched at once, so its footprint does not depend on the data);
 * the --dup merge holds B/2 and goes out of core beyond it; loading a tile
 * refuses (GDT_EUSAGE 2506) a tile whose points and halo exceed B/2.  The
 * tile table costs about 110 bytes per non-empty tile and must fit in B/8.
 * File descriptors: a budget probed from RLIMIT_NOFILE (half the soft
 * limit, at most 1024); more non-empty tiles than that are spilled through
 * intermediate bucket files, level by level.
 *
 * Message numbers: 2501 bad options, 2502 tile-local range, 2503 too many
 * tiles for the budget, 2504 budget too small, 2505 call out of order,
 * 2506 tile too large for the budget, 3501 input changed between passes,
 * 6501 tile files of an earlier run missing or damaged, 6503 a tile file
 * changed under the run (another size than written), 1301 stopped by the
 * progress callback (GDT_EINTERRUPTED),
 * 4501 job directory, 4502 create, 4503 write, 4504 read, 4505 fsync or
 * rename, 7501 internal, 7502 merge did not converge; from the index:
 * 3511 unreadable index, 4511 index write, 7511 OpenVDB failure;
 * 7001 out of memory.
 *
 * Not thread-safe per instance; gdt_tiler_load_tile of different tiles may
 * not run concurrently on one instance either.
 */
#ifndef GDT_TILER_H
#define GDT_TILER_H

#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "gdt_cloud.h"
#include "gdt_error.h"
#include "gdt_predicates.h"

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_TILER_REC_BYTES 32
#define GDT_TILER_MIN_TILE 64
#define GDT_TILER_MAX_TILE 16384
#define GDT_TILER_DEFAULT_BUDGET ((uint64_t)256 << 20)
#define GDT_TILER_MIN_BUDGET ((uint64_t)16 << 20)
#define GDT_TILER_DEFAULT_DENSITY_VOXELS 65536u
#define GDT_TILER_DENSITY_TREE_BYTES ((uint64_t)16 << 20)

typedef struct gdt_tiler_opts {
    int tile;              /* N: texels per side, a power of two in [64, 16384] */
    double cell;           /* texel size in CRS units (x axis); 0 = auto */
    long halo;             /* halo width in texels; < 0 = auto */
    uint64_t mem_budget;   /* bytes; 0 = auto; otherwise >= GDT_TILER_MIN_BUDGET */
    gdt_dup_policy dup;    /* the --dup rule */
    const char *job_dir;   /* existing directory; NULL: plan only (no index saved,
                              pass 2 refused).  Copied. */
    gdt_log *log;          /* progress notes (-v) and warnings; may be NULL */
    /* Progress, or NULL: called after every read batch of pass 1 (stage 1)
     * and pass 2 (stage 2) with points done and points expected, and after
     * every merged tile (stage 3) with tiles done and tiles.  A non-zero
     * return stops the tiler with GDT_EINTERRUPTED 1301; the job directory
     * stays consistent (pass 2 starts over when run again). */
    int (*progress)(void *ctx, int stage, uint64_t done, uint64_t total);
    void *progress_ctx;
    int threads;           /* host threads for the --dup merge (0 or 1: one);
                              the files do not depend on it */
    int64_t edge_min;      /* lattice steps: .edge files hold the points within
                              max(h, edge_min) of the border (a reach wider than
                              the halo, gdt_tiler_load_reach); 0: h */
    int subsets;           /* a subset replaces every tile's points after pass 2
                              (gdt_tiler_take_subsets): a recorded .pts file may
                              then be empty */
    uint64_t file_id[2];   /* the job's id: seeds the checksums of the .pts and
                              .edge files (gdt_job_file_seed), so that a file of
                              another job never verifies */
    /* Test knobs: none of them changes a byte of the output. */
    int test_tiny;         /* tiny buffers, 4 descriptors, out-of-core merge from 64
                              records: forces every spill and merge path */
    unsigned fd_budget;    /* descriptors for spill files; 0 = probe (>= 4) */
    unsigned density_voxels; /* cap of the density grid; 0 = default.  Changes the
                                density voxel, hence the auto cell: not a budget. */
    int keep_spill;        /* keep the pass-2 files tile_<i>_<j>.raw */
    int last_read;         /* pass 2 is the cloud's last read: it releases the
                              cloud's decoded records once it has read them
                              (gdt_cloud_release_replay) */
    int test_nosync;       /* no fsync of tile files (tests on slow disks): same
                              bytes, but a crash may lose renamed files */
} gdt_tiler_opts;

/* The tile plan: what pass 1 decided.  All counts include duplicates. */
typedef struct gdt_tile_plan {
    int tile;                 /* N */
    int64_t cell;             /* c: texel side in lattice steps */
    int cell_auto, halo_auto; /* 1 when chosen from the density */
    int64_t halo;             /* H in texels */
    int64_t span;             /* T = N * c lattice steps */
    gdt_lattice lattice;      /* the cloud's lattice (texel in CRS: c * sx by c * sy) */
    uint64_t points;          /* points read */
    int64_t min_x, max_x, min_y, max_y; /* lattice bounding box (valid if points > 0) */
    double min_z, max_z;
    int64_t tile_i0, tile_j0; /* index of the south-west tile of the grid */
    int64_t nx, ny;           /* grid of tiles covering the bounding box */
    uint64_t tiles;           /* non-empty tiles */
    uint64_t empty_tiles;     /* nx * ny - tiles */
    uint64_t min_points, median_points, max_points; /* over non-empty tiles
                                 (median: the lower middle); 0 if none */
    double spacing;           /* median point spacing, lattice steps (0 if unknown) */
    int density_shift;        /* density voxel V = 2^shift lattice steps */
    uint64_t density_voxels;  /* active voxels of the density grid */
    uint64_t mem_budget;      /* effective budget, bytes */
} gdt_tile_plan;

/* One non-empty tile. */
typedef struct gdt_tile_desc {
    uint64_t index;           /* position in tile order */
    int64_t i, j;             /* tile indices */
    int64_t x0, y0;           /* south-west corner: tile = [x0, x0+T) x [y0, y0+T) */
    int64_t local_x0, local_y0; /* x0 - h, y0 - h: subtract for tile-local coordinates */
    int64_t local_extent;     /* T + 2h: local coordinates lie in [0, local_extent) */
    uint64_t raw_points;      /* records of the tile in pass 2 (duplicates included) */
    uint64_t points;          /* after the --dup merge (valid after pass 2) */
    uint64_t edge_points;     /* of those, within h of the border */
} gdt_tile_desc;

/* A caller-owned growable point array, reused across tiles. */
typedef struct gdt_point_buf {
    gdt_point *pts;
    size_t n, cap;
} gdt_point_buf;

/* Frees pts and zeroes the struct; b may be NULL. */
void gdt_point_buf_free(gdt_point_buf *b);

typedef struct gdt_tiler_stats {
    double t_pass1, t_pass2, t_merge; /* wall seconds: pass 1, pass 2 spill, --dup merge */
    uint64_t points;              /* points streamed per pass */
    uint64_t bucket_records;      /* records written to intermediate bucket files */
    unsigned spill_levels;        /* bucket levels used by pass 2 (0: direct) */
    unsigned spill_in_memory;     /* 1: pass 2 held every record in memory (no .raw
                                     files; the budget allowed it) */
    uint64_t merged_duplicates;   /* points removed by the --dup merge */
    uint64_t external_merges;     /* tiles merged out of core */
    unsigned merge_levels;        /* deepest partition level of those */
    uint64_t max_tile_points;     /* largest tile after the merge */
    unsigned fd_budget;           /* descriptors used for spill files at most */
    uint64_t mem_budget;          /* effective budget */
} gdt_tiler_stats;

typedef struct gdt_tiler gdt_tiler;

/* Checks the options.  The cloud is borrowed: it must outlive the tiler and
 * not be read by anyone else meanwhile.
 * returns: GDT_EUSAGE 2501/2504, GDT_EIO 4501 (job directory unusable),
 *   GDT_EINTERNAL 7001.
 * Ownership: *out is new, free with gdt_tiler_destroy; NULL on failure. */
gdt_status gdt_tiler_create(gdt_tiler **out, const gdt_tiler_opts *opts, gdt_cloud *cloud,
                            gdt_error *err);

/* Pass 1: streams the cloud (from its current position, normally the
 * start), fills the index, decides cell and halo and, with a job directory,
 * saves <job>/index.vdb.  Call once.
 * returns: the cloud's errors, GDT_EUSAGE 2502/2503, GDT_EIO 4505/4506,
 *   GDT_EINTERNAL. */
gdt_status gdt_tiler_pass1(gdt_tiler *t, gdt_error *err);

/* Pass 1 shared between processes.  Every process creates a tiler over its
 * own cloud, sets the cloud to its share (gdt_cloud_set_range) and reads it
 * with gdt_tiler_pass1_part; the others export what they read
 * (gdt_tiler_pass1_part_export), the planning one adds each share
 * (gdt_tiler_pass1_part_merge, any order) and ends pass 1 with
 * gdt_tiler_pass1_end.  Plan, index and the cloud's filter counts are then
 * those gdt_tiler_pass1 gives over the whole cloud (gdt_tiler_pass1 is part
 * then end).  The planner reports the counts (gdt_cloud_report_counts).
 * returns: as gdt_tiler_pass1; GDT_EUSAGE 2505 (out of order); part_merge
 * GDT_EINTERNAL 7506 (bytes of another build, or damaged). */
gdt_status gdt_tiler_pass1_part(gdt_tiler *t, gdt_error *err);
gdt_status gdt_tiler_pass1_part_export(const gdt_tiler *t, unsigned char **buf, size_t *len,
                                       gdt_error *err);
gdt_status gdt_tiler_pass1_part_merge(gdt_tiler *t, const unsigned char *buf, size_t len,
                                      gdt_error *err);
gdt_status gdt_tiler_pass1_end(gdt_tiler *t, gdt_error *err);

/* Valid after pass 1 until gdt_tiler_destroy; NULL before. */
const gdt_tile_plan *gdt_tiler_get_plan(const gdt_tiler *t);

/* Pass 2: rewinds the cloud, writes every point to its tile's file, checks
 * the per-tile counts against the index, then merges duplicates of every
 * tile (--dup) and writes its .pts and .edge files.  Needs a job directory;
 * removes stale tile files of an earlier run first.  Call once, after pass 1.
 * returns: the cloud's errors, GDT_EINPUT 3501 (input changed between the
 *   passes), GDT_EUSAGE 2505, GDT_EIO 4502..4505, GDT_EINTERNAL 7501/7502. */
gdt_status gdt_tiler_pass2(gdt_tiler *t, gdt_error *err);

/* Pass 2 shared between processes (the ranks of an MPI job) that see the
 * same job directory: this tiler spills every point as gdt_tiler_pass2
 * does, but runs the --dup merge only of the tiles mine(k) says are its
 * own; every other tile goes to ship(k, recs, n), on the caller's thread,
 * in tile order, before the own tiles are merged: recs are its n records
 * in input order when pass 2 held them in memory, NULL when they are in
 * the tile's .raw file of the job directory.  The process that owns the
 * tile merges it (gdt_tiler_merge_shipped) and this tiler takes the result
 * (gdt_tiler_set_tile_files); gdt_tiler_pass2_finish then completes
 * pass 2.  mine() is called from the merge's threads: it must be a pure
 * function.  The files and their sums are those of gdt_tiler_pass2.
 * returns: as gdt_tiler_pass2; ship's errors. */
typedef struct gdt_tiler_share {
    int (*mine)(void *ctx, uint64_t k);
    gdt_status (*ship)(void *ctx, uint64_t k, const gdt_point *recs, uint64_t n,
                       gdt_error *err);
    void *ctx;
} gdt_tiler_share;

gdt_status gdt_tiler_pass2_shared(gdt_tiler *t, const gdt_tiler_share *sh, gdt_error *err);

/* After pass 1: the tile of lattice point (x, y), UINT64_MAX when no tile
 * holds it. */
uint64_t gdt_tiler_tile_of(const gdt_tiler *t, int64_t x, int64_t y);

/* After pass 1: 1 when the records of pass 2 fit in half the memory
 * budget (gdt_tiler_pass2 would hold them in memory). */
int gdt_tiler_pass2_in_memory(const gdt_tiler *t);

/* Pass 2 in shares between processes, each reading a share of the cloud
 * and sending each tile's records to the tile's owner: on the tiler that
 * records the job, after pass 1, prepares the tile directory (as
 * gdt_tiler_pass2 does first); then gdt_tiler_merge_shipped for its own
 * tiles (which records their files here), gdt_tiler_set_tile_files for
 * the others', and gdt_tiler_pass2_finish.  returns: GDT_EUSAGE 2505, GDT_EIO 4501. */
gdt_status gdt_tiler_pass2_open(gdt_tiler *t, gdt_error *err);

/* Pass 2 out of core in shares: each process, after pass 1 (or
 * gdt_tiler_pass2_open on the recording one) and with its cloud set to its
 * share, spills it into .raw files of its own, suffix ".p<part>"
 * (gdt_tiler_spill_part); once every share is spilled, the owner of tile k
 * takes the shares' files 0 .. parts - 1 in that order (a missing file
 * holds none of the tile's points) with gdt_tiler_take_parts: into a fresh
 * array *recs of *n records, the tile's pass-1 count, when the records and the merge's
 * table fit in half the memory budget (the files are then removed), else
 * joined into the tile's .raw file (*recs NULL, as gdt_tiler_join_parts
 * does; *n 0); then merges it (gdt_tiler_merge_shipped with *recs and *n,
 * or NULL) and frees *recs.
 * returns: the spill's errors; take and join: GDT_EINPUT 3501 (not pass
 * 1's count), GDT_EIO 4502/4503/4504, GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_spill_part(gdt_tiler *t, int part, gdt_error *err);
gdt_status gdt_tiler_take_parts(gdt_tiler *t, uint64_t k, int parts, gdt_point **recs,
                                uint64_t *n, gdt_error *err);
gdt_status gdt_tiler_join_parts(gdt_tiler *t, uint64_t k, int parts, gdt_error *err);

/* What the --dup merge of one tile wrote. */
typedef struct gdt_tiler_tile_files {
    uint64_t points, edge; /* records of its .pts and .edge files */
    uint64_t sum[2];       /* their checksums (gdt_tiler_file_sum) */
    uint64_t deepest;      /* partition depth of the merge (0: in memory) */
} gdt_tiler_tile_files;

/* On the process that owns tile k, a tiler after pass 1 (gdt_tiler_import
 * of the shipping tiler's state): the --dup merge of tile k from its
 * records recs[0, n) in input order (reordered in place), or from its .raw
 * file when recs is NULL; writes its .pts and .edge files and describes
 * them in *out.  returns: as the merge of gdt_tiler_pass2. */
gdt_status gdt_tiler_merge_shipped(gdt_tiler *t, uint64_t k, gdt_point *recs, uint64_t n,
                                   gdt_tiler_tile_files *out, gdt_error *err);

/* On the shipping tiler: tile k's files as their owner wrote them. */
gdt_status gdt_tiler_set_tile_files(gdt_tiler *t, uint64_t k, const gdt_tiler_tile_files *in,
                                    gdt_error *err);

/* Makes durable every tile file this process wrote (a syncfs of the job's
 * file system, then the tile directory): what gdt_tiler_pass2 and
 * gdt_tiler_pass2_finish do before they return; a process that merged
 * shipped tiles (gdt_tiler_merge_shipped) calls it before it reports their
 * files.  returns: GDT_EUSAGE 2505 (no job directory), GDT_EIO 4505. */
gdt_status gdt_tiler_sync_files(const gdt_tiler *t, gdt_error *err);

/* After gdt_tiler_pass2_shared and the files of every shipped tile: checks
 * them, syncs the tile directory, and leaves the tiler as gdt_tiler_pass2
 * does.  returns: GDT_EUSAGE 2505 (a tile without its files), GDT_EIO. */
gdt_status gdt_tiler_pass2_finish(gdt_tiler *t, gdt_error *err);

/* The size and checksum (gdt_hash64_wide over the whole file, seeded with
 * gdt_job_file_seed(opts.file_id, k, kind)) of one pass-2 file. */
typedef struct gdt_tiler_file_sum {
    uint64_t size, sum;
} gdt_tiler_file_sum;

/* After pass 2 or an adoption: the records of tile k's .pts file (out[0])
 * and .edge file (out[1]), computed while pass 2 wrote them.
 * returns: GDT_EUSAGE 2505. */
gdt_status gdt_tiler_file_sums(const gdt_tiler *t, uint64_t k, gdt_tiler_file_sum out[2],
                               gdt_error *err);

/* The tiler's state after pass 1 or pass 2 (plan, tile table, counts) as bytes, for
 * the other ranks of an MPI job, which share the job directory and so its
 * tile files: gdt_tiler_import on a tiler of the same options and inputs
 * then behaves as this one after that pass (tile info, loading; after
 * pass 1, gdt_tiler_merge_shipped), without reading the input.  The bytes
 * are for the same build of gdt-tile only.
 * returns: GDT_EUSAGE 2505 (not after pass 1 or 2), GDT_EINTERNAL 7001.
 * Ownership: *buf is malloc'd, the caller frees it. */
gdt_status gdt_tiler_export(const gdt_tiler *t, unsigned char **buf, size_t *len,
                            gdt_error *err);

/* Takes the state gdt_tiler_export gave, on a new tiler (before pass 1).
 * returns: GDT_EUSAGE 2505 (not a new tiler), GDT_EINTERNAL 7503 (bytes of
 * another build or damaged), 7001. */
gdt_status gdt_tiler_import(gdt_tiler *t, const unsigned char *buf, size_t len,
                            gdt_error *err);

/* Resume: after pass 1, takes the .pts and .edge files that a completed
 * pass 2 of the same job left, instead of running pass 2 again.  expect
 * holds 2 records per tile (.pts, .edge, as gdt_tiler_file_sums gave them);
 * every file is read once and must match its size and checksum, and its
 * record counts must fit the pass-1 count of its tile.  Nothing changes
 * unless every file verifies.
 * returns: GDT_EUSAGE 2505 (out of order, no job directory), GDT_EJOB 6501
 *   (a tile file is missing or damaged, or another job's: the message names
 *   it and says why), GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_adopt_pass2(gdt_tiler *t, const gdt_tiler_file_sum *expect,
                                 gdt_error *err);

/* Number of non-empty tiles (0 before pass 1). */
uint64_t gdt_tiler_tile_count(const gdt_tiler *t);

/* 1 when every tile has its files (after pass 2, its adoption, or the
 * import of a state after pass 2). */
int gdt_tiler_pass2_done(const gdt_tiler *t);

/* Describes tile k (k < gdt_tiler_tile_count).  returns: GDT_EUSAGE 2505. */
gdt_status gdt_tiler_tile_info(const gdt_tiler *t, uint64_t k, gdt_tile_desc *out,
                               gdt_error *err);

/* Path of tile k's file of the given kind ("raw", "pts" or "edge") into buf;
 * returns 0, or -1 if it does not fit, k is out of range or there is no job
 * directory. */
int gdt_tiler_tile_path(const gdt_tiler *t, uint64_t k, const char *kind, char *buf,
                        size_t len);

/* Loads tile k after pass 2: pts receives the tile's deduplicated points
 * sorted by ordinal, halo its halo points (from the neighbours' .edge files,
 * deduplicated, inside the halo box, not in the tile) sorted by ordinal.
 * Both buffers are grown as needed and reused; their old content is dropped.
 * returns: GDT_EUSAGE 2505 (before pass 2, bad k), 2506 (tile and halo
 *   exceed half the memory budget), GDT_EIO 4504, GDT_EJOB 6503,
 *   GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_load_tile(gdt_tiler *t, uint64_t k, gdt_point_buf *pts,
                               gdt_point_buf *halo, gdt_error *err);

/* As gdt_tiler_load_tile, but the tile's own points go to xy (the caller's,
 * room for gdt_tile_desc.points) as coordinates relative to (x0, y0), in
 * the same order, their z to z (the same room; NULL: not wanted), and *n
 * receives their count: the records are read through a small buffer and
 * never held whole.  The caller chooses x0, y0 so that the differences fit
 * its coordinate range. */
gdt_status gdt_tiler_load_tile_local(gdt_tiler *t, uint64_t k, int64_t x0, int64_t y0,
                                     gdt_ipt *xy, double *z, size_t *n, gdt_point_buf *halo,
                                     gdt_error *err);

/* A subset of every tile's points replaces them after pass 2 (the ground
 * filter of gdt_ground.h, which needs each tile's points and those of the
 * cloud within its reach):
 *  - gdt_tiler_load_reach: tile k's points into own (sorted by ordinal) and
 *    every other point within reach of the tile (reach <= max(h,
 *    opts.edge_min)) into around (sorted by ordinal); refuses (2506) more
 *    than max_points in all.  Reads only: calls for different tiles with
 *    different buffers may run concurrently.
 *  - gdt_tiler_write_subset: writes the points own[i] with keep[i] != 0
 *    (own: the n points load_reach gave, in that order) as tile k's .gpts
 *    file and their edge (within h) as its .gedge file, each synced and
 *    renamed, with the sums of a .pts and an .edge file; *out describes
 *    them.  Calls for different tiles may run concurrently.
 *  - gdt_tiler_take_subsets: once every tile has its subset (files[k],
 *    k < tiles, as write_subset described them), renames them over the
 *    .pts and .edge files and takes their counts and sums; the tiler then
 *    behaves as after a pass 2 of the subset (a tile may hold no point).
 * returns: GDT_EUSAGE 2505 (not after pass 2; reach too wide), 2506;
 *   GDT_EIO 4502..4505; GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_load_reach(const gdt_tiler *t, uint64_t k, int64_t reach,
                                uint64_t max_points, gdt_point_buf *own, gdt_point_buf *around,
                                gdt_error *err);
gdt_status gdt_tiler_write_subset(const gdt_tiler *t, uint64_t k, const gdt_point *own,
                                  size_t n, const uint8_t *keep, gdt_tiler_tile_files *out,
                                  gdt_error *err);
gdt_status gdt_tiler_take_subsets(gdt_tiler *t, const gdt_tiler_tile_files *files,
                                  gdt_error *err);

/* A subset that an earlier run wrote for tile k (pass 2 writes the same
 * files again, and leaves .gpts and .gedge files alone): verifies them
 * against want (sizes and sums as gdt_tiler_write_subset gave them; their
 * record counts must fit the tile) and, when pts is not NULL, loads the
 * subset's points.  *ok = 0 when a file is missing or differs (then it is
 * simply written again).  Reads only.
 * returns: GDT_OK; GDT_EUSAGE 2505; GDT_EIO 4504; GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_check_subset(const gdt_tiler *t, uint64_t k,
                                  const gdt_tiler_tile_files *want, gdt_point_buf *pts, int *ok,
                                  gdt_error *err);

/* With opts.keep_spill, after pass 2: tile k's pass-2 records (every
 * point of the tile, duplicates included, in input order) from its .raw
 * file into out; gdt_tiler_drop_raw removes the file.  Reads only: calls
 * for different tiles with different buffers may run concurrently.
 * returns: GDT_EUSAGE 2505 (no kept .raw files), 2506 (more than
 * max_points), GDT_EIO 4504, GDT_EINTERNAL 7001. */
gdt_status gdt_tiler_load_raw(const gdt_tiler *t, uint64_t k, uint64_t max_points,
                              gdt_point_buf *out, gdt_error *err);
void gdt_tiler_drop_raw(const gdt_tiler *t, uint64_t k);

const gdt_tiler_stats *gdt_tiler_get_stats(const gdt_tiler *t);

/* t may be NULL.  Leaves the job directory's files in place. */
void gdt_tiler_destroy(gdt_tiler *t);

/* --info --tile N: pass 1 only, the plan in *out (index saved when
 * opts->job_dir is set).  The cloud is read once from its current position. */
gdt_status gdt_tiler_plan(const gdt_tiler_opts *opts, gdt_cloud *cloud, gdt_tile_plan *out,
                          gdt_error *err);

/* Human-readable tile plan ("tile plan:" block, same layout as --info). */
void gdt_tile_plan_print(FILE *out, const gdt_tile_plan *plan);

/* Effective memory budget for the given options (resolves 0 = auto). */
uint64_t gdt_tiler_budget(const gdt_tiler_opts *opts);

#ifdef __cplusplus
}
#endif
#endif
