/* mpi_sched.h — the MPI scheduler's shared state and messages (mpi_run.c:
 * the ranks' stages; mpi_pass2.c: the shared pass 2; mpi_msg.c: message
 * helpers).  Internal to those files. */
#ifndef GDT_MPI_SCHED_H
#define GDT_MPI_SCHED_H

#include <stddef.h>
#include <stdint.h>

#include "private/comm.h"
#include "private/stages.h"

enum {
    TAG_GO = 1,        /* 0 -> r */
    TAG_RECORD = 2,    /* r -> 0 */
    TAG_DONE = 3,      /* r -> 0 */
    TAG_FINISHED = 4,  /* r -> 0 */
    TAG_STOP = 5,      /* 0 -> r */
    TAG_FINAL = 6,     /* 0 -> r */
    TAG_PLAN = 7,      /* 0 -> r: a shared pass 2 begins */
    TAG_RECS = 8,      /* 0 -> r: a tile to merge (then TAG_RECDATA chunks) */
    TAG_RECDATA = 9,   /* 0 -> r */
    TAG_FILES = 10,    /* r -> 0: a merged tile's files */
    TAG_P1 = 11,       /* 0 -> r: the rank's share of pass 1 */
    TAG_P1DONE = 12,   /* r -> 0: what it read, or its failure */
    TAG_SPILL = 13,    /* r <-> q: pass 2 in shares: status, then records */
    TAG_P2FAIL = 14,   /* r -> 0: why this rank's share of pass 2 failed */
    TAG_PARTS = 15,    /* 0 -> r: write your tiles into the mesh (mpi_run.c) */
    TAG_WROTE = 16,    /* r -> 0: the rank's part is written and synced, or why not */
    TAG_GROUND = 17,   /* 0 -> r: classify your tiles (mpi_ground.c) */
    TAG_GREC = 18,     /* r -> 0: ground subsets written */
    TAG_GDONE = 19,    /* r -> 0: the rank's ground filter ended, or why it failed */
    TAG_GOUT = 20,     /* 0 -> r: write your share of --ground-out (mpi_ground.c) */
    TAG_GOUTDONE = 21, /* r -> 0: the share is written and synced, or why not */
    TAG_TSIZES = 22,   /* r -> 0: a text mesh's part: its fragments' lengths (mpi_parts.c) */
    TAG_TPLACE = 23,   /* 0 -> r: where to place them */
    TAG_REMOVED = 24,  /* r -> 0: the rank's share of the tile files is removed */
    TAG_FPLACE = 25,   /* 0 -> r: where the faces of some of its done tiles go (mpi_parts.c) */
    TAG_MORE = 26,     /* r -> 0: this rank takes more tiles */
    TAG_GRANT = 27     /* 0 -> r: the tiles it takes (with their records), or none left */
};

/* Records per TAG_RECDATA message (32 MiB of gdt_point). */
#define RECS_PER_MSG ((size_t)(32u << 20) / sizeof(gdt_point))

typedef struct mr_ctx {
    tr_run *c;
    gdt_comm *comm;
    int rank, size;
    /* rank 0 */
    uint8_t *done;           /* per tile: its file is there */
    uint64_t ntiles, prefix; /* done[0, prefix) are all set */
    uint64_t done_points;    /* vertices of the done tiles (progress) */
    int *finished;           /* per rank: FINISHED received */
    int nfinished;
    gdt_status job_st; /* the first failure of any rank */
    gdt_error job_err;
    tr_summary remote;    /* the other ranks' counts, summed */
    uint64_t remote_seam; /* and their seam vertices */
    int stop_sent;
    /* the shared pass 2: its owners weigh the tiles' pass-1 counts */
    uint64_t *raw_pre; /* ntiles + 1 prefix sums of the pass-1 counts */
    uint64_t raw_n;
    uint64_t shipped, files_got;
    tr_pass2_share p2;
    tr_pass1_share p1;            /* the shared pass 1 */
    int p1_shared;                /* pass 1 was shared */
    uint64_t *p1_bounds;          /* its shares of the records (size + 1) */
    uint64_t *p1_kept;            /* the kept points of each share (size) */
    gdt_filter_counts *p1_counts; /* the filter's counts of the whole pass, per input */
    /* another rank */
    int stopped; /* STOP received */
    int remove_share; /* another rank: FINAL asked it to remove its share of the tile files */
    /* the mesh in parts (mpi_parts.c), on every rank */
    int parts;     /* this run writes the mesh in parts */
    int part_text; /* and it is a text mesh (OBJ, LandXML): fragments first */
    int part_dem;  /* and there is a DEM: another rank rasterises its tiles
                    * into windows (private/tiled_dem.h) over part_grid */
    gdt_raster_grid part_grid;
    tr_dem *part_windows; /* another rank: its DEM in window mode */
    char *part_path;      /* another rank: the temporary, from GO */
    uint64_t part_header, part_nvert;
    gdt_lattice part_lattice;
    tr_out *part_out;   /* another rank: its part, open from GO to PARTS */
    gdt_status part_st; /* the first failure of this rank's writes */
    gdt_error part_err;
    double part_t;           /* seconds this rank spent writing its part */
    gdt_trim_counts part_tc; /* its tiles' faces and drops (a trimmed mesh) */
    int *towner;       /* rank 0: the rank of each tile in the tile stage (mr_tile_owners
                        * for GO's tiles, then as they are taken; -1 before) */
    uint64_t next_tile; /* rank 0: the first tile not dealt yet (ntiles: none left);
                         * the tiles from it on are taken on demand, in order */
    uint64_t *mine, nmine; /* rank 0: its tiles (room for every tile) */
    int on_demand;      /* another rank: GO left tiles to take on demand */
    int asked;          /* another rank: MORE sent, its GRANT not yet here */
    int no_more;        /* another rank: a GRANT said no tile is left */
    uint64_t own_cap;   /* another rank: room in own_ks and own_rec */
    tr_tile_rec *own_rec; /* another rank: the records of own_ks */
    uint64_t taken;     /* the tiles this rank took on demand */
    int placing;       /* rank 0: faces are placed as the prefix of done tiles grows */
    uint64_t *first;   /* rank 0: ntiles + 1: first[k + 1] is known for k < fplaced */
    uint64_t fplaced;  /* rank 0: tiles [0, fplaced) have their place in the mesh */
    uint8_t *fwritten; /* per tile (rank 0) or per tile of own_ks (another rank):
                        * its faces are in the mesh */
    uint64_t *own_ks; /* another rank: its tiles, increasing (GO's, then those taken) */
    uint64_t own_n;
    uint64_t placed_early; /* another rank: its tiles FPLACE placed (for WROTE) */
    /* the shared ground filter (mpi_ground.c), rank 0 */
    tr_ground_share gs;
    int g_left;        /* ranks told GROUND that have not sent GDONE */
    tr_gout_share gos; /* --ground-out in shares (mpi_ground.c), rank 0 */
    int go_left;       /* ranks told GOUT that have not sent GOUTDONE */
} mr_ctx;

/* Sends the packed message p to dest and frees it. */
gdt_status mr_send_pack(mr_ctx *m, int dest, int tag, gdt_pack *p, gdt_error *err);

/* Receives the message a probe announced (from, tag, len); *buf is malloc'd. */
gdt_status mr_recv(mr_ctx *m, int from, int tag, size_t len, unsigned char **buf, gdt_error *err);

/* Waits (without spinning) for the message with tag from rank from and
 * receives it (*buf malloc'd, *len); ends the job (gdt_comm_abort) when
 * the messages fail: the protocol cannot go on without it. */
void mr_wait_recv(mr_ctx *m, int from, int tag, unsigned char **buf, size_t *len);

/* An answer's first fields: its status, then its error's code and message
 * (empty when it is GDT_OK). */
void mr_pack_status(gdt_pack *p, gdt_status st, const gdt_error *err);

/* Reads what mr_pack_status packed from rank from; a failure becomes the
 * job's (mr_fail: "rank R: " and the message) and is returned (GDT_OK
 * also when u went bad: the caller checks u->bad). */
gdt_status mr_unpack_status(mr_ctx *m, gdt_unpack *u, int from);

/* GDT_EINTERNAL 7952: a message that does not parse. */
gdt_status mr_bad_message(int from, int tag, gdt_error *err);

/* The rank of tile k in the shared pass 2 and ground filter (contiguous
 * shares of tile order balanced by the weights whose prefix sums are
 * pre[0, n]). */
int mr_owner_of(const uint64_t *pre, uint64_t n, uint64_t k, int size);

/* The ranks of the tile stage, owner[0, n): tiles taken in tile order,
 * each by the rank with the least weight so far (pre[0, n]: prefix sums
 * of the weights; ties to the lower rank).  Every rank's tiles are spread
 * over the whole order and each prefix of it is balanced within one
 * tile's weight, so that the ranks pass through tile order together: the
 * prefix of done tiles, which the seam merge and the placing of faces
 * follow, grows all through the tile stage instead of waiting for the
 * first rank's last tile.  A pure function of the weights.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status mr_tile_owners(const uint64_t *pre, uint64_t n, int size, int *owner,
                          gdt_error *err);

/* A rank asks rank 0 for more tiles when this many of its own are left to
 * start: rank 0 answers between its own tiles, so the answer may take one
 * of rank 0's tiles to come, and two of the asking rank's give it that
 * time (with one, a rank whose last tile was shorter than rank 0's current
 * one waited). */
#define MR_ASK_AHEAD 2

/* The share of the vertices, in parts of MR_TAIL_PARTS, that the tile
 * stage leaves to be taken on demand at its end. */
#define MR_TAIL_PARTS 4

/* How many tiles GO deals out (mr_tile_owners over them): those before the
 * last 1 / MR_TAIL_PARTS of the weights pre[0, n] (their prefix sums);
 * the rest are taken on demand, so that ranks whose cores run at different
 * speeds in a run, or tiles that cost more than their weight, end the
 * stage together. */
uint64_t mr_tile_dealt(const uint64_t *pre, uint64_t n);

/* How many tiles of the n - next left to grant one rank of size at once:
 * a part of what is left that shrinks to 1 (guided self-scheduling). */
uint64_t mr_grant_size(uint64_t next, uint64_t n, int size);

/* Rank 0: a rank's failure becomes the job's (the first one stands). */
void mr_fail(mr_ctx *m, int from, gdt_status st, int code, const char *msg);

/* Rank 0: the hooks of the shared pass 1 into m->p1 (mpi_pass1.c). */
void mr_pass1_hooks(mr_ctx *m);

/* Another rank, given P1 (msg, len): reads its share and answers P1DONE;
 * *st, *err: this rank's state so far (a failure is the answer).  Unless
 * *core_started, the OpenCL core's start-up begins between the reading and
 * the answer (tr_run_start_core; *core_started set, a failure to start into
 * *st, *err): the answer waits for rank 0 to take it, time the build can
 * use.  Ends the job (gdt_comm_abort) when the answer cannot be sent. */
void mr_pass1_answer(mr_ctx *m, const unsigned char *msg, size_t len, gdt_status *st,
                     gdt_error *err, int *core_started);

/* m->raw_pre / raw_n from tiler t's pass-1 counts.  returns: 7001. */
gdt_status mr_raw_prefix(mr_ctx *m, const gdt_tiler *t, gdt_error *err);

/* Rank 0: FILES of the m->shipped - m->files_got tiles still out, into the
 * tiler (a rank's failure in them becomes the job's). */
gdt_status mr_collect_files(mr_ctx *m, gdt_error *err);

/* Another rank's FILES reports, held until its merged tiles' files are
 * durable (one sync for all of them); zeroed to start. */
struct mr_report;
typedef struct mr_reports {
    struct mr_report *r;
    size_t n, cap;
} mr_reports;

/* Another rank: the --dup merge of tile k from recs[0, n) (or its failure
 * st, err when st is not GDT_OK) into b, for mr_send_reports (sent at once,
 * after a sync, when b cannot grow). */
void mr_merge_report(mr_ctx *m, mr_reports *b, uint64_t k, gdt_point *recs, uint64_t n,
                     gdt_status st, const gdt_error *err);

/* Another rank: makes the files of b's merged tiles durable
 * (gdt_tiler_sync_files; its failure becomes theirs) and sends every
 * report to rank 0 as FILES, in b's order; b is emptied. */
void mr_send_reports(mr_ctx *m, mr_reports *b);

/* Rank 0: the hook of pass 2 in shares into m->p2 (mpi_spill.c). */
void mr_spill_hooks(mr_ctx *m);

/* Another rank, after PLAN in mode 1 or 2 (and tr_run_attach): its share
 * [first, end) of pass 2 with ordinals from base, in memory or (files) in
 * .raw files (mpi_spill.c); *st, *err: this rank's status, in and out. */
void mr_spill_answer(mr_ctx *m, uint64_t first, uint64_t end, uint64_t base, int files,
                     gdt_status *st, gdt_error *err);

/* The mesh in parts (mpi_parts.c; c->out_parts).  GO carries the file's
 * layout: mr_parts_pack_layout (rank 0) and mr_parts_read_layout (another
 * rank, then mr_parts_open after tr_run_attach).  mr_parts_tile_done writes
 * the vertices of this rank's finished or reused tile k during the tile
 * stage (a failure is kept for WROTE). */
void mr_parts_pack_layout(mr_ctx *m, gdt_pack *p);
gdt_status mr_parts_read_layout(mr_ctx *m, gdt_unpack *u, gdt_error *err);
gdt_status mr_parts_open(mr_ctx *m, gdt_error *err);
void mr_parts_tile_done(mr_ctx *m, uint64_t k);

/* Rank 0, when the prefix of done tiles has grown (m->prefix): the tiles
 * that joined it get their place in the mesh (their kept faces counted
 * from their .tri files): rank 0 writes the faces of its own, FPLACE tells
 * the other ranks where theirs go.  Only while m->placing (a binary PLY in
 * parts without --concavity, and no failure so far); a failure here is
 * kept for PARTS and stops the placing. */
void mr_parts_advance(mr_ctx *m);

/* Another rank, given FPLACE (msg, len): writes the faces of the tiles it
 * names (pairs of tile and first face) that it has not written (a failure
 * is kept for WROTE).  A malformed message ends the job. */
void mr_parts_place(mr_ctx *m, const unsigned char *msg, size_t len);

/* Rank 0, after every FINISHED: reads every tile's face count, sends
 * PARTS (the tiles' first faces) to every other rank and writes its own
 * tiles' faces; *wait is set when the others were told to write (then
 * mr_parts_wait must follow, also after a failure here).  returns: GDT_OK;
 * the tile files' and the part's errors (also those of the vertex writes). */
gdt_status mr_parts_send(mr_ctx *m, int *wait, gdt_error *err);

/* Rank 0: WROTE from every other rank; the first failure becomes the
 * job's, which is returned. */
gdt_status mr_parts_wait(mr_ctx *m, gdt_error *err);

/* Another rank, given PARTS (msg, len): writes its tiles' faces ks[0, n),
 * syncs its part and answers WROTE (nothing when PARTS carries a failure).
 * Ends the job (gdt_comm_abort) when the answer cannot be sent. */
void mr_parts_answer(mr_ctx *m, const uint64_t *ks, uint64_t n, const unsigned char *msg,
                     size_t len);

/* Another rank: closes a part PARTS never came for (the job failed). */
void mr_parts_drop(mr_ctx *m);

/* Rank 0: the hooks of the shared ground filter into m->gs (mpi_ground.c). */
void mr_ground_hooks(mr_ctx *m);

/* Another rank, given GROUND (msg, len): classifies its tiles, reporting
 * them (GREC), then answers GDONE; *st, *err: this rank's state, in and out
 * (a failure is the answer).  Ends the job (gdt_comm_abort) when the
 * messages themselves fail. */
void mr_ground_answer(mr_ctx *m, const unsigned char *msg, size_t len, gdt_status *st,
                      gdt_error *err);

/* Another rank, given GOUT (msg, len): writes its share of the
 * --ground-out records and answers GOUTDONE.  Ends the job
 * (gdt_comm_abort) when the messages themselves fail. */
void mr_gout_answer(mr_ctx *m, const unsigned char *msg, size_t len);

/* Rank 0: the hooks of the shared pass 2 into m->p2 (mpi_pass2.c). */
void mr_pass2_hooks(mr_ctx *m);

/* Another rank: waits for GO, meanwhile reading its share of pass 1 (P1)
 * and merging the tiles a shared pass 2 ships it; starts the OpenCL core
 * (tr_run_start_core) at the first message that is not P1.  *st, *err:
 * this rank's state, updated (a failure is reported for each request);
 * *go (malloc'd) and *len receive GO.  Ends the job (gdt_comm_abort) when
 * the messages themselves fail. */
void mr_wait_go(mr_ctx *m, gdt_status *st, gdt_error *err, unsigned char **go, size_t *len);

#endif
