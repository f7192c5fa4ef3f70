/* tiled_out.h — the mesh of a tiled run, written beside the tile stage.
 *
 * A writer thread creates the mesh (PLY, OBJ or LandXML by the output's
 * extension: gdt_mesh_out.h) under its temporary name and
 * writes every vertex (tile by tile, from the .pts files); then, in tile
 * order, the certified faces of each tile (from its .tri file) as soon as
 * the tile stage reports the file written (tr_out_ready).  tr_out_finish
 * waits for the thread, appends the merge's faces (merge.faces) and
 * completes the file.  The bytes are those of writing everything after the
 * merge; the tile stage gives the writer a share of the CPU (all of it
 * that a GPU leaves idle) instead of the run spending a stage on it.  A
 * failed write stops the writer and is reported by tr_out_finish: the
 * tiles go on and stay in the job, so a rerun only redoes the output.
 *
 * Threads: the caller's thread calls every function; the writer thread
 * only reads the tiler (tile descriptions), the files and src, and writes
 * into src.dem (tr_dem_tile_faces is thread-safe).  With a DEM the writer
 * holds each tile's points while it copies the tile's faces (32 bytes a
 * point of the largest tile). */
#ifndef GDT_TILED_OUT_H
#define GDT_TILED_OUT_H

#include <signal.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_mesh_out.h"
#include "gdt_tiler.h"
#include "gdt_trim.h"
#include "private/tiled_dem.h"

typedef struct tr_out tr_out;

typedef struct tr_out_src {
    const char *output;     /* the mesh path; its extension picks the format */
    gdt_mesh_meta meta;     /* its strings outlive the writer */
    const char *check_ply;  /* NULL, or a PLY path that receives the same records
                             * (--check of a text output: the checker reads PLY) */
    const gdt_tiler *tiler; /* the tiles (read only while the writer runs) */
    const char *tiles_dir;
    const char *job;      /* for messages */
    const uint64_t *base; /* ntiles + 1: output index of each tile's first vertex */
    uint64_t ntiles;
    volatile sig_atomic_t *stop; /* nonzero: stop (may be NULL) */
    int trim;                    /* the .tri files end with a trim section: faces it
                                  * drops are not written (tiled_files.h) */
    int concavity;               /* --concavity: no face is written before
                                  * tr_out_set_trim */
    tr_dem *dem;                 /* --dem: each tile's kept certified faces are rasterised
                                    into it as they are copied (NULL: no DEM); must outlive
                                    the writer */
    int parts;                   /* a mesh (no DEM or check copy; trimmed or not) written
                                  * in parts by the tiles' owners (mpirun): see below */
    int tri_cached;              /* the .tri files were written through the page cache
                                  * (tr_run.tri_cached): read them through it */
} tr_out_src;

/* Starts the writer (src is copied; the arrays and strings it points to
 * must outlive it).  Stale temporaries of killed writers beside the output
 * are removed first.  Without a thread the work is done in tr_out_finish.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
gdt_status tr_out_start(tr_out **out, const tr_out_src *src, gdt_error *err);

/* Tiles 0..n-1 have their .tri files (n never decreases). */
void tr_out_ready(tr_out *o, uint64_t n);

/* With src.trim, after the merge: the resolved trim graph (it must outlive
 * the writer), which decides the candidates' and the merge faces' fate. */
void tr_out_set_trim(tr_out *o, const gdt_trim_graph *g);

/* Waits until every tile's faces are written, then appends the merge's
 * merge_faces faces from merge_path (with a DEM, rasterising the kept ones
 * with their vertices from merge_dem, the merge.dem file beside it; NULL
 * without) and completes the mesh (and the
 * check_ply copy); *tc gets the faces before trimming and the drops (zeros
 * without src.trim).  Consumes o (also on failure, when the temporary files
 * are removed).
 * returns: GDT_OK; the mesh writer's errors (GDT_EIO 47xx); GDT_EIO 4805,
 * GDT_EJOB 6801-6802 (a job file missing, foreign or short);
 * GDT_EINTERRUPTED 1302. */
gdt_status tr_out_finish(tr_out *o, const char *merge_path, const char *merge_dem,
                         uint64_t merge_faces, gdt_trim_counts *tc, gdt_error *err);

/* fn(ctx) is called once by tr_out_finish, on the caller's thread, when
 * every face is written (and rasterised, with a DEM), before the mesh is
 * synced and renamed; not when the output failed before that.  Set it
 * before tr_out_finish. */
void tr_out_on_complete(tr_out *o, void (*fn)(void *), void *ctx);

/* ---- A PLY written in parts by the tiles' owners (src.parts) ----
 *
 * Under mpirun every rank writes the vertex and face blocks of its own
 * tiles straight into the output's temporary (gdt_ply.h, "in parts"), so
 * that rank 0 does not copy the whole mesh.  Vertices of tile k go to
 * base[k]; its faces to the sum of the face counts of tiles 0..k-1
 * (tr_out_count_faces), known once those tiles are finished; the merge's
 * faces follow the last tile's.  The bytes are those of the sequential
 * writer.  Rank 0: tr_out_start with src.parts creates the file, writes its
 * header and starts no thread (tr_out_ready does nothing);
 * tr_out_parts_layout gives what the other ranks need; rank 0 writes its
 * own tiles (tr_out_write_vertices as each is done, tr_out_write_faces
 * once the tiles before it are counted); tr_out_set_tile_faces, then tr_out_finish
 * writes the merge's faces and completes the file once every other rank
 * has closed its part.  Another rank: tr_out_open_part, the same two
 * writes for each of its tiles, tr_out_close_part (which syncs them). */

/* The temporary's path (owned by o), the header's length and the vertex
 * count, for tr_out_open_part. */
void tr_out_parts_layout(const tr_out *o, const char **tmp_path, uint64_t *header, uint64_t *nvert);

/* Opens the temporary written in parts (src: tiler, tiles_dir, job, base,
 * ntiles, meta.lattice as on rank 0).  returns: GDT_OK; gdt_ply_part_open's
 * errors; GDT_EINTERNAL 7001. */
gdt_status tr_out_open_part(tr_out **out, const tr_out_src *src, const char *tmp_path,
                            uint64_t header, uint64_t nvert, gdt_error *err);

/* The faces of tile k that the mesh keeps: the count in its .tri header
 * (checked against the tile), less with src.trim the faces the rules drop
 * (--concavity: by the trim graph, tr_out_set_trim, which must be set).
 * With labels (else labels, nlabels and cap may be NULL), the (tile,
 * label) pairs of the candidates dropped are
 * appended to (*labels)[2 *nlabels ..] (grown, *cap pairs' room), sorted
 * and each once.  returns: GDT_OK; GDT_EIO 4805; GDT_EJOB 6801, 6802;
 * GDT_EINTERNAL 7001. */
gdt_status tr_out_count_faces(tr_out *o, uint64_t k, uint64_t *kept, uint64_t **labels,
                              size_t *nlabels, size_t *cap, gdt_error *err);

/* A part of a trimmed mesh without the trim graph: the (tile, label) pairs
 * of the candidates --concavity drops, sorted (tr_out_count_faces gave
 * them on rank 0); they must outlive the writes. */
void tr_out_set_dropped(tr_out *o, const uint64_t *pairs, size_t n);

/* The faces and drops of the tiles this writer has written (trimmed). */
gdt_trim_counts tr_out_tile_counts(const tr_out *o);

/* Rank 0: adds another rank's tile counts, for tr_out_finish's. */
void tr_out_add_counts(tr_out *o, const gdt_trim_counts *tc);

/* Writes tile k's vertices (at base[k]; any time after pass 2), or its
 * faces from face index first_face (once the tiles before it are counted).
 * returns: GDT_OK; the part's and the tile files' errors (4805, 6801-6802,
 * 47xx). */
gdt_status tr_out_write_vertices(tr_out *o, uint64_t k, gdt_error *err);
gdt_status tr_out_write_faces(tr_out *o, uint64_t k, uint64_t first_face, gdt_error *err);

/* ---- A text mesh (OBJ, LandXML) in parts ----
 *
 * The same roles, but a text record has no fixed size (gdt_mesh_out.h,
 * "in parts"): tr_out_write_vertices and tr_out_write_faces make tile k's
 * fragments (tiles/<tile>.vtx, .ftx; faces once only, so they may be made
 * during the tile stage and asked for again), and nothing is placed until
 * every fragment's length is known: tr_out_text_sizes gives each tile's
 * lengths, tr_out_place_text copies each tile's fragments to the offsets
 * rank 0 computed from every tile's lengths in tile order, removing each
 * once placed.  Rank 0 also writes the separator and where its own
 * faces begin (tr_out_text_tail) before tr_out_finish. */

/* Whether o writes a text mesh in parts. */
int tr_out_text(const tr_out *o);

/* The vertex and face fragment bytes of tiles ks[0 .. n), each made:
 * vbytes[i] and fbytes[i] for tile ks[i].
 * returns: GDT_OK; GDT_EINTERNAL 7830 (a fragment not made). */
gdt_status tr_out_text_sizes(const tr_out *o, const uint64_t *ks, uint64_t n, uint64_t *vbytes,
                             uint64_t *fbytes, gdt_error *err);

/* Copies the fragments of tiles ks[0 .. n) into the mesh: tile ks[i]'s
 * vertex bytes at byte vat[i], its face bytes at fat[i].  returns: GDT_OK;
 * gdt_mesh_part_copy's errors. */
gdt_status tr_out_place_text(tr_out *o, const uint64_t *ks, uint64_t n, const uint64_t *vat,
                             const uint64_t *fat, gdt_error *err);

/* Rank 0: writes the separator at sep_at (where the vertex bytes end); its
 * own faces (tr_out_finish) will begin at tail_at.  returns: GDT_OK; 4721. */
gdt_status tr_out_text_tail(tr_out *o, uint64_t sep_at, uint64_t tail_at, gdt_error *err);

/* Syncs and closes another rank's part; frees o.  returns: GDT_OK; GDT_EIO
 * 4722. */
gdt_status tr_out_close_part(tr_out *o, gdt_error *err);

/* Rank 0: the faces of all tiles (where the merge's faces begin). */
void tr_out_set_tile_faces(tr_out *o, uint64_t n);

/* Stops the writer and removes its temporary file.  o may be NULL. */
void tr_out_abort(tr_out *o);

#endif
