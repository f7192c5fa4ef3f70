/* gdt_las_copy.h — a LAS file made of the records of LAS/LAZ inputs, copied
 * (the classified cloud of --ground-out), or of records the caller makes
 * (gdt_las_copy_open_new: points that were not LAS).
 *
 * The output takes the first input's header and VLRs (its CRS among them),
 * without the LASzip VLR and with the compression bits of the point format
 * cleared, so a LAZ input becomes LAS; its EVLRs (LAS 1.4) follow the
 * records.  The caller gives records of that point format, record length,
 * scale and offset (gdt_las_copy_accepts checks another input's header), in
 * the order they go to the file, and may change their bytes on the way
 * (an input whose offset differs by whole steps has its integers shifted
 * onto the template's, gdt_las_copy_shift);
 * the point counts (legacy and 64-bit), the points by return and the bounds
 * are those of the records written.  A waveform pointer of the template is
 * cleared (the waveform data is not copied).  Written under a temporary
 * name beside path, synced and renamed by gdt_las_copy_finish; a failure or
 * gdt_las_copy_abort removes it.
 *
 * Message numbers: 2151 an input the output cannot take (another point
 * format, record length or scale, an offset not on the template's lattice;
 * not LAS), 2152 a shifted record out of int32, 3151 the template's
 * header or VLRs unreadable, 4151 create, 4152 write, 4153 sync or rename,
 * 7001 out of memory.
 */
#ifndef GDT_LAS_COPY_H
#define GDT_LAS_COPY_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_source.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct gdt_las_copy gdt_las_copy;

/* Starts path with the header, VLRs and EVLRs of the LAS/LAZ file template
 * (its source info tinfo, for the point layout).
 * Ownership: *out is new; end with gdt_las_copy_finish or _abort. */
gdt_status gdt_las_copy_open(gdt_las_copy **out, const char *path, const char *template_path,
                             const gdt_source_info *tinfo, gdt_error *err);

/* Starts path as a new LAS 1.2 file of point format 0 (20-byte records)
 * with these scales and offsets, no VLR (so no CRS) and zero dates: the
 * caller makes the records (gdt_las_copy_put), e.g. from points that were
 * not LAS.  Ownership: as gdt_las_copy_open. */
gdt_status gdt_las_copy_open_new(gdt_las_copy **out, const char *path, const double scale[3],
                                 const double offset[3], gdt_error *err);

/* GDT_OK when records of an input with this header can be copied (LAS or
 * LAZ, the template's point format, record length and scale; an offset
 * that differs by whole multiples of the scale, below 2^31 of them, in
 * each axis: shift[] receives them, which gdt_las_copy_shift adds to the
 * record integers); GDT_EUSAGE 2151 naming path and the difference
 * otherwise.  Usable before open: template_info is the first input's. */
gdt_status gdt_las_copy_accepts(const gdt_source_info *template_info, const char *path,
                                const gdt_source_info *in, int64_t shift[3], gdt_error *err);

/* Adds shift[] (from gdt_las_copy_accepts) to the X, Y, Z of n records of
 * record_length bytes.  returns: GDT_OK; GDT_EUSAGE 2152 when a shifted
 * integer leaves int32 (the message names path and the record). */
gdt_status gdt_las_copy_shift(unsigned char *recs, size_t n, unsigned record_length,
                              const int64_t shift[3], const char *path, uint64_t first,
                              gdt_error *err);

/* Appends n records (n * record_length bytes).  After a failure the
 * caller ends with gdt_las_copy_abort. */
gdt_status gdt_las_copy_put(gdt_las_copy *w, const unsigned char *recs, size_t n,
                            gdt_error *err);

/* Writes the EVLRs after the last record written, patches the header,
 * syncs, renames; frees w. */
gdt_status gdt_las_copy_finish(gdt_las_copy *w, gdt_error *err);

/* ---- written in parts by several processes ----
 * Records have a fixed length, so record r of the file (the records in
 * input order) is at points_at + r * record_length whoever writes it.  The
 * owner opens the file (gdt_las_copy_open), gives every other process its
 * temporary's path and points_at (gdt_las_copy_layout) and may write a
 * share itself (gdt_las_copy_seek, then _put); another process opens the
 * temporary (gdt_las_copy_open_part), seeks to its share's first record,
 * puts its records and closes its part (gdt_las_copy_close_part: synced)
 * with their statistics, which the owner adds (gdt_las_copy_add_stats)
 * before it seeks past the last record of the file and finishes.  The
 * header's counts and bounds are then those of every record. */
typedef struct gdt_las_copy_stats {
    uint64_t count, by_return[15];
    int32_t lo[3], hi[3]; /* record integers; meaningless when count is 0 */
} gdt_las_copy_stats;

void gdt_las_copy_layout(const gdt_las_copy *w, const char **tmp, uint64_t *points_at);

/* tinfo: the template's source info (point format, record length).
 * returns: GDT_OK; GDT_EIO 4151; GDT_EINTERNAL 7001.  End with
 * gdt_las_copy_close_part or _abort (which leaves the file). */
gdt_status gdt_las_copy_open_part(gdt_las_copy **out, const char *tmp, uint64_t points_at,
                                  const gdt_source_info *tinfo, gdt_error *err);

/* The next record put goes to record rec of the file.  returns: GDT_OK;
 * GDT_EIO 4152 (the buffered records could not be written: abort w). */
gdt_status gdt_las_copy_seek(gdt_las_copy *w, uint64_t rec, gdt_error *err);

void gdt_las_copy_get_stats(const gdt_las_copy *w, gdt_las_copy_stats *s);
void gdt_las_copy_add_stats(gdt_las_copy *w, const gdt_las_copy_stats *s);
/* a += s: counts added, bounds widened. */
void gdt_las_copy_stats_add(gdt_las_copy_stats *a, const gdt_las_copy_stats *s);

/* Writes the rest, syncs, closes; *s: the part's statistics; frees w.
 * returns: GDT_OK; GDT_EIO 4152, 4153. */
gdt_status gdt_las_copy_close_part(gdt_las_copy *w, gdt_las_copy_stats *s, gdt_error *err);

/* Removes the temporary file and frees w; w may be NULL. */
void gdt_las_copy_abort(gdt_las_copy *w);

#ifdef __cplusplus
}
#endif
#endif
