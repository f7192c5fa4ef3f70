/* gcd_ctx.h — internals of the gCD core shared by core/gcd*.c.
 *
 * Device buffers (names say where they live: d_ = device):
 *   GCD_PTS_IN   int2 per point: true tile-local coordinates, input order
 *   GCD_TEXEL_IN uint per point: its texel, input order (both Phase 1 only;
 *                the storage of d_vote and d_fnext)
 *   d_int2in uint per point: input index of internal point k; internally
 *            the kept points come first in texel order, then the missing
 *            ones by the corner chunk of their texel (locality, and the
 *            order of their reserved slots: see p1_number_kept)
 *   d_pts    int2 per point: true coordinates, internal order
 *   d_pos    int2 per vertex: current coordinates (texel corner of a kept
 *            point until phase 3 shifts it; true position after)
 *   d_texel  uint per point: its texel index
 *   d_seed   uint per texel: index of the point owning it, or GCD_EMPTY
 *   GCD_NEAR   uint per texel: column-nearest site row, then the row stacks
 *              (Phase 1; the storage of d_exact)
 *   GCD_COLOUR uint per texel: texel index of its site (the Voronoi colour;
 *              Phases 1 and 2; the storage of d_cand)
 *   d_tri    int per triangle slot x3: vertex indices (gdt_mesh layout);
 *            a dead slot has tri[3t] = GCD_NONE
 *   d_opp    int per triangle slot x3: packed opposite pointers (gdt_mesh)
 *   d_vt     int per vertex: one live triangle incident to it; a vertex
 *            deleted in Phase 3 holds -2 - q instead, q a former neighbour
 *            (where its re-insertion walk starts)
 *   d_rslot  int2 per real point: the two dead triangle slots Phase 4
 *            inserts it into (reserved by Phase 2 next to the dual
 *            triangles of its home chunk, freed by its own deletion for a
 *            bad case, appended for the insertion path); meaningful only
 *            for points not in the triangulation
 *   d_mrange uint2 per corner chunk: the internal missing points at home
 *            there are kept + [range[2c], range[2c+1])
 * plus scratch buffers named by use.  Vertex indices: real points 0..n-1,
 * fake boundary n..n+GCD_NFAKE-1 (kernels/gcd_geom.clh), then the frame
 * vertices (one per border texel, deleted in Phase 3).
 *
 * Every buffer is owned by the OpenCL context (gdt_ocl.h); the core keeps
 * the handles and grows them on demand between calls.
 */
#ifndef GCD_CTX_H
#define GCD_CTX_H

#include <stddef.h>
#include <stdint.h>

#include "gdt_core.h"
#include "gdt_error.h"
#include "gdt_mesh.h"
#include "gdt_ocl.h"

#include "gcd_geom.clh" /* GCD_NFAKE, GCD_NONE, GCD_EMPTY, the frame layout */

#define GCD_SCAN_CHUNK 256u
/* Fills of at least this many uints run as a kernel (gcd_fill). */
#define GCD_KERNEL_FILL 65536u

/* Corner chunks of a W x H grid (kernels/gcd_geom.clh). */
static inline size_t gcd_corner_chunks(uint32_t W, uint32_t H)
{
    size_t ncorner = W >= 2 && H >= 2 ? (size_t)(W - 1) * (H - 1) : 0;
    return (ncorner + GCD_CORNER_CHUNK - 1) / GCD_CORNER_CHUNK;
}

/* A growable device buffer. */
typedef struct gcd_buf {
    gdt_ocl_buf *b;
    size_t cap;       /* bytes allocated */
    const char *what; /* name for messages */
} gcd_buf;

typedef struct gcd_kernels {
    /* gcd_scan.cl */
    gdt_ocl_kernel *scan_reduce, *scan_single, *scan_down, *compact_index, *radix_hist,
        *radix_scatter, *fill_u32;
    /* gcd_pba.cl */
    gdt_ocl_kernel *p1_splat, *p1_missing_flags, *p1_plant, *p1_frame, *p1_occ_flags,
        *p1_number_kept, *p1_number_missing, *p1_permute, *p1_missing_keys, *p1_missing_range,
        *p1_cols_band, *p1_cols_link,
        *p1_cols, *p1_rows, *p1_debris, *p1_gather, *p1_scatter;
    /* gcd_dual.cl */
    gdt_ocl_kernel *p2_count, *p2_write, *p2_kept_flags;
    /* gcd_mesh.cl */
    gdt_ocl_kernel *m_vcount, *m_vfill, *m_vt_min, *m_link, *m_snap, *m_frame_pos,
        *m_real_flags, *m_compact_tris, *m_fix_vt_collect, *m_fix_vt_apply,
        *m_sort_count, *m_sort_scatter, *m_sort_bucket, *m_sort_inverse,
        *m_sort_apply, *m_sort_vt, *m_slots_seq;
    /* gcd_shift.cl */
    gdt_ocl_kernel *p3_shift, *p3_bulk_check, *p3_bulk_star, *p3_bulk_apply, *p3_del_deg, *p3_del_mark, *p3_del_win, *p3_del_apply,
        *p3_del_link, *p3_del_next, *p3_del_flags;
    /* gcd_insert.cl */
    gdt_ocl_kernel *p4_locate, *p4_mark, *p4_win, *p4_apply, *p4_link, *p4_unmark, *p4_nb,
        *p4_hints, *p4_compact, *p4_absent_flags;
    /* gcd_flip.cl */
    gdt_ocl_kernel *p5_check, *p5_exact, *p5_flip, *p5_link, *p5_next, *p5_all, *p5_from_list,
        *p5_round_flags, *p5_local, *p5_local_lists;
} gcd_kernels;

struct gdt_core {
    gdt_ocl *ocl;
    gdt_log *log;
    gdt_core_opts opts;
    gcd_kernels k;
    /* persistent buffers (grown on demand) */
    gcd_buf d_pts, d_pos, d_texel, d_seed, d_tri, d_opp, d_vt;
    gcd_buf d_cnt, d_flags, d_list, d_list2, d_aux, d_aux2, d_aux3, d_scan, d_small;
    gcd_buf d_band_lo, d_band_hi, d_band_below, d_band_above;
    gcd_buf d_mark, d_round, d_small1, d_small2, d_small3;
    gcd_buf d_vote, d_inact, d_flipped, d_stat, d_active, d_next, d_cand, d_exact;
    gcd_buf d_chk, d_bad, d_vnew, d_list3, d_deg, d_off, d_sc, d_hint, d_hint2;
    gcd_buf d_cont, d_oldnb, d_rank, d_fix, d_stat34, d_fnext, d_int2in,
        d_inm, d_inm2, d_dropped, d_cont2, d_locep, d_locep2,
        d_rk, d_rv, d_rhist, d_mkeys, d_queue, d_nlist, d_nlist2, d_rslot, d_mrange, d_piv;
    size_t scan_levels_cap;
    unsigned strip;  /* columns per work-item in the column pass */
    unsigned bands;  /* row bands of the column pass */
    size_t wg;       /* work-group size of the launches over elements */
    size_t small_wg; /* of the launches over columns, rows and chunks (a few
                      * thousand work-items): 16 on a CPU, 64 on a GPU (two
                      * NVIDIA warps, one AMD wavefront) */
    size_t flip_blocks; /* Phase 5 starts with block-local Lawson passes over
                           about this many blocks (0: parallel rounds only;
                           CPU devices: 32 per compute unit) */
    size_t flip_min_block; /* smallest block (triangle slots) */
    size_t flip_queue;     /* largest queue of a work-item (edges, a power of two) */
};

/* Buffers whose lives do not overlap share storage: the digital Voronoi
 * diagram of Phases 1 and 2 lives in the flip lists, which are scratch of
 * each flipping round (Phases 4 and 5).  Phase 5 keeps its sort's scratch
 * in the same way (sort_tris in gcd_phase5.c). */
#define GCD_NEAR(c) (&(c)->d_exact)
#define GCD_COLOUR(c) (&(c)->d_cand)
/* The per-round scratch of Phases 3-5 (exch: where each outer edge of a
 * modified triangle went; win: the winners among a round's candidates; both
 * are read only where the same round wrote them) lives in Phase 2's vertex
 * arrays, dead from the end of Phase 2 until sort_tris, and then in the
 * triangle storage sort_tris swaps out, dead until extract. */
/* The input-order points and texels of Phase 1 (read last by p1_permute)
 * live in two flip buffers, dead until the flips of Phase 4 or 5. */
#define GCD_PTS_IN(c) (&(c)->d_vote)
#define GCD_TEXEL_IN(c) (&(c)->d_fnext)
#define GCD_EXCH(c) (&(c)->d_aux2)
#define GCD_WIN(c) (&(c)->d_aux3)

/* Geometry of one run (the texel mapping of Phase 1). */
typedef struct gcd_run {
    const gdt_ipt *pts; /* host input (not owned) */
    size_t n;           /* real points */
    size_t nv;          /* vertices: n + GCD_NFAKE + nframe */
    size_t nframe;      /* frame vertices (border texels) */
    size_t frame_base;  /* index of frame vertex 0: n + GCD_NFAKE */
    int64_t xmin, ymin, xmax, ymax;
    int64_t cx, cy;     /* centre of the fake boundary */
    int64_t cell;       /* lattice units per texel */
    uint32_t W, H;      /* texels used */
    size_t ntris;       /* triangle slots in use (live or dead) */
    size_t cap_tris;    /* triangle slots allocated */
    size_t nmissing;    /* entries of the missing list (d_list) */
    size_t kept;
    int all_missing;    /* insertion path: every point goes through Phase 4 */
    int sort_tris;      /* Phase 5 first sorts the triangles (no dead slots):
                           the insertion path, whose slots follow the
                           insertion order; the gcd path's reserved slots
                           already sit next to their neighbours */
    uint32_t epoch;     /* round counter shared by every phase: marks in
                           d_flipped / d_inact name the round that set them */
    gdt_core_stats *st;
} gcd_run;

/* ---- gcd.c: buffers, launches, scans ---- */

/* Makes b hold at least bytes (contents are lost when it grows). */
gdt_status gcd_buf_need(gdt_core *c, gcd_buf *b, size_t bytes, gdt_error *err);
/* Grows b keeping its first keep bytes. */
gdt_status gcd_buf_grow_keep(gdt_core *c, gcd_buf *b, size_t bytes, size_t keep,
                             gdt_error *err);
/* Exclusive scan of n uints of b in place; *total receives the sum. */
gdt_status gcd_scan(gdt_core *c, gcd_buf *b, size_t n, uint32_t *total, gdt_error *err);
/* Reads one uint at element index i of b. */
/* flags[0..n) (0/1, overwritten by their scan) -> out[0..count) the
 * flagged indices in increasing order (out grown as needed). */
gdt_status gcd_compact(gdt_core *c, gcd_buf *flags, size_t n, gcd_buf *out, size_t *count,
                       gdt_error *err);
/* Stable sort of keys[0..n) with vals by the low bits of the keys (LSD
 * radix, 8 bits a pass); the handles of keys and vals may be swapped with
 * scratch buffers. */
gdt_status gcd_radix_sort(gdt_core *c, gcd_buf *keys, gcd_buf *vals, size_t n, unsigned bits,
                          gdt_error *err);
gdt_status gcd_read_u32(gdt_core *c, gcd_buf *b, size_t i, uint32_t *v, gdt_error *err);
gdt_status gcd_fill(gdt_core *c, gcd_buf *b, size_t n_u32, uint32_t v, gdt_error *err);

/* Kernel argument helpers: set a sequence of arguments in one call.
 * Each argument is a (kind, value) pair: 'b' gcd_buf*, 'u' uint32_t (as
 * unsigned), 'i' int32_t (as int), 'l' int64_t. */
gdt_status gcd_args(gdt_ocl_kernel *k, gdt_error *err, const char *kinds, ...);
gdt_status gcd_launch(gdt_core *c, gdt_ocl_kernel *k, size_t global, gdt_error *err);
/* With a given work-group size (a power of two; kernels with few but long
 * work-items need small groups to spread over the compute units). */
gdt_status gcd_launch_wg(gdt_core *c, gdt_ocl_kernel *k, size_t global, size_t wg,
                         gdt_error *err);

double gcd_now(void);


/* ---- phases ---- */
gdt_status gcd_phase1(gdt_core *c, gcd_run *r, gdt_error *err);
gdt_status gcd_voronoi_from_seeds(gdt_core *c, gcd_run *r, gdt_error *err);
gdt_status gcd_phase2(gdt_core *c, gcd_run *r, gdt_error *err);
/* Neighbour links and vertex entries (d_opp, d_vt) of the triangle slots
 * [0, r->ntris): gcd_link_start clears the vertex counts, then the slots
 * before counted must have been counted (p2_write does it for the dual),
 * and gcd_link_all counts the rest and links everything. */
gdt_status gcd_link_start(gdt_core *c, gcd_run *r, gdt_error *err);
gdt_status gcd_link_all(gdt_core *c, gcd_run *r, size_t counted, gdt_error *err);
gdt_status gcd_phase3(gdt_core *c, gcd_run *r, gdt_error *err);
gdt_status gcd_phase4(gdt_core *c, gcd_run *r, int flip_between, gdt_error *err);
gdt_status gcd_phase5(gdt_core *c, gcd_run *r, gdt_error *err);
/* Phase 5 machinery, shared with the insertion path: buffers for T
 * triangle slots (votes reset, counters zeroed), then flipping rounds. */
gdt_status gcd_flip_prepare(gdt_core *c, size_t T, gdt_error *err);
/* Flips until every edge is locally optimal.  all_active: every live slot
 * starts active; else d_active[0..na0) does, marked with r->epoch in
 * d_inact by the caller.  Advances r->epoch; counters go to d_stat. */
gdt_status gcd_flip_run(gdt_core *c, gcd_run *r, size_t na0, int all_active, uint64_t *rounds,
                        gdt_error *err);
/* Sizes the per-run buffers indexed by triangle slot (cap_tris) or vertex
 * and clears the round marks. */
gdt_status gcd_run_buffers(gdt_core *c, gcd_run *r, gdt_error *err);

#endif
