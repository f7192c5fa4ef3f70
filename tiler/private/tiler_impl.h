/* tiler_impl.h — state of the tiler shared by its source files.
 *
 * Invariants once pass 1 is done:
 *  - tiles[0..ntiles) are the non-empty tiles sorted by (j, i); tiles[k].count
 *    is the pass-1 count, > 0; map sends (i, j) to k for exactly these tiles;
 *  - plan.span = plan.tile * plan.cell, and (tile + 2 halo) * cell <= 2^31.
 * After pass 2: tiles[k].written == tiles[k].count, and .points / .edge are
 * the record counts of tile_<i>_<j>.pts / .edge.
 */
#ifndef GDT_TILER_IMPL_H
#define GDT_TILER_IMPL_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_tiler.h"
#include "gdt_vdb_index.h"

typedef struct tl_tile {
    int64_t i, j;
    uint64_t count;     /* pass 1 */
    uint64_t written;   /* pass 2 */
    uint64_t points;    /* after the --dup merge */
    uint64_t edge;      /* records of the .edge file */
    uint64_t sum[2];    /* checksums of the .pts and .edge files */
} tl_tile;

/* Pass 2's mark of a tile (gdt_tiler.merge_mark): its files are written,
 * and the partition depth of its --dup merge (0: in memory; at most 127). */
#define TL_MARK_MERGED 0x80u
#define TL_MARK_DEPTH 0x7fu

/* Open addressing (linear probing) from tile (i, j) to a value. */
typedef struct tl_map_entry {
    int64_t i, j;
    uint64_t v;
    uint64_t used;
} tl_map_entry;

typedef struct tl_map {
    tl_map_entry *e;    /* owned */
    size_t cap;         /* power of two, or 0 */
    size_t n;
} tl_map;

/* Looks (i, j) up; returns a pointer to its value, or NULL. */
uint64_t *tl_map_find(const tl_map *m, int64_t i, int64_t j);
/* Finds or inserts (i, j) (value 0 when new); grows at 1/2 load, so
 * pointers from earlier calls are invalid after it.  returns: GDT_EINTERNAL
 * 7001. */
gdt_status tl_map_upsert(tl_map *m, int64_t i, int64_t j, uint64_t **val, gdt_error *err);
void tl_map_free(tl_map *m);

/* density.c: the density histogram of pass 1 (rules in density.c). */
typedef struct tl_density {
    tl_map map;             /* (vx, vy) -> points, at shift */
    int shift;              /* voxel V = 2^shift lattice steps */
    size_t max_voxels;
    uint64_t tree_bytes;    /* OpenVDB node bytes of the final voxels (after finish) */
} tl_density;

gdt_status tl_density_add(tl_density *d, const gdt_point *pts, size_t n, gdt_error *err);
/* Coarsens until the voxels' OpenVDB tree fits in node_budget bytes
 * (node_bytes: leaf, lower and upper internal node).  node_budget must be at
 * least 4 * (sum of node_bytes). */
gdt_status tl_density_finish(tl_density *d, uint64_t node_budget, const size_t node_bytes[3],
                             gdt_error *err);
void tl_density_free(tl_density *d);

/* density.c: the voxels of d as (x, y, count) triples (*v malloc'd, *n
 * triples); and the sum of d and such triples of a histogram at shift s:
 * the histogram of the union of the two point sets, at the shift that
 * union would have reached (both rules are monotone). */
gdt_status tl_density_export(const tl_density *d, uint64_t **v, size_t *n, gdt_error *err);
gdt_status tl_density_merge(tl_density *d, int s, const uint64_t *v, size_t n, gdt_error *err);

/* Sizes of every buffer, derived from the budget (or the test knobs). */
typedef struct tl_sizes {
    size_t read_cap;        /* points per cloud read */
    size_t write_bytes;     /* pass 2 write buffers, all files of one level */
    size_t min_file_recs;   /* smallest per-file write buffer worth a direct level */
    size_t merge_cap;       /* records held by the --dup merge */
    unsigned merge_k;       /* partitions per merge level */
    size_t part_recs;       /* write buffer per merge partition, records */
    size_t merge_read_recs; /* read buffer per merged run, records */
    size_t halo_read_recs;  /* read buffer for a neighbour's .edge file */
    size_t tiles_bytes;     /* cap of the tile table */
} tl_sizes;

struct gdt_tiler {
    gdt_tiler_opts opts;    /* job_dir points at job_dir below */
    char *job_dir;          /* owned, NULL without a job directory */
    char *tiles_dir;        /* owned */
    gdt_cloud *cloud;       /* borrowed */
    gdt_log *log;
    uint64_t budget;
    unsigned fd_budget;
    tl_sizes sz;
    int64_t user_cell;      /* > 0: given --cell in lattice steps */
    int state;              /* 0 new, 1 after pass 1, 2 after pass 2, 3 a shared pass 2
                               waiting for shipped tiles, 4 a share of pass 1 read (its
                               bounds, counts and histograms: not yet a plan), 5 a pass 2
                               in shares (gdt_tiler_pass2_open), -1 failed */
    double pass1_t0;        /* when pass 1 began */
    char spill_part[24];    /* "" or ".p<R>": the suffix of the .raw and bucket files a
                               share of pass 2 writes (gdt_tiler_spill_part) */
    double merge_t0;        /* when pass 2's --dup merge began */
    uint8_t *merge_mark;    /* ntiles marks (TL_MARK_*) while pass 2 merges; owned */
    gdt_tile_plan plan;
    tl_tile *tiles;         /* owned */
    uint64_t ntiles;
    tl_map map;             /* (i, j) -> index in tiles (after pass 1) */
    tl_density density;     /* pass 1 */
    gdt_tiler_stats stats;
    /* Pass 2 in memory (spill.c): when set, the records of tile k are
     * resident[res_off[k] .. res_off[k + 1]) in input order, there are no
     * .raw files, and the --dup merge runs res_workers workers.  Owned;
     * freed by the merge. */
    gdt_point *resident;
    uint64_t *res_off;
    unsigned res_workers;
};

/* plan.c: turns the pass-1 results into the plan and the tile table.
 * With t->user_cell > 0, t->map holds the directly counted tiles (value =
 * count); otherwise tiles are derived from the density grid.  Fills
 * t->plan, t->tiles, t->ntiles and rebuilds t->map (value = index). */
gdt_status tl_plan_finish(gdt_tiler *t, gdt_error *err);

/* spill.c: pass 2 proper (after the rewind): every point to its tile's
 * .raw file, or to its tile's range of t->resident when the budget holds
 * them all; counts in tiles[].written. */
gdt_status tl_spill(gdt_tiler *t, gdt_error *err);

/* merge_dup.c: the --dup merge of every tile (.raw or its resident
 * records -> .pts + .edge), on up to opts.threads workers; fills
 * tiles[].points/.edge and the merge counters of t->stats, and frees the
 * resident records. */
gdt_status tl_merge_tiles(gdt_tiler *t, const gdt_tiler_share *sh, gdt_error *err);

/* merge_dup.c: the --dup merge of tile k alone, from recs[0, n) (input
 * order) or, when recs is NULL, from its .raw file; on the caller's thread. */
gdt_status tl_merge_one(gdt_tiler *t, uint64_t k, gdt_point *recs, uint64_t n, gdt_error *err);

/* t->merge_mark, allocated (zeroed) if it is not yet.  returns: 7001. */
gdt_status tl_merge_marks(gdt_tiler *t, gdt_error *err);

/* The merge counters of t->stats from the tile table (every tile merged). */
void tl_merge_stats(gdt_tiler *t);

/* Paths of tile k's files; malloc'd, NULL when out of memory.  kind is
 * "raw", "pts", "edge", "gpts" or "gedge"; tmp adds ".tmp". */
char *tl_tile_file(const gdt_tiler *t, uint64_t k, const char *kind, int tmp);

/* 1 when lattice point p of the tile [x0, x0 + span) x [y0, y0 + span)
 * lies within h of its border (an .edge record). */
static inline int tl_on_edge(const gdt_point *p, int64_t x0, int64_t y0, int64_t span, int64_t h)
{
    return p->x - x0 < h || x0 + span - 1 - p->x < h || p->y - y0 < h ||
           y0 + span - 1 - p->y < h;
}

/* Width of the .edge files in lattice steps: the halo h, or opts.edge_min
 * when that is wider. */
static inline int64_t tl_edge_width(const gdt_tiler *t)
{
    int64_t h = t->plan.halo * t->plan.cell;
    return t->opts.edge_min > h ? t->opts.edge_min : h;
}

/* Reports progress (opts.progress); GDT_EINTERRUPTED 1301 when told to stop. */
gdt_status tl_progress(gdt_tiler *t, int stage, uint64_t done, uint64_t total, gdt_error *err);

/* Tile index of lattice point (x, y) or UINT64_MAX if no such tile. */
uint64_t tl_tile_of(const gdt_tiler *t, int64_t x, int64_t y);

/* Pass 1 with a given --cell: the points counted into t->map by tile (at
 * most tl_max_counted_tiles tiles, else GDT_EUSAGE 2503). */
gdt_status tl_count_tiles(gdt_tiler *t, const gdt_point *pts, size_t n, gdt_error *err);
size_t tl_max_counted_tiles(const gdt_tiler *t);

/* 1 when t has a plan and tile table (after pass 1). */
static inline int tl_planned(const gdt_tiler *t)
{
    return t->state == 1 || t->state == 2 || t->state == 3 || t->state == 5;
}

/* spill.c: the spill to .raw files (and buckets) of what the cloud gives,
 * whatever the budget; counts in tiles[].written. */
gdt_status tl_spill_files(gdt_tiler *t, gdt_error *err);

/* spill.c: the --dup merge workers of a pass 2 in memory, 0 when the
 * records do not fit in half the budget. */
unsigned tl_resident_workers(const gdt_tiler *t);

/* Frees the resident records of pass 2 (if any). */
void tl_free_resident(gdt_tiler *t);

/* Records the --dup merge holds at once: its hash table stores index + 1 in
 * 32 bits. */
#define TL_MERGE_CAP_MAX (UINT64_C(1) << 31)

/* Bytes of the --dup merge's hash table for a tile of n records (collapse
 * in merge_dup.c: a power of two of at least 2n 32-bit slots). */
uint64_t tl_collapse_table_bytes(uint64_t n);

#endif
