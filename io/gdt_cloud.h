/* gdt_cloud.h — several inputs as one cloud on one exact integer lattice.
 *
 * A cloud opens every input (headers only), decides the output CRS and the
 * lattice, and then streams gdt_point records: lattice integers, z, and a
 * global input ordinal.  All later geometry is done on these integers.
 *
 * Lattice rule (x_crs = ox + sx * ix, y_crs = oy + sy * iy):
 *  - Projected (or unknown-CRS) LAS: the lattice of the first LAS input is
 *    the cloud's, used as is: ix = X, iy = Y, (sx, sy) = its scales,
 *    (ox, oy) = its offsets.  Another LAS input whose step is an integer
 *    multiple m of it (m = 1: same scale) and whose offset differs by an
 *    integer number k of steps maps exactly: ix = m * X + k, judged per
 *    axis with a residual below 1e-9 of a step (or the offsets' own rounding
 *    noise).  Any other LAS input is snapped to the first lattice with a
 *    warning: ix = round_half_even((x - ox) / sx).
 *  - Float input (PCD) is snapped: to the quantum lattice (sx = sy =
 *    quantum, ox = oy = 0) when no input has a LAS lattice, otherwise to the
 *    first LAS lattice (quantum is then unused).
 *  - Geographic input (lon/lat degrees) is first projected with GeographicLib
 *    to the UTM/UPS zone of the data's centre (the middle of the union of
 *    the LAS header bounds), then snapped to the quantum lattice.  Every
 *    input of such a cloud is projected, including PCD and CRS-less LAS.
 * round_half_even is nearbyint() under the default rounding mode.
 * Coordinates that are not finite (x, y or z), or whose lattice integer has
 * magnitude >= 2^53, fail with GDT_EINPUT naming the file and point index.
 *
 * CRS rule: inputs whose CRS is known must all agree (same EPSG code, or
 * the same WKT up to white space, and never projected with geographic);
 * otherwise the cloud is refused (GDT_EINPUT 3410).  An input with no CRS
 * (PCD, LAS without GeoKeys/WKT) is taken to be in the CRS of the others.
 *
 * The ordinal counts the points delivered, across inputs in command-line
 * order, from 0 without gaps; it drives the --dup rule and deterministic
 * vertex order.  (A reader may drop records it defines as invalid, such as
 * PCD points with NaN coordinates; they get no ordinal.)
 *
 * Filter (gdt_filter.h, opts.filter): each record is tested as it is read,
 * before its coordinates are checked or mapped; a dropped record gets no
 * ordinal and is never checked, so a filtered cloud streams exactly what
 * the cloud of a file holding only the kept records streams.  Every pass
 * filters the same way.  Class and return tests on an input without LAS
 * attributes (PCD) are refused at open (GDT_EUSAGE 2305).
 *
 * Diagnostics: readers' warnings reach opts.log during the first pass over
 * each input; headers are read quietly at open and later passes (after
 * gdt_cloud_rewind) are quiet, so each warning is given once.
 *
 * Memory: one read buffer (opts.buffer_bytes) and one open input at a time,
 * whatever the number or size of the inputs (a LAZ input decoded on
 * opts.threads workers holds up to 2 x threads decoded chunks).
 *
 * Message numbers: 2401 (no input, bad quantum), 2305 (class or return
 * filter with an input without those attributes); 3401 (coordinate not
 * finite), 3402 (lattice integer out of range), 3404 (LAS point count
 * differs from the header), 3405 (input changed since open), 3406 (a cloud
 * wider than 2^31 - 1 lattice steps, gdt_cloud_check_span), 3410 (different
 * CRSs), 3411 (geographic with projected), 3412 (CRSs that cannot be shown
 * equal), 3460 (header bounds not lon/lat), 3461 (a point cannot be
 * projected); warnings 3420 (LAS input snapped onto a foreign lattice), 3421
 * (geographic datum is not WGS 84), 3430 (class filter naming classes
 * above 31 with a LAS input of point format 0-5), 3431 (the filter kept no
 * point at all, at the end of the first pass); 7001 (out of memory), 7401 (bad
 * arguments to gdt_points_dedup), 7402 (gdt_cloud_read without a buffer),
 * 7461 (unexpected exception in the projection).
 *
 * Not thread-safe per instance.
 */
#ifndef GDT_CLOUD_H
#define GDT_CLOUD_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_error.h"
#include "gdt_filter.h"
#include "gdt_source.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Largest lattice magnitude accepted (exclusive): integers below it are
 * exact in a double, and differences of two stay in int64. */
#define GDT_LATTICE_LIMIT 9007199254740992.0 /* 2^53 */

typedef struct gdt_lattice {
    double sx, sy; /* lattice spacing in CRS units, > 0 */
    double ox, oy; /* CRS coordinates of lattice point (0, 0) */
} gdt_lattice;

/* One input point on the lattice. */
typedef struct gdt_point {
    int64_t x, y;  /* lattice integers, |x|, |y| < 2^53 */
    double z;      /* CRS units, finite */
    uint64_t ord;  /* global input ordinal */
} gdt_point;

typedef enum gdt_dup_policy {
    GDT_DUP_FIRST = 0, /* keep the z of the first occurrence (lowest ordinal) */
    GDT_DUP_MIN_Z,     /* keep the lowest z (ties: lowest ordinal) */
    GDT_DUP_MAX_Z      /* keep the highest z (ties: lowest ordinal) */
} gdt_dup_policy;

/* Parses "first", "min-z", "max-z"; returns 0, or -1 for anything else. */
int gdt_dup_policy_parse(const char *s, gdt_dup_policy *out);
/* "first", "min-z", "max-z". */
const char *gdt_dup_policy_name(gdt_dup_policy p);

typedef struct gdt_cloud_opts {
    gdt_log *log;          /* warnings and notes; may be NULL */
    double quantum;        /* lattice step for float/projected input; 0 = default 0.001 */
    size_t buffer_bytes;   /* per-source read buffer; 0 = default */
    int threads;           /* decoder threads per compressed input (LAZ); <= 1: none */
    const char *replay_dir; /* when set, the first pass keeps the records of
                               compressed inputs in an unlinked temporary file
                               here, and later passes read them back instead
                               of decoding again (same points, same bytes);
                               NULL: every pass decodes */
    const gdt_point_filter *filter; /* copied at open; NULL = the default filter (every
                                       point but the LAS withheld ones) */
    int census;            /* 1: keep a gdt_las_census of each input (--info) */
} gdt_cloud_opts;

#define GDT_CLOUD_DEFAULT_QUANTUM 0.001

/* How one input's points reach the cloud lattice. */
typedef enum gdt_cloud_map {
    GDT_CLOUD_MAP_NATIVE = 0, /* ix = X, iy = Y (the input defining the lattice) */
    GDT_CLOUD_MAP_SHIFT,      /* ix = mx * X + kx, iy = my * Y + ky, exact */
    GDT_CLOUD_MAP_SNAP,       /* ix = round_half_even((x - ox) / sx) */
    GDT_CLOUD_MAP_PROJECT     /* projected lon/lat, then snapped */
} gdt_cloud_map;

typedef struct gdt_cloud_input_map {
    gdt_cloud_map kind;
    int64_t mx, kx, my, ky;  /* GDT_CLOUD_MAP_NATIVE/SHIFT only (native: 1, 0, 1, 0) */
} gdt_cloud_input_map;

typedef struct gdt_cloud_info {
    size_t ninputs;
    uint64_t point_count;        /* sum of the inputs' verified header counts (an upper
                                    bound when a reader drops invalid records or the
                                    filter drops points) */
    gdt_lattice lattice;
    int lattice_native;          /* 1: a LAS int32 lattice is used as is */
    size_t lattice_input;        /* when lattice_native: the input defining it */
    int projected;               /* 1: input was lon/lat and has been projected */
    int utm_zone;                /* when projected: 1..60, 0 = UPS */
    int utm_north;               /* when projected: 1 north, 0 south */
    int epsg;                    /* output CRS EPSG code, 0 if unknown */
    const char *crs_wkt;         /* output CRS as WKT, or NULL */
    const char *crs_desc;        /* human description, never NULL */
} gdt_cloud_info;

typedef struct gdt_cloud gdt_cloud;

/* Opens all inputs (each is opened, its header validated, and closed again),
 * checks their CRSs, and fixes the lattice.  paths[0..npaths) are copied.
 * returns: GDT_EUSAGE 2401 (no input, bad quantum), GDT_EINPUT (an input's
 *   own error, 3410..3412 for CRS mismatch, 3460 bad geographic bounds),
 *   GDT_EIO, GDT_EINTERNAL 7001.
 * Ownership: *out is new, free with gdt_cloud_close; NULL on failure. */
gdt_status gdt_cloud_open(gdt_cloud **out, const char *const *paths, size_t npaths,
                          const gdt_cloud_opts *opts, gdt_error *err);
/* Valid until gdt_cloud_close; strings are owned by the cloud. */
const gdt_cloud_info *gdt_cloud_get_info(const gdt_cloud *cloud);
/* Per-input source info (i < ninputs), a copy taken at open. */
const gdt_source_info *gdt_cloud_input_info(const gdt_cloud *cloud, size_t i);
const char *gdt_cloud_input_path(const gdt_cloud *cloud, size_t i);
const gdt_cloud_input_map *gdt_cloud_input_map_of(const gdt_cloud *cloud, size_t i);

/* Streams the next points in input order; *n == 0 at the end (and after).
 * Points whose coordinates are not finite, or whose lattice integers fall
 * outside |i| < 2^53, fail with GDT_EINPUT naming the file and point index.
 * An input that now differs from what gdt_cloud_open saw (size, point
 * count) fails with GDT_EINPUT 3405; a LAS input that yields another number
 * of points than its header says fails with GDT_EINPUT 3404.  Errors are sticky: every later call
 * returns the first error again until gdt_cloud_rewind. */
gdt_status gdt_cloud_read(gdt_cloud *cloud, gdt_point *buf, size_t cap, size_t *n,
                          gdt_error *err);
/* Records read from input i (i < ninputs) in this pass so far, and what
 * the filter did with them; after a whole pass, the input's totals. */
const gdt_filter_counts *gdt_cloud_input_counts(const gdt_cloud *cloud, size_t i);
/* The sum over the inputs of gdt_cloud_input_counts. */
gdt_filter_counts gdt_cloud_total_counts(const gdt_cloud *cloud);
/* The attributes of the records of input i read in this pass (every record,
 * kept or not); NULL unless opts.census. */
const gdt_las_census *gdt_cloud_input_census(const gdt_cloud *cloud, size_t i);
/* The cloud's filter (the default one when opts.filter was NULL). */
const gdt_point_filter *gdt_cloud_filter(const gdt_cloud *cloud);

/* A share of the cloud, for a pass shared between processes: the records
 * [first, end) of the inputs taken as one sequence in input order (record r
 * of input i is number b_i + r, b_i the sum of the header point counts of
 * the inputs before it), with ordinals from ord_base (the kept points before
 * the share).  Set after gdt_cloud_open or gdt_cloud_rewind, or else the
 * cloud starts again (gdt_cloud_rewind); it holds over rewinds until set
 * again (0, UINT64_MAX, 0: the whole cloud).  Boundaries inside an input are allowed only where it can
 * start at a record: anywhere in uncompressed LAS and PCD binary, at the
 * first record of a chunk of LAZ (gdt_cloud_split puts them only there).  A share's
 * first pass keeps the replay of its part of each compressed input (opts.replay_dir),
 * which a later pass over the same share reads.  A share gives no per-input notes:
 * the caller sums the shares'
 * counts (gdt_cloud_add_counts) and reports them (gdt_cloud_report_counts).
 * Empty inputs belong to no share.  returns: GDT_EINTERNAL 7403 (first >
 * end, or a boundary inside an input that cannot seek). */
gdt_status gdt_cloud_set_range(gdt_cloud *cloud, uint64_t first, uint64_t end,
                               uint64_t ord_base, gdt_error *err);

/* How many times an input (or a share's part of one) was read from the
 * replay instead of being decoded again, since the cloud was opened. */
uint64_t gdt_cloud_replayed(const gdt_cloud *cloud);

/* Cuts the cloud's records into n >= 1 shares balanced by count:
 * bounds[0 .. n], bounds[0] = 0, bounds[n] = every record, nondecreasing;
 * a boundary inside an input only where it can start (any record of
 * uncompressed LAS or PCD binary, the nearest chunk start of LAZ), elsewhere at the
 * nearer end of the input.  Depends on the headers, the LAZ chunk tables
 * and n only.  returns 1, or 0 when the cloud is better read by one
 * process (a compressed input with fewer than two chunks in a table: its
 * first pass decodes it once for every later pass, and it cannot be cut). */
int gdt_cloud_split(const gdt_cloud *cloud, int n, uint64_t *bounds);

/* Adds a share's counts of input i to this pass's (see gdt_cloud_set_range). */
void gdt_cloud_add_counts(gdt_cloud *cloud, size_t i, const gdt_filter_counts *k);

/* The notes a whole first pass gives (each input's counts, and warning 3431
 * when the filter kept no point): after the shares' counts were added. */
void gdt_cloud_report_counts(gdt_cloud *cloud);

/* Starts again from the first point of the first input (second pass); the
 * stream that follows is identical to the first one.  The counts and
 * census start again from zero. */
gdt_status gdt_cloud_rewind(gdt_cloud *cloud, gdt_error *err);
/* Drops the decoded records of compressed inputs kept for later passes
 * (a later pass decodes its inputs again): after the caller's last read,
 * so that their temporary file is freed before anything (a sync of the
 * file system) writes it to the disk.  Between passes only; cloud may be
 * NULL. */
void gdt_cloud_release_replay(gdt_cloud *cloud);

/* cloud may be NULL. */
void gdt_cloud_close(gdt_cloud *cloud);

/* Checks that a cloud spanning wx x wy lattice steps (max - min per axis)
 * fits the 2^31 - 1 steps per axis that `what` (a mode or stage, for the
 * message) handles.  returns: GDT_EINPUT 3406 when it does not, with the
 * limit in CRS units and advice that works for the lattice's kind (a LAS
 * lattice is the file's scale, which --quantum does not change). */
gdt_status gdt_cloud_check_span(const gdt_cloud *cloud, int64_t wx, int64_t wy,
                                const char *what, gdt_error *err);

/* In-memory duplicate merge: sorts pts by (x, y), keeps one point per (x, y)
 * and compacts the array in (x, y) order into pts[0 .. *kept).  The z of the
 * kept record follows policy; its ord is the LOWEST ordinal of its group
 * whatever the policy, so vertex order never depends on the policy.  The
 * number of merged points is n - *kept.
 * design: bottom-up merge sort on (x, y, ord, z) (a total order, so the
 *   result is the same for every permutation of the input, even with
 *   repeated ordinals), then one linear pass over each group; O(n log n)
 *   time, n records of scratch, no recursion.
 * returns: GDT_EINTERNAL 7001 (out of memory for the scratch array), 7401
 *   (NULL pts with n > 0, unknown policy).
 * Precondition: z is not NaN. */
gdt_status gdt_points_dedup(gdt_point *pts, size_t n, gdt_dup_policy policy, size_t *kept,
                            gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
