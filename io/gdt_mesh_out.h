/* gdt_mesh_out.h — one streaming writer of the output TIN over its formats.
 *
 * The format follows the extension of the output path, compared without
 * regard to case (gdt_mesh_format_of):
 *   .obj   Wavefront OBJ, text: "# ..." header comments (generator, CRS,
 *          lattice, the caller's comments), then one "v x y z" line per
 *          vertex, then one "f a b c" line per face (1-based indices,
 *          counter-clockwise).  Beside it, <stem>.prj (gdt_mesh_prj_path)
 *          holds the CRS as WKT when one is known (see below).
 *   .xml   LandXML 1.2 (namespace GDT_LANDXML_NS): <Units> (Imperial when
 *          the CRS's linear unit is a foot, else Metric), <CoordinateSystem>
 *          (epsgCode and ogcWktCode as known), <Application>, then
 *          <Surfaces><Surface name="<stem>"><Definition surfType="TIN">
 *          with <Pnts> (<P id="k">northing easting elevation</P>, k from 1:
 *          y x z of vertex k-1) and <Faces> (<F>a b c</F>, 1-based ids in
 *          the writer's face order).  The LandXML date and time attributes
 *          are meta->stamp (UTC), so the bytes are a function of the inputs.
 *   other  binary little-endian PLY (gdt_ply.h, which this writer wraps).
 * Numbers in the text formats are the shortest of %.15g, %.16g and %.17g
 * that strtod reads back as the same double (so every value round-trips
 * exactly), written and checked in the "C" numeric locale whatever the
 * process's LC_NUMERIC.
 *
 * The CRS of the .prj: meta->crs_wkt when the input carried WKT; else, for
 * an EPSG code of WGS 84 / UTM (326zz, 327zz), WGS 84 / UPS (32661, 32761)
 * or NAD83 / UTM (26901..26923), WKT 1 made here; else there is no WKT:
 * no .prj is written (with a warning GDT-3720 on meta->log for an EPSG
 * code without WKT; a note with -v for an unknown CRS), and a .prj
 * already at that path (a regular file) is removed, since it would describe
 * an earlier output.  The OBJ header and the LandXML still carry the code.
 *
 * Streaming and file safety (all formats): records go through one bounded
 * buffer (GDT_MESH_BUFFER_BYTES for the text formats), nothing of the mesh
 * is held in memory.  The mesh is written as "<path>.tmp-<pid>", the .prj
 * as "<prj>.tmp-<pid>"; gdt_mesh_finish flushes and fsyncs both, renames
 * the .prj into place first and the mesh last, then fsyncs the directory.
 * So a mesh at its final path always has its complete .prj (or none), and
 * a .prj is never half-written.  Should the mesh's rename fail after the
 * .prj's, the new .prj is removed as well.  Any failure removes every
 * temporary at once; errors are sticky (every later call returns the first
 * error, and finish never renames an incomplete file).
 *
 * Message numbers (text formats; PLY keeps those of gdt_ply.h):
 *   3710 too many vertices (indices are int32, as in the PLY);
 *   4710 path is a directory, 4711 temporary cannot be created, 4712 write
 *   failed, 4713 fsync failed, 4714 close failed, 4715 rename failed, 4716
 *   directory sync failed (the files are complete at their paths), 4717 the
 *   .prj temporary cannot be created or written, 4718 a stale .prj cannot
 *   be removed; 4010/4011 (gdt_outfile.h) for the mesh or the .prj path;
 *   7710 bad argument, 7711 bad comment byte, 7712 bad lattice, 7713
 *   vertices after faces, 7714 face index out of range, 7715 repeated
 *   index, 7716 non-finite vertex, 7717 a number that does not round-trip
 *   (a C library fault), 7718 the C locale cannot be made; 7001 out of
 *   memory.  Warning 3720: no .prj (no WKT for the CRS).
 *
 * Not thread-safe per instance; separate instances (different paths) are
 * independent.
 */
#ifndef GDT_MESH_OUT_H
#define GDT_MESH_OUT_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_cloud.h"
#include "gdt_error.h"
#include "gdt_ply.h"

#ifdef __cplusplus
extern "C" {
#endif

#define GDT_MESH_BUFFER_BYTES ((size_t)1 << 20)
#define GDT_LANDXML_NS "http://www.landxml.org/schema/LandXML-1.2"

typedef enum gdt_mesh_format {
    GDT_MESH_PLY = 0,
    GDT_MESH_OBJ = 1,
    GDT_MESH_LANDXML = 2
} gdt_mesh_format;

/* The format of an output path: ".obj" OBJ, ".xml" LandXML (any case),
 * anything else PLY.  path may be NULL (PLY). */
gdt_mesh_format gdt_mesh_format_of(const char *path);

/* "PLY", "OBJ", "LandXML". */
const char *gdt_mesh_format_name(gdt_mesh_format f);

/* The .prj beside an OBJ path: its extension replaced by ".prj" (same
 * stem, same directory).  NULL for the other formats, or out of memory.
 * Ownership: the caller frees the result. */
char *gdt_mesh_prj_path(const char *path, gdt_mesh_format f);

typedef struct gdt_mesh_meta {
    gdt_lattice lattice;         /* sx, sy finite and > 0; ox, oy finite */
    int epsg;                    /* > 0 when the CRS is known by an EPSG code */
    const char *crs_wkt;         /* the CRS as WKT (the input's), or NULL */
    const char *const *comments; /* printable ASCII lines (PLY: "comment" lines) */
    size_t ncomments;
    int64_t stamp; /* LandXML date/time, seconds since 1970 UTC */
    gdt_log *log;  /* warning 3720; may be NULL */
} gdt_mesh_meta;

typedef struct gdt_mesh_writer gdt_mesh_writer;

/* Checks meta and the paths, creates the temporaries and writes the header.
 * returns: GDT_OK and *out; else *out = NULL, nothing left on disk, and the
 *   errors above (PLY: those of gdt_ply_create).
 * Ownership: *out must be ended by gdt_mesh_finish or gdt_mesh_abort; meta
 * and its strings are only read during the call. */
gdt_status gdt_mesh_create(gdt_mesh_writer **out, const char *path, gdt_mesh_format fmt,
                           const gdt_mesh_meta *meta, gdt_error *err);

/* Appends n vertices (3n finite doubles x, y, z), only before the first
 * face.  returns: 3710/3701, 7713/7704, 7716/7707, 7710/7701, 4712/4702. */
gdt_status gdt_mesh_write_vertices(gdt_mesh_writer *w, const double *xyz, size_t n, gdt_error *err);

/* Appends n faces (3n 0-based vertex indices, CCW; each in [0, vertices
 * written) and distinct within a face).  returns: 7714/7705, 7715/7706,
 * 7710/7701, 4712/4702. */
gdt_status gdt_mesh_write_faces(gdt_mesh_writer *w, const int32_t *tri, size_t n, gdt_error *err);

uint64_t gdt_mesh_vertex_count(const gdt_mesh_writer *w);
uint64_t gdt_mesh_face_count(const gdt_mesh_writer *w);
gdt_mesh_format gdt_mesh_writer_format(const gdt_mesh_writer *w);

/* Completes the files (see the top of this file) and frees w, also on
 * failure.  returns GDT_OK when the mesh (and its .prj, if any) are at
 * their paths; 4716/4706 when they are but the directory sync failed;
 * otherwise the first error, every temporary removed. */
gdt_status gdt_mesh_finish(gdt_mesh_writer *w, gdt_error *err);

/* The PLY writer inside a PLY mesh writer (NULL for the text formats), for
 * writing the mesh in parts (gdt_ply.h: gdt_ply_begin_parts); such a mesh
 * is completed by gdt_mesh_finish_parts. */
gdt_ply_writer *gdt_mesh_ply_writer(gdt_mesh_writer *w);

/* gdt_mesh_finish of a PLY mesh written in parts, with nface faces
 * (gdt_ply_finish_parts); frees w, also on failure. */
gdt_status gdt_mesh_finish_parts(gdt_mesh_writer *w, uint64_t nface, gdt_error *err);

/* Removes the temporaries and frees w; w may be NULL. */
void gdt_mesh_abort(gdt_mesh_writer *w);

/* ---- A text mesh (OBJ, LandXML) written in parts ----
 *
 * Text records have no fixed size, so a part's place is known only once
 * every part before it is formatted.  The parts are first formatted into
 * fragments (files of records exactly as the writer makes them, no header
 * or footer), whose lengths give every part its byte offset; then each
 * fragment is copied to its place in the mesh's temporary.  The file is:
 *   header | vertex fragments in vertex order | separator |
 *   face fragments in face order | the writer's own faces | footer
 * and its bytes are those of the sequential writer.  The writer that made
 * the temporary: gdt_mesh_begin_text_parts (writes the header; nothing
 * else written), then, once the fragments are placed,
 * gdt_mesh_resume_text at the end of the last one, its own faces, and
 * gdt_mesh_finish.  Whoever places fragments: gdt_mesh_part_open on the
 * temporary's path (gdt_mesh_temp_path), gdt_mesh_part_copy /
 * gdt_mesh_part_write, gdt_mesh_part_close (which syncs). */

/* The bytes between the vertex and the face records: LandXML
 * "</Pnts>\n<Faces>\n", OBJ "". */
const char *gdt_mesh_text_separator(gdt_mesh_format f);

/* A fragment writer at path (created or truncated; not synced, kept by
 * gdt_mesh_fragment_close, removed on failure or gdt_mesh_abort) that
 * takes gdt_mesh_write_vertices (faces == 0: the first vertex has index
 * first, which LandXML ids count from) or gdt_mesh_write_faces (faces != 0:
 * indices below first, the mesh's vertex count).  fmt: OBJ or LandXML.
 * returns: GDT_OK; 7710; 3710; 4711 (cannot create); 7001. */
gdt_status gdt_mesh_fragment_create(gdt_mesh_writer **out, const char *path, gdt_mesh_format fmt,
                                    uint64_t first, int faces, gdt_error *err);

/* Writes out and closes a fragment; *bytes (may be NULL) its length; frees
 * w, also on failure (the file is then removed).  returns: GDT_OK; the
 * first error of its writes; 4712, 4714. */
gdt_status gdt_mesh_fragment_close(gdt_mesh_writer *w, uint64_t *bytes, gdt_error *err);

/* The temporary the mesh is written to (owned by w). */
const char *gdt_mesh_temp_path(const gdt_mesh_writer *w);

/* A fresh text mesh (nothing written after gdt_mesh_create): its header is
 * written out; *header gets its length.  returns: GDT_OK; 7710; 4712. */
gdt_status gdt_mesh_begin_text_parts(gdt_mesh_writer *w, uint64_t *header, gdt_error *err);

/* After the fragments are in place: the writer goes on at byte offset (the
 * end of the last face fragment) as if it had written nvert vertices, the
 * separator and nface faces.  returns: GDT_OK; 7710; 4712. */
gdt_status gdt_mesh_resume_text(gdt_mesh_writer *w, uint64_t offset, uint64_t nvert, uint64_t nface,
                                gdt_error *err);

typedef struct gdt_mesh_part gdt_mesh_part;

/* Opens the temporary at tmp_path (it must exist) to place fragments.
 * returns: GDT_OK; GDT_EIO 4720; 7001. */
gdt_status gdt_mesh_part_open(gdt_mesh_part **out, const char *tmp_path, gdt_error *err);

/* Copies the fragment file (which must be exactly bytes long) to byte
 * offset of the temporary.  returns: GDT_OK; GDT_EIO 4805 (unreadable),
 * 4721 (write); GDT_EJOB 6802 (its length is not bytes); 7001. */
gdt_status gdt_mesh_part_copy(gdt_mesh_part *p, const char *fragment, uint64_t bytes,
                              uint64_t offset, gdt_error *err);

/* Writes n bytes at byte offset of the temporary.  returns: GDT_OK; 4721. */
gdt_status gdt_mesh_part_write(gdt_mesh_part *p, const void *bytes, size_t n, uint64_t offset,
                               gdt_error *err);

/* Syncs and closes p; frees it.  p may be NULL.  returns: GDT_OK; 4722. */
gdt_status gdt_mesh_part_close(gdt_mesh_part *p, gdt_error *err);

/* Closes p without syncing; frees it.  p may be NULL. */
void gdt_mesh_part_abort(gdt_mesh_part *p);

/* The shortest of %.15g / %.16g / %.17g of the finite d that strtod reads
 * back as d, made and checked in the C numeric locale whatever the
 * process's, into out (cap >= 32).  The writer itself switches locale once
 * per batch; this entry switches per call (for tests and tools).
 * returns: its length, or 0 when no precision round-trips (never with a
 *   correct C library), d is not finite, or no C locale could be made. */
size_t gdt_mesh_format_double(char *out, size_t cap, double d);

#ifdef __cplusplus
}
#endif
#endif
