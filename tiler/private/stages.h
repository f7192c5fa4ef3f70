/* stages.h — the stages of a tiled run (tiled_run.h) behind one context.
 *
 * A run is a tr_run context driven through the stages below in this order;
 * the single-process run (tiled_run.c) calls every one of them once.  Each
 * stage reads what the earlier ones left in the context and the job
 * directory J (--job, default OUT.ply.gdt-job) and returns gdt_status with
 * the error in a caller-owned gdt_error.  After any failure the caller
 * skips the remaining stages and calls tr_run_close, which releases
 * everything, keeps the job for a rerun (or removes it, see there) and
 * returns the status of the run.
 *
 *   tr_run_init         run_job.c     job paths; every output path checked
 *   tr_run_start_core   run_passes.c  OpenCL core started on its own thread;
 *                                     certifier
 *   tr_run_prepare_job  run_job.c     J made and locked; --restart; J/job.db
 *                                     opened and checked against options
 *                                     and inputs (fingerprint)
 *   tr_run_pass1        run_passes.c  cloud, tiler, pass 1 (J/index.vdb);
 *                                     core joined; plan checks
 *   tr_run_pass2        run_passes.c  pass 2 (the .pts, .edge files in J/tiles) or its
 *                                     recorded files adopted; with --ground
 *                                     the ground filter in it (run_ground.c);
 *                                     vertex bases
 *   tr_run_output_start run_finish.c  trim graph, DEM, mesh writer thread
 *   tr_run_tiles        run_tiles.c   core + post thread per tile: the
 *                                     .tri files in J/tiles and their records
 *   tr_run_merge        run_merge.c   seam merge: J/merge.faces (J/merge.dem)
 *   tr_run_finish       run_finish.c  Euler check, mesh and DEM completed,
 *                                     --check, --json, summary, clean-up
 *   tr_run_close        run_finish.c  release; returns the run's status
 *
 * Threads: every stage runs on the caller's thread; the helper threads a
 * stage starts (core creation, post stage, writer, reclaim) are joined by a
 * later stage or by tr_run_close. */
#ifndef GDT_STAGES_H
#define GDT_STAGES_H

#include <pthread.h>
#include <stddef.h>
#include <stdint.h>

#include "gdt_certify.h"
#include "gdt_cli.h"
#include "gdt_cloud.h"
#include "gdt_core.h"
#include "gdt_error.h"
#include "gdt_grow.h"
#include "gdt_las_copy.h"
#include "gdt_mesh.h"
#include "gdt_mesh_out.h"
#include "gdt_raster.h"
#include "gdt_seam.h"
#include "gdt_tiler.h"
#include "gdt_trim.h"
#include "private/filter_report.h"
#include "private/job.h"
#include "private/progress.h"
#include "private/run_stats.h"
#include "private/tiled_dem.h"
#include "private/tiled_out.h"
#include "private/trim_report.h"

/* One rank's share of an MPI run (its tile stage). */
typedef struct tr_rank_stats {
    uint64_t tiles, vertices, certified, reused;
    double t_tiles, t_core, t_certify, t_post;
    double t_device, t_device_span; /* as tr_summary's, for its own devices */
    double t_write; /* its parts of a mesh written in parts: vertices, faces, sync */
    double t_pass1, t_pass2; /* its own parts of the passes (tr_summary's t_pass*_own) */
    uint64_t placed_early; /* tiles whose faces it wrote as their place became known,
                            * before PARTS */
    uint64_t on_demand;    /* of its tiles, those it took on demand (after GO's) */
    uint64_t ground_tiles; /* --ground: tiles it classified (or adopted) */
    double t_ground;       /* and its time in the filter */
    uint64_t replayed;     /* compressed inputs (its shares of them) read back from
                            * its replay instead of decoded again */
    char device[128];
} tr_rank_stats;

/* What the summary and --json report. */
typedef struct tr_summary {
    uint64_t points_read, vertices, tiles, faces, certified, merge_faces;
    uint64_t max_tile_points, max_halo_points, gcd_tiles, insert_tiles;
    double t_pass1, t_pass2, t_tiles, t_core, t_certify, t_post, t_merge, t_write, t_check, t_total;
    /* the devices' busy time in the tile stage (gdt_core_device_busy, summed
     * over the cores) and the stage's time times the number of cores: their
     * ratio is the share of the stage the devices worked */
    double t_device, t_device_span;
    double t_parts; /* MPI, a mesh in parts: from PARTS to the last part synced */
    /* MPI: this rank's own part of pass 1 (reading its share, or the whole
     * cloud when rank 0 reads alone) and of pass 2 (reading and spilling its
     * share or, when rank 0 spills alone, the whole cloud; merging its
     * tiles; on another rank, syncing their files too, which rank 0 does
     * with the job's pass 2 once every rank has reported) */
    double t_pass1_own, t_pass2_own;
    gdt_cert_stats cert;
    gdt_merge_stats merge;
    int checked;
    char device[256];
    int resumed, pass2_reused;
    uint64_t tiles_reused, tiles_redone;
    gdt_trim_counts trim; /* faces before trimming and the drops (with a rule on) */
    int dem_done;
    gdt_dem_geo dem_geo;
    gdt_dem_stats dem_stats;
    double t_dem;
    uint64_t ground_points, nonground_points; /* --ground: the classes of pass 2's
                                 points (deduplicated), when this run classified */
    double t_ground;        /* the ground filter's wall time (0: adopted, or off) */
    double t_ground_own;    /* of which this process's own tiles (a shared filter) */
    uint64_t ground_tiles_reused; /* subsets an earlier, stopped run classified */
    uint64_t ground_bits_size, ground_bits_sum; /* --ground-out: J/ground.bits */
    int ground_out_shared;  /* --ground-out: its records written by the ranks in shares */
    int nranks;             /* ranks of an MPI run; 0 in a plain run */
    tr_rank_stats *ranks;   /* nranks of them, rank 0 first; owned */
} tr_summary;

/* A finished tile file waiting for its journal record. */
typedef struct tr_pending {
    uint64_t k, size, checksum;
} tr_pending;

/* One triangulated tile on its way from the core to its .tri file.  The
 * main thread owns a slot until it hands it to the post stage, the post
 * stage until it is joined. */
typedef struct tr_slot {
    uint64_t k;
    gdt_tile_desc d;
    size_t n, nh;       /* own points, halo points */
    gdt_ipt *lh;        /* nh halo points, tile-local; owned */
    size_t cap_lh;
    gdt_mesh mesh;      /* the core's triangulation of the own points */
    double *z;          /* their z, by vertex; owned */
    size_t cap_z;
} tr_slot;

typedef struct tr_run tr_run;
typedef struct tr_ground_share tr_ground_share;
typedef struct tr_gout_share tr_gout_share;

/* What running the core on tiles adds to the run's figures (per core,
 * added up at the end of the tile stage). */
typedef struct tr_core_counts {
    uint64_t max_tile_points, max_halo_points, gcd_tiles, insert_tiles;
    double t_core;
} tr_core_counts;

/* Several devices: the cores beyond the first, each on a thread of its own
 * (run_lanes.c). */
typedef struct tr_lanes tr_lanes;

/* Pass 1 shared with other processes (the MPI scheduler): after the cloud
 * and the tiler exist, begin() says whether pass 1 is shared and, when it
 * is, gives this process's share [*first, *end) of the records (the others
 * were told theirs); the share is read (gdt_tiler_pass1_part), then
 * collect() adds the others' shares into the tiler (gdt_tiler_pass1_part_
 * merge); it is called whatever the own share's status (own, own_err: the
 * others' answers are always taken) and returns the first failure. */
typedef struct tr_pass1_share {
    gdt_status (*begin)(void *ctx, int *shared, uint64_t *first, uint64_t *end,
                        gdt_error *err);
    gdt_status (*collect)(void *ctx, gdt_status own, gdt_error *err);
    void *ctx;
} tr_pass1_share;

/* Pass 2 shared with other processes (the MPI scheduler): when pass 2 is
 * to be run, begin() is called after pass 1 (the others get the tiler's
 * state), then gdt_tiler_pass2_shared with sh, then collect() (the shipped
 * tiles' files into the tiler, gdt_tiler_set_tile_files), then
 * gdt_tiler_pass2_finish; an adopted pass 2 calls none of them. */
typedef struct tr_pass2_share {
    gdt_tiler_share sh;
    gdt_status (*begin)(void *ctx, gdt_error *err);
    gdt_status (*collect)(void *ctx, gdt_error *err);
    /* tried first: pass 2 read in shares by the processes, every tile's
     * records sent to its owner; *whole = 1 when it ran pass 2 to
     * gdt_tiler_pass2_finish, 0 when it cannot (then the above) */
    gdt_status (*spill)(void *ctx, int *whole, gdt_error *err);
    void *ctx;
} tr_pass2_share;

/* The post stage of a tile (certification, seam, sorted faces, .tri file,
 * pending record) runs on its own thread while the main thread loads the
 * next tile and runs the core on it.  While it runs it alone touches cert,
 * count, fbuf, seam, seam_total, pending/npending/nsynced, t_flushed, ttile and
 * s.cert, s.certified, s.t_certify, s.t_post; the main thread reads them only
 * after tr_post_join. */
typedef struct tr_post {
    pthread_t tid;
    int running;        /* a thread was started and not yet joined */
    tr_run *c;
    tr_slot *slot;
    int announce;       /* a whole run's tile stage: the tile is announced as done */
    gdt_status st;
    gdt_error err;
} tr_post;

/* What the tile stage leaves behind (the core with its device memory, the
 * slots' meshes, the post stage's arrays: about the memory of a tile),
 * released on a thread of its own while the merge and the output go on;
 * unmapping it takes a tenth of a second per GB. */
typedef struct tr_reclaim {
    pthread_t tid;
    int running;        /* a thread was started and not yet joined */
    gdt_core *core;
    gdt_mesh mesh[2];
    void *bufs[5];
} tr_reclaim;

/* The seam merge on a thread of its own, beside the tile stage: a row of
 * tiles is merged as soon as its tiles have their .tri files (ready, which
 * the tile stage or the MPI scheduler raises, tr_merge_ready).  It has its
 * own seam and buffers; mu guards ready and quit. */
typedef struct tr_merge_bg {
    pthread_t tid;
    int running;        /* a thread was started and not yet joined */
    pthread_mutex_t mu;
    pthread_cond_t cv;
    int sync_made;      /* mu and cv exist */
    uint64_t ready;     /* tiles [0, ready) have their .tri files */
    int quit;           /* the run gives up: stop at the next wait */
    gdt_status st;
    gdt_error err;
    double t_end;       /* when the thread finished */
} tr_merge_bg;

/* The core is created (OpenCL context, kernels from the cache: about 0.2 s
 * on a CPU device) on a thread of its own while pass 1 reads the input, and
 * joined after it.  When pass 1 fails first, its error is the one reported:
 * the device's may be a consequence (the compiler inside the OpenCL
 * runtime removes its temporary files on SIGXFSZ, which a write beyond
 * the file size limit raises on the thread that made it). */
typedef struct tr_core_start {
    gdt_core_opts opts;
    char **specs;       /* several devices: --device as single SPECs
                           (gdt_ocl_device_list), opts.device = specs[0]; owned */
    size_t nspecs;
    gdt_core *core;     /* on opts.device */
    gdt_core **more;    /* on specs[1..nspecs), then the further queues of every
                           device (core_queues): the tile stage's lanes; owned */
    size_t nmore;       /* created */
    size_t cap_more;    /* room in more */
    int queues;         /* --queues (0: auto) */
    int tile;           /* the tile side (auto queues: whether two tiles fit) */
    gdt_error err;
    gdt_status st;
    pthread_t thread;
    int running;
    int preload_dem; /* the process writes a DEM: the thread also loads the DEM
                      * writer's plug-in (set before tr_run_start_core) */
} tr_core_start;

/* The context of one run.  Zeroed and filled by tr_run_init; released by
 * tr_run_close.  Owns everything it points to except opts. */
struct tr_run {
    const gdt_options *opts;
    int tile;           /* the tile side: --tile, or chosen for the device
                           (tr_run_start_core) */
    int tile_auto;      /* tile was chosen, not given */
    gdt_log log;
    double t_start;     /* gdt_now() at tr_run_init */
    char *job;          /* owned */
    char *tiles_dir;    /* owned */
    char *ground_bits;  /* J/ground.bits (--ground-out); owned */
    int created;        /* this run made the job directory */
    int own_dir;        /* a run of this job made it (gdt_job_lock) */
    int removal_parts;  /* > 1: the job's tile files are removed by this many processes
                         * (MPI ranks) after the run, not by tr_run_finish alone */
    int removal_due;    /* tr_run_finish removed the journal and left the tile files
                         * to those processes (removal_parts > 1) */
    tr_core_start cstart; /* the core's creation, until tr_run_pass1 joins it */
    gdt_cloud *cloud;
    gdt_tiler *tiler;
    gdt_core *core;
    gdt_certifier *certifier;
    const gdt_tile_plan *plan;
    uint64_t *base;     /* ntiles + 1 output index of each tile's first vertex */
    gdt_point_buf halo; /* the current tile's halo */
    tr_slot slot[2];    /* the i-th tile a tile stage runs uses slot[i & 1] (one
                           device; with several, the lanes' slots) */
    tr_lanes *lanes;    /* several devices, during the tile stage; else NULL */
    tr_post post;
    tr_reclaim reclaim;
    tr_out *out;        /* the mesh writer, from the tile stage on */
    int tri_cached;     /* the .tri files go through the page cache: this rank's mesh
                         * writer reads them back once the tile stage is over (an
                         * MPI rank other than 0 writing its part) */
    int out_parts;      /* asked by the MPI run before tr_run_output_start: the tiles'
                         * owners write the mesh in parts when it is a plain PLY;
                         * tr_run_output_start leaves it set only then */
    char *check_ply;    /* --check of a text output: the PLY copy in the job; owned */
    tr_dem *dem;        /* --dem: fed by the mesh writer */
    /* the mesh header's filter and trim lines: live until the writer is done */
    char filter_comment[GDT_FILTER_COMMENT_MAX];
    char trim_comment[GDT_TRIM_TEXT_MAX];
    char ground_comment[256];
    const char *filter_comments[3];
    uint8_t *cert;
    size_t cap_cert;
    uint32_t *count;    /* bucket counts for the face sort */
    size_t cap_count;
    unsigned char *fbuf; /* the .tri file image */
    size_t cap_fbuf;
    gdt_seam seam;      /* one tile's seam (tile stage) */
    gdt_seam mseam;     /* one row's seam (merge) */
    unsigned char *mbuf; /* the merge's read buffer */
    size_t cap_mbuf;
    tr_merge_bg mbg;    /* the merge's thread (tr_run_merge_start) */
    gdt_trim_rule trim; /* --max-edge, --concavity with the lattice steps */
    gdt_trim_tile ttile; /* one tile's trim section (post stage) */
    gdt_trim_graph *tgraph; /* the run's long edges (merge), with a rule on */
    gdt_trim_open *topen; /* one tile's open edges (merge) */
    size_t ntopen, cap_topen;
    uint64_t seam_total; /* seam vertices of all tiles (merge progress) */
    gdt_job *jobdb;
    uint64_t job_id[2];   /* seeds every checksum the journal records */
    int lock_fd;          /* the job directory's lock (gdt_job_lock), or -1 */
    tr_pending *pending;  /* finished tiles not yet recorded */
    size_t npending, cap_pending;
    size_t nsynced;       /* pending[0, nsynced) are on disk, to be recorded */
    double t_flushed;
    gdt_progress prog;
    tr_summary s;
    const tr_pass1_share *p1share; /* set by the caller after tr_run_init; NULL: alone */
    const tr_pass2_share *p2share; /* likewise */
    const tr_ground_share *gshare; /* likewise */
    const tr_gout_share *goshare;  /* likewise (--ground-out written in shares) */
};

/* 1 when a signal asked the run to stop. */
static inline int tr_stopped(const tr_run *c)
{
    return c->opts->stop != NULL && *c->opts->stop != 0;
}

/* Grows an array to at least need elements (gdt_grow.h: doubling, the
 * pointer moved without a void ** cast). */
static inline int tr_reserve(void *pp, size_t *cap, size_t need, size_t elem)
{
    return gdt_grow(pp, cap, need, elem, need);
}

/* ---- run_job.c: the job directory and its journal ---- */

/* Zeroes c and sets it up for opts (which must outlive c): log, progress,
 * the job path (opts->job, or OUT.gdt-job) and J/tiles, then checks every
 * path (gdt_cli_check_paths).  Nothing is written.  Call tr_run_close
 * also when it fails.
 * returns: GDT_OK; GDT_EINTERNAL 7001; gdt_cli_check_paths' errors. */
gdt_status tr_run_init(tr_run *c, const gdt_options *opts, gdt_error *err);

/* After tr_run_start_core: makes J (c->created) and takes its lock
 * (c->lock_fd, c->own_dir) before anything in it is read or removed; with
 * --restart removes the job's files; then opens or creates J/job.db
 * (c->jobdb, c->job_id) and checks that it belongs to this command: the
 * recorded params (options and absolute input paths) and fingerprint (per
 * input size, mtime and hashes) must match, unless the journal holds no
 * finished work, when it is taken over.  Records "output" and "products"
 * (for --resume); c->s.resumed when the journal was this command's.
 * returns: GDT_OK; GDT_EIO 4801, 49xx; GDT_EJOB 6901, 6903 (options
 * differ), 6904 (an input changed), 6906; GDT_EINPUT 3802; GDT_EUSAGE
 * 2106. */
gdt_status tr_run_prepare_job(tr_run *c, gdt_error *err);

/* Removes the files a job directory holds (job.db and its WAL files,
 * index.vdb, merge.faces, merge.dem, check.ply, ground.bits, tiles/ with our tile
 * files)
 * and tiles/ if empty.  With final (the end of the run that holds the
 * lock), the lock file goes last, then the job directory itself if it is
 * empty and own_dir; otherwise (--restart) the lock file and the directory
 * stay.  Never removes anything else: --job may name a directory the user
 * owns. */
void tr_remove_job_files(const char *job, int final, int own_dir);

/* The first step of tr_remove_job_files alone: the journal and the job's
 * other files beside tiles/ (a removal cut short must not leave a journal
 * that vouches for files already gone). */
void tr_remove_job_journal(const char *job);

/* Part part of parts of the removal of tiles/: the tile files whose name
 * hashes to part (so that K processes share it without a word, each file
 * once); a file already gone is no error.  tr_remove_job_files after the
 * last part removes whatever is left and the directories. */
void tr_remove_tile_share(const char *tiles_dir, int part, int parts);

/* ---- run_passes.c: the device, pass 1 and pass 2 ---- */

/* After tr_run_init: starts creating the OpenCL core on a thread of its own
 * (c->cstart; joined by tr_run_pass1 or tr_run_close) and creates the
 * certifier.
 * returns: GDT_OK; the certifier's errors. */
gdt_status tr_run_start_core(tr_run *c, gdt_error *err);

/* Joins the core's creation (if it runs) and hands the core to *core.
 * Returns the creation's status; on failure its error replaces *err (err
 * may be NULL). */
gdt_status tr_core_start_join(tr_core_start *cs, gdt_core **core, gdt_error *err);

/* After tr_run_prepare_job: opens the cloud (c->cloud; LAZ replayed from
 * J), creates the tiler (c->tiler) and runs pass 1 (writes J/index.vdb);
 * joins the core (c->core, c->s.device); c->plan and c->s.t_pass1.  Refuses
 * a cloud wider than the merge frame and a --dem-res the lattice refuses,
 * before pass 2.
 * returns: GDT_OK; the cloud's, tiler's and core's errors; GDT_EINTERRUPTED
 * 1302. */
gdt_status tr_run_pass1(tr_run *c, gdt_error *err);

/* Whether pass 2 reads the run's cloud for the last time (--ground-out
 * reads it a third time): then its decoded records are released once read
 * (gdt_cloud_release_replay). */
static inline int tr_pass2_last_read(const gdt_options *opts)
{
    return opts->ground_out == NULL;
}

/* Another rank of an MPI job, told its share of pass 1: opens the run's
 * cloud (c->cloud, kept: its replay holds the share's decoded LAZ records
 * for the rank's pass 2) and a tiler of its own (no job directory), reads
 * the records [first, end) (gdt_tiler_pass1_part) and returns what it read
 * as bytes (*buf malloc'd, gdt_tiler_pass1_part_export) and the points the
 * filter kept (*kept); nothing else of c changes.
 * returns: the cloud's and tiler's errors. */
gdt_status tr_run_pass1_share(tr_run *c, uint64_t first, uint64_t end, unsigned char **buf,
                              size_t *len, uint64_t *kept, gdt_error *err);

/* After tr_run_pass1: when the journal records pass 2 done and every
 * recorded .pts/.edge file matches, adopts them (c->s.pass2_reused);
 * otherwise clears the journal's pass-2 and tile records, runs pass 2
 * (writes J/tiles/tile_*.pts, .edge) and records its files and the stage.
 * With c->p2share, pass 2 is shared (tr_pass2_share).
 * Then c->base (each tile's first output vertex), c->s.tiles, c->s.vertices,
 * c->s.points_read, c->s.t_pass2.
 * returns: GDT_OK; the tiler's and journal's errors; GDT_EINPUT 3801 (more
 * than 2^31 - 1 vertices); GDT_EINTERRUPTED 1302. */
gdt_status tr_run_pass2(tr_run *c, gdt_error *err);

/* ---- run_ground.c: --ground, inside pass 2 ---- */

/* After the tiler's pass 2 (every tile's .pts and its reach-wide .edge
 * files): classifies every tile's points with the ground filter on up to
 * --threads workers and replaces the tile files with the ground points
 * (gdt_tiler_take_subsets); c->s.ground_points, nonground_points,
 * t_ground.  With c->gshare, shared with other processes (see below).
 * returns: GDT_OK; the filter's (2702, 7701) and the tiler's errors;
 * GDT_EINTERRUPTED 1303; another process's failure. */
gdt_status tr_run_ground(tr_run *c, gdt_error *err);

/* A tile's ground subset as another process wrote (or adopted) it: its
 * files (gdt_tiler_write_subset) and the tile's points before the filter. */
typedef struct tr_ground_rec {
    uint64_t k, own;
    gdt_tiler_tile_files files;
    int adopted;          /* an earlier run's subset, verified */
} tr_ground_rec;

/* The ground filter shared between processes (MPI), on rank 0: with
 * c->gshare, tr_run_ground classifies only the tiles mine() gives it;
 * begin tells the other processes to classify theirs (they run
 * tr_run_ground_part); collect gives the subsets they finished since its
 * last call (*recs malloc'd, *n; wait: until at least one message came)
 * and *left, the processes still to finish; it returns a process's
 * failure (the first one; later calls go on collecting).  merge_bits ORs
 * the others' --ground-out bits into fd (every process has finished). */
struct tr_ground_share {
    int (*mine)(void *ctx, uint64_t k);
    gdt_status (*begin)(void *ctx, gdt_error *err);
    gdt_status (*collect)(void *ctx, int wait, tr_ground_rec **recs, size_t *n, int *left,
                          gdt_error *err);
    gdt_status (*merge_bits)(void *ctx, int fd, gdt_error *err);
    void *ctx;
};

/* What rank 0's journal holds of a tile's subset: its .gpts and .gedge
 * files' records (found, size, checksum). */
typedef struct tr_ground_known {
    int found[2];
    uint64_t size[2], sum[2];
} tr_ground_known;

/* Another process's share of the ground filter: the tiles ks[0, n) with
 * known[i] for ks[i]; report (on the caller's thread, between tiles and at
 * the end) takes the subsets written since its last call; bits_path: this
 * process's --ground-out bits (one bit per ordinal, a sparse file). */
typedef struct tr_ground_part {
    const uint64_t *ks;
    uint64_t n;
    const tr_ground_known *known;
    gdt_status (*report)(void *ctx, const tr_ground_rec *recs, size_t n, gdt_error *err);
    void *ctx;
    const char *bits_path;
} tr_ground_part;

/* --ground-out written in shares (MPI), on rank 0 with the file's
 * temporary open (tmp; the records from points_at): begin tells every other
 * process its share of the input records, when they can be cut (*shared =
 * 1; rank 0's own share is [*first, *end) with ordinals from *ord_base);
 * wait (after begin shared, whatever rank 0's own share did) gives the
 * others' statistics summed and their kept records, or a process's
 * failure. */
struct tr_gout_share {
    gdt_status (*begin)(void *ctx, const char *tmp, uint64_t points_at, int *shared,
                        uint64_t *first, uint64_t *end, uint64_t *ord_base, gdt_error *err);
    gdt_status (*wait)(void *ctx, gdt_las_copy_stats *sum, uint64_t *kept, gdt_error *err);
    void *ctx;
};

/* Another process of an MPI job, after tr_run_attach_ground: classifies
 * the tiles of part as tr_run_ground does, writes their subsets and
 * reports them; it records nothing (rank 0 does) and takes no subset
 * into the tiler.  *classified: tiles it classified or adopted.
 * returns: as tr_run_ground. */
gdt_status tr_run_ground_part(tr_run *c, const tr_ground_part *part, uint64_t *classified,
                              gdt_error *err);

/* Another rank of an MPI job, after tr_run_start_core, in place of
 * tr_run_prepare_job, tr_run_pass1 and tr_run_pass2 (which rank 0 ran):
 * takes the job's id and the tiler's state (gdt_tiler_export) from rank 0,
 * opens the cloud (headers only: the input is not read), and with the
 * state after pass 2 joins the core (tr_run_start_core first) and sets what
 * the tile stage needs (c->plan, c->base, c->trim).  Called again, it
 * replaces the tiler: first with the state after pass 1 (a shared pass 2,
 * gdt_tiler_merge_shipped), then after pass 2.  Such a context has no journal and no lock: it never
 * writes job.db.
 * returns: GDT_OK; the cloud's, tiler's and core's errors. */
gdt_status tr_run_attach(tr_run *c, const uint64_t job_id[2], const unsigned char *state,
                         size_t len, gdt_error *err);

/* Another rank of an MPI job with the ground filter: replaces its tiler
 * with the state after pass 2 (every tile's files, before the ground
 * subsets are taken), for tr_run_ground_part.  returns: as tr_run_attach. */
gdt_status tr_run_attach_ground(tr_run *c, const unsigned char *state, size_t len,
                                gdt_error *err);

/* ---- run_tiles.c: the tile stage ---- */

/* A tile's journal record as a rank without the journal is told it. */
typedef struct tr_tile_rec {
    int found;            /* the journal records the tile as finished */
    uint64_t size, sum;   /* its .tri file's size and checksum */
} tr_tile_rec;

/* Which tiles a tile stage runs, and who hears of each finished one. */
typedef struct tr_tile_set {
    /* n tile indices, strictly increasing; NULL: every tile, in order */
    const uint64_t *k;
    uint64_t n;
    /* NULL, or called on the caller's thread once per tile of the set when
     * its .tri file is durable and recorded (a reused tile: when its file
     * has been verified against its record) */
    void (*done)(void *ctx, uint64_t k);
    /* A context without the journal (c->jobdb NULL, another rank of an MPI
     * job): rec[i] is the record of tile k[i], and record() takes the
     * durable finished tiles p[0, n) in place of the journal; an error it
     * returns ends the stage.  NULL with the journal. */
    const tr_tile_rec *rec;
    gdt_status (*record)(void *ctx, const tr_pending *p, size_t n, gdt_error *err);
    /* NULL, or called on the caller's thread before each tile and at the
     * end of the stage (messages of other ranks); an error ends the stage */
    gdt_status (*poll)(void *ctx, gdt_error *err);
    /* NULL (the set is n tiles), or a set that grows as the stage goes
     * (tiles taken on demand): called on the caller's thread before tile i,
     * *n the set's length so far (i <= *n); it may lengthen the set, k and
     * rec (allocated for every tile it may get) holding the new tiles,
     * still increasing, and waits for tiles when i == *n; the stage ends
     * when i == *n on return.  An error ends the stage.  Only for a run
     * without lanes (c->cstart.nmore == 0): lanes take the first n tiles
     * ahead. */
    gdt_status (*more)(void *ctx, uint64_t i, uint64_t *n, gdt_error *err);
    void *ctx;
} tr_tile_set;

/* After tr_run_pass2 (and tr_run_output_start when c->out is to be fed):
 * runs the tiles of set in its order.  A tile the journal records is reused
 * when its .tri file matches the record (a warning 6803 names a file that
 * does not, and the tile is redone); any other is loaded, triangulated by
 * the core, and handed to the post stage (certification, seam, trim
 * section), which writes J/tiles/tile_<i>_<j>.tri and whose files are
 * synced in batches and recorded in the journal (or by set->record).  The
 * writer (c->out, if any) is told of the tiles that have their files, as a
 * prefix of the tile order, when the set is every tile; with a subset the
 * caller tells it (tr_out_ready).  Leaves c->seam_total and
 * c->s (certified, tiles_reused, tiles_redone, t_tiles, the core's and
 * certification's counts); the core and the stage's buffers go to the
 * reclaim thread at the end, so it runs once per context.  Interrupted, it
 * records what is finished first.
 * returns: GDT_OK; the tiler's, core's, certifier's and journal's errors;
 * GDT_EIO 48xx; GDT_EINTERRUPTED 1302. */
gdt_status tr_run_tiles(tr_run *c, const tr_tile_set *set, gdt_error *err);

/* Tile k loaded (with its halo, through the buffer halo) and triangulated
 * by core into sl; counts takes the figures.  Thread-safe for distinct
 * cores, halos, counts and slots (run_tiles.c). */
gdt_status tr_core_tile(tr_run *c, gdt_core *core, gdt_point_buf *halo, tr_core_counts *counts,
                        uint64_t k, tr_slot *sl, gdt_error *err);
void tr_core_counts_add(tr_run *c, const tr_core_counts *n);

/* Lanes (run_lanes.c), for the n tiles of set when the run has more than
 * one core (c->cstart.nmore > 0; else nothing is started): tr_lanes_start
 * starts them; tr_lanes_take gives the i-th tile of the set triangulated
 * (by a lane, or by c->core on the caller's thread, counted in counts);
 * tr_lanes_posted frees a slot whose post stage was joined; tr_lanes_stop
 * joins the lanes, adds their figures and frees their slots (c->lanes
 * NULL; nothing when none run).  Errors of take: the core's, a lane's for
 * that tile. */
gdt_status tr_lanes_start(tr_run *c, const tr_tile_set *set, uint64_t n, gdt_error *err);
gdt_status tr_lanes_take(tr_run *c, uint64_t i, tr_slot **sl, tr_core_counts *counts,
                         gdt_error *err);
void tr_lanes_posted(tr_run *c, tr_slot *sl);
void tr_lanes_stop(tr_run *c);

/* Waits for the post stage (if one runs) and returns its status; its error,
 * if any, is copied to *err. */
gdt_status tr_post_join(tr_run *c, gdt_error *err);

/* Waits for the reclaim thread (if one runs). */
void tr_reclaim_join(tr_run *c);

/* ---- run_merge.c: the seam merge ---- */

/* After tr_run_output_start, before tr_run_tiles (optional): starts the
 * seam merge on a thread of its own, which merges each row of tiles as
 * soon as tr_merge_ready says its tiles have their files; tr_run_merge
 * then waits for it.  Without it (or when no thread can be started),
 * tr_run_merge merges every row itself.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status tr_run_merge_start(tr_run *c, gdt_error *err);

/* Tiles [0, prefix) have their .tri files (from the caller's thread of
 * the tile stage; no effect without a merge thread). */
void tr_merge_ready(tr_run *c, uint64_t prefix);

/* Stops the merge thread, if one runs, without waiting for the tiles
 * (tr_run_close). */
void tr_merge_abort(tr_run *c);

/* After tr_run_tiles has finished every tile: the seam merge by rows of
 * tiles, reading each row's seams from their .tri files, or the end of the
 * merge thread that does so; writes J/merge.faces
 * (and with --dem J/merge.dem) anew, synced with the directory; with a
 * trim rule, the trim graph resolved.  Leaves c->s.merge, merge_faces,
 * faces, t_merge (the time the merge adds after the tile stage).
 * returns: GDT_OK; the merger's errors; GDT_EIO 48xx; GDT_EJOB 6801-6802;
 * GDT_EINTERRUPTED 1302. */
gdt_status tr_run_merge(tr_run *c, gdt_error *err);

/* ---- run_finish.c: the output ---- */

/* After tr_run_pass2: the trim rule and graph (c->trim, c->tgraph), the
 * DEM (c->dem) and the mesh writer thread (c->out), which writes the mesh
 * beside the tile stage; with --check of a text output, the PLY copy in J.
 * returns: GDT_OK; GDT_EINTERNAL 7001; the DEM's errors. */
gdt_status tr_run_output_start(tr_run *c, gdt_error *err);

/* After tr_run_merge: hands the trim graph to the writer, checks Euler's
 * relation, completes the mesh (merge faces appended) and the DEM, marks
 * the "ply" stage, runs --check, writes --json and the summary; without
 * --keep-job removes the job.
 * returns: GDT_OK; GDT_EINTERNAL 7820 (Euler: a bug), 73xx/7821 (--check);
 * the writer's and DEM's errors. */
gdt_status tr_run_finish(tr_run *c, gdt_error *err);

/* Joins every helper thread, releases c and unlocks J; returns st, the
 * run's status.  A run refused for its input or options (GDT_EINPUT,
 * GDT_EUSAGE) of a job without finished work removes the job. */
gdt_status tr_run_close(tr_run *c, gdt_status st);

#endif
