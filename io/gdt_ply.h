/* gdt_ply.h — streaming writer of the output mesh.
 *
 * Format: binary_little_endian 1.0, whatever the host byte order.  The header
 * is, line by line (every line ends with a single '\n'):
 *   ply
 *   format binary_little_endian 1.0
 *   comment generator gdt-tile <version>
 *   comment crs <EPSG:n | WKT on one line | unknown>
 *   comment lattice <sx> <sy> <ox> <oy>        (%.17g: exact round trip)
 *   comment <extra>                            (meta->comments, in order)
 *   element vertex <V>                         (V in a 20-character field)
 *   property double x
 *   property double y
 *   property double z
 *   element face <F>                           (F in a 20-character field)
 *   property list uchar int vertex_indices
 *   end_header
 * then V records of 24 bytes (x, y, z as IEEE-754 doubles) and F records of
 * 13 bytes (the byte 3, then three int32 vertex indices).  The file size is
 * therefore exactly header + 24 V + 13 F.
 *
 * Faces are counter-clockwise.  Vertices come first, then faces; neither is
 * held in memory: records go through one bounded buffer (GDT_PLY_BUFFER_BYTES).
 * V and F are written left-aligned and space-padded in fixed-width fields, so
 * the header length does not depend on them, and are patched in place by
 * gdt_ply_finish.  The numbers in the lattice line do not depend on the
 * C locale.
 *
 * The file is written once and never read back by the writer, so it goes
 * to the disk with direct I/O (O_DIRECT, whole 4 KiB blocks from an aligned
 * buffer) where the file system accepts it, and through the page cache
 * otherwise and for the last partial block: a large output does not fill the
 * page cache with fresh pages, which costs more system time than the write.
 *
 * File safety: the file is written as "<path>.tmp-<pid>" in the directory of
 * <path> (an existing file of that name, left by a killed process whose pid
 * is reused, is overwritten).  gdt_ply_finish flushes, patches the counts,
 * fsyncs the file, renames it to <path> (atomically replacing any file
 * there) and fsyncs the directory.  A PLY at the final path is therefore
 * always complete; a failed or aborted writer leaves no temporary behind
 * (a killed process does leave its temporary, never a file at <path>).
 *
 * Errors are sticky: after any failure the temporary file is removed at once
 * and every later call on the writer returns the first error again, so a
 * caller that goes on regardless can never rename an incomplete file.
 *
 * Message numbers: 3701 (too many vertices), 47xx (I/O: create, write, sync,
 * rename), 77xx (precondition violated by the caller), 7001 (out of memory).
 *
 * Not thread-safe per instance; separate instances (with different paths)
 * are independent.
 */
#ifndef GDT_PLY_H
#define GDT_PLY_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Size of the writer's internal buffer. */
#define GDT_PLY_BUFFER_BYTES ((size_t)1 << 20)
/* Width of the fixed count fields of the element lines. */
#define GDT_PLY_COUNT_WIDTH 20
/* Vertex indices are PLY "int": at most INT32_MAX vertices. */
#define GDT_PLY_MAX_VERTICES ((uint64_t)INT32_MAX)

typedef struct gdt_ply_meta {
    gdt_lattice lattice;         /* sx, sy finite and > 0; ox, oy finite */
    int epsg;                    /* > 0: "EPSG:n"; 0 = not known as a code */
    const char *crs_wkt;         /* used when epsg == 0; may be NULL or "" ("unknown").
                                  * Control characters (line breaks, tabs) become
                                  * spaces and bytes >= 0x80 become '?', so the
                                  * header stays printable ASCII on one line. */
    const char *const *comments; /* extra comment lines, may be NULL when
                                  * ncomments == 0.  Each must be printable
                                  * ASCII (0x20..0x7e, or tab): a line break
                                  * or any other byte is refused. */
    size_t ncomments;
} gdt_ply_meta;

typedef struct gdt_ply_writer gdt_ply_writer;

/* Validates meta, creates "<path>.tmp-<pid>" and writes the header.
 * returns: GDT_OK and *out set; else *out = NULL and nothing is left on disk:
 *   GDT_EINTERNAL 7701 (NULL/empty argument, negative epsg), 7702 (bad
 *   comment byte), 7703 (lattice not finite or spacing <= 0);
 *   GDT_EIO 4707 (path names a directory), 4010/4011 (path exists and is no
 *   regular file: gdt_outfile.h), 4701 (temporary cannot be created).
 * Ownership: *out must be ended by gdt_ply_finish or gdt_ply_abort; meta and
 * its strings are only read during the call. */
gdt_status gdt_ply_create(gdt_ply_writer **out, const char *path, const gdt_ply_meta *meta,
                          gdt_error *err);

/* Appends n vertices; xyz holds 3n doubles (x, y, z in CRS units), each
 * finite.  Only before the first face (even with n == 0).
 * returns: GDT_EINTERNAL 7704 (after faces), 7707 (non-finite value, NULL
 *   xyz); GDT_EINPUT 3701 (the total would exceed GDT_PLY_MAX_VERTICES; this
 *   is checked before xyz is read); GDT_EIO 4702 (write failed). */
gdt_status gdt_ply_write_vertices(gdt_ply_writer *w, const double *xyz, size_t n, gdt_error *err);

/* Appends n faces; tri holds 3n vertex indices (CCW).  Every index must be
 * in [0, number of vertices written so far) and the three indices of a face
 * must differ.
 * returns: GDT_EINTERNAL 7705 (index out of range), 7706 (repeated index),
 *   7701 (NULL tri); GDT_EIO 4702 (write failed). */
gdt_status gdt_ply_write_faces(gdt_ply_writer *w, const int32_t *tri, size_t n, gdt_error *err);

/* Records accepted so far. */
uint64_t gdt_ply_vertex_count(const gdt_ply_writer *w);
uint64_t gdt_ply_face_count(const gdt_ply_writer *w);

/* Name of the temporary file ("<path>.tmp-<pid>"), owned by w. */
const char *gdt_ply_temp_path(const gdt_ply_writer *w);

/* Flushes, patches the counts, fsyncs, renames to the final path, fsyncs the
 * directory and frees w, also on failure.
 * returns: GDT_OK: the complete file is at the final path.  Otherwise the
 *   first error of the writer, or GDT_EIO 4702/4703/4704/4705 (flush, fsync,
 *   close, rename), 4010/4011 (the path became something other than a
 *   regular file: it is not replaced), and the temporary has been removed; GDT_EIO 4706 (the
 *   directory could not be synced: the complete file is at the final path
 *   but its name may not survive a power loss).  w == NULL: GDT_EINTERNAL. */
gdt_status gdt_ply_finish(gdt_ply_writer *w, gdt_error *err);

/* Removes the temporary file and frees w; w may be NULL. */
void gdt_ply_abort(gdt_ply_writer *w);

/* ---- Writing in parts, by several processes ----
 *
 * When the vertex count V is known before anything is written and the
 * records' places are known from counts (a tiled run under mpirun: each
 * rank writes the vertex and face blocks of its own tiles), the file is
 * written in parts:
 *   - its creator, after gdt_ply_create, calls gdt_ply_begin_parts: the
 *     header goes to the temporary, V is fixed, and the writer takes no more
 *     records itself;
 *   - any process opens the temporary (gdt_ply_temp_path) with
 *     gdt_ply_part_open and writes vertex records [first, first + n) at
 *     header + 24 first and face records [first, first + n) at
 *     header + 24 V + 13 first (the same bytes as the sequential writer);
 *     a thread of the part writes them out while the caller goes on, the
 *     whole 4 KiB blocks of each chunk with direct I/O where the file
 *     system accepts it, the partial blocks at its ends (which another
 *     part may share) through the page cache; a failed write is reported
 *     by a later call on the part; gdt_ply_part_close syncs what it wrote;
 *   - when every part is written and closed, the creator calls
 *     gdt_ply_finish_parts with the face count F: the file must hold exactly
 *     header + 24 V + 13 F bytes; the counts are patched and the file is
 *     synced and renamed as by gdt_ply_finish.
 * The parts must not overlap and must together cover every record: the
 * size check finds a missing last part, not a hole, so the caller counts
 * its parts. */

/* Writes the header out and fixes the vertex count (no record written yet).
 * *header_bytes: the header's length.
 * returns: GDT_OK; GDT_EINTERNAL 7720 (records already written, or parts
 *   begun twice); GDT_EINPUT 3701 (nvert over GDT_PLY_MAX_VERTICES); GDT_EIO
 *   4702.  On failure the temporary is removed (the writer stays to be
 *   aborted). */
gdt_status gdt_ply_begin_parts(gdt_ply_writer *w, uint64_t nvert, uint64_t *header_bytes,
                               gdt_error *err);

/* Completes a file written in parts with nface faces; frees w, also on
 * failure.  returns: as gdt_ply_finish; GDT_EINTERNAL 7720 (not begun in
 * parts), 7721 (the file's size is not that of V vertices and nface faces:
 * a part is missing). */
gdt_status gdt_ply_finish_parts(gdt_ply_writer *w, uint64_t nface, gdt_error *err);

typedef struct gdt_ply_part gdt_ply_part;

/* Opens the temporary tmp_path (header_bytes and nvert from
 * gdt_ply_begin_parts) to write parts.  returns: GDT_OK; GDT_EIO 4720
 * (cannot open); GDT_EINTERNAL 7001.  Ownership: end with
 * gdt_ply_part_close or gdt_ply_part_abort. */
gdt_status gdt_ply_part_open(gdt_ply_part **out, const char *tmp_path, uint64_t header_bytes,
                             uint64_t nvert, gdt_error *err);

/* Writes vertices first .. first + n - 1 (xyz: 3n finite doubles); xyz
 * may be reused at once.
 * returns: GDT_OK; GDT_EINTERNAL 7722 (beyond V), 7707 (not finite);
 *   GDT_EIO 4721 (this or an earlier write failed). */
gdt_status gdt_ply_part_vertices(gdt_ply_part *p, uint64_t first, const double *xyz, size_t n,
                                 gdt_error *err);

/* Writes faces first .. first + n - 1 (tri: 3n indices below V, distinct
 * within a face).  returns: GDT_OK; GDT_EINTERNAL 7705, 7706 (as
 *   gdt_ply_write_faces); GDT_EIO 4721. */
gdt_status gdt_ply_part_faces(gdt_ply_part *p, uint64_t first, const int32_t *tri, size_t n,
                              gdt_error *err);

/* Waits until every record given so far is written.  returns: GDT_OK;
 * GDT_EIO 4721 (a write failed). */
gdt_status gdt_ply_part_flush(gdt_ply_part *p, gdt_error *err);

/* The bytes p wrote with direct I/O so far (complete after
 * gdt_ply_part_flush): 0 where the file system refuses it. */
uint64_t gdt_ply_part_direct_bytes(gdt_ply_part *p);

/* Waits for the part's writes, syncs and closes; frees p (also on failure;
 * NULL accepted).
 * returns: GDT_OK; GDT_EIO 4722. */
gdt_status gdt_ply_part_close(gdt_ply_part *p, gdt_error *err);

/* Stops the part's writes (what is queued is written) and closes without
 * syncing; frees p; NULL accepted. */
void gdt_ply_part_abort(gdt_ply_part *p);

#ifdef __cplusplus
}
#endif
#endif
