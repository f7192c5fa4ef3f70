/* gcd.c — the gCD core: context, device buffers, scans and the driver of
 * the five phases (see gdt_core.h).  Phases live in gcd_phase*.c. */
#include "private/gcd_ctx.h"
#include "private/gcd_test.h"

#include <inttypes.h>
#include <stdarg.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "gcd_geom.clh"

double gcd_now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- buffers ---- */

gdt_status gcd_buf_need(gdt_core *c, gcd_buf *b, size_t bytes, gdt_error *err)
{
    size_t want;
    if (b->b != NULL && b->cap >= bytes)
        return GDT_OK;
    want = bytes + bytes / 8 + 64;
    if (b->b != NULL) {
        gdt_ocl_buf_release(c->ocl, b->b);
        b->b = NULL;
        b->cap = 0;
    }
    if (gdt_ocl_buf_create(c->ocl, want, b->what, &b->b, err) != GDT_OK)
        return err->status;
    b->cap = want;
    return GDT_OK;
}

gdt_status gcd_buf_grow_keep(gdt_core *c, gcd_buf *b, size_t bytes, size_t keep, gdt_error *err)
{
    gdt_ocl_buf *nb = NULL;
    size_t want;
    if (b->b != NULL && b->cap >= bytes)
        return GDT_OK;
    want = bytes + bytes / 4 + 64;
    if (gdt_ocl_buf_create(c->ocl, want, b->what, &nb, err) != GDT_OK)
        return err->status;
    if (b->b != NULL && keep > 0 &&
        gdt_ocl_copy(c->ocl, b->b, 0, nb, 0, keep < b->cap ? keep : b->cap, err) != GDT_OK) {
        gdt_ocl_buf_release(c->ocl, nb);
        return err->status;
    }
    if (b->b != NULL)
        gdt_ocl_buf_release(c->ocl, b->b);
    b->b = nb;
    b->cap = want;
    return GDT_OK;
}

gdt_status gcd_fill(gdt_core *c, gcd_buf *b, size_t n_u32, uint32_t v, gdt_error *err)
{
    if (n_u32 >= GCD_KERNEL_FILL && n_u32 <= UINT32_MAX) {
        if (gcd_args(c->k.fill_u32, err, "buu", b, (unsigned)n_u32, (unsigned)v) != GDT_OK)
            return err->status;
        return gcd_launch(c, c->k.fill_u32, n_u32, err);
    }
    return gdt_ocl_fill_u32(c->ocl, b->b, 0, v, 4 * n_u32, err);
}

gdt_status gcd_read_u32(gdt_core *c, gcd_buf *b, size_t i, uint32_t *v, gdt_error *err)
{
    return gdt_ocl_read(c->ocl, b->b, 4 * i, v, 4, err);
}

gdt_status gcd_args(gdt_ocl_kernel *k, gdt_error *err, const char *kinds, ...)
{
    va_list ap;
    gdt_status st = GDT_OK;
    va_start(ap, kinds);
    for (unsigned i = 0; kinds[i] != '\0' && st == GDT_OK; i++) {
        switch (kinds[i]) {
        case 'b': {
            gcd_buf *b = va_arg(ap, gcd_buf *);
            st = gdt_ocl_arg_buf(k, i, b->b, err);
            break;
        }
        case 'u':
            st = gdt_ocl_arg_u32(k, i, va_arg(ap, unsigned), err);
            break;
        case 'i':
            st = gdt_ocl_arg_i32(k, i, va_arg(ap, int), err);
            break;
        case 'l':
            st = gdt_ocl_arg_i64(k, i, va_arg(ap, int64_t), err);
            break;
        default:
            st = gdt_error_set(err, GDT_EINTERNAL, 7601, "bad kernel argument kind '%c'",
                               kinds[i]);
        }
    }
    va_end(ap);
    return st;
}

/* A fixed work-group size per kernel: PoCL specialises (compiles) a kernel
 * for every local size it meets, so letting it choose per launch would
 * recompile.  c->wg, or the largest power of two the device allows for the
 * kernel (register-hungry kernels may allow less on a GPU). */
gdt_status gcd_launch(gdt_core *c, gdt_ocl_kernel *k, size_t global, gdt_error *err)
{
    return gcd_launch_wg(c, k, global, c->wg, err);
}

gdt_status gcd_launch_wg(gdt_core *c, gdt_ocl_kernel *k, size_t global, size_t wg,
                         gdt_error *err)
{
    size_t max = gdt_ocl_kernel_max_wg(k);
    while (wg > 1 && wg > max)
        wg /= 2;
    return gdt_ocl_run(c->ocl, k, global, wg, err);
}

/* ---- exclusive scan ----
 * Level sums live in d_scan: element 0 holds the total, the levels follow. */
gdt_status gcd_scan(gdt_core *c, gcd_buf *b, size_t n, uint32_t *total, gdt_error *err)
{
    const uint32_t CH = GCD_SCAN_CHUNK;
    size_t sizes[16], offs[16], need = 1;
    int levels = 0;
    gcd_buf *data[16];
    size_t doff[16];

    if (n == 0) {
        *total = 0;
        return GDT_OK;
    }
    if (n > UINT32_MAX / 2)
        return gdt_error_set(err, GDT_EINTERNAL, 7602, "scan of %zu elements is too long", n);
    sizes[0] = n;
    while (sizes[levels] > CH && levels < 15) {
        sizes[levels + 1] = (sizes[levels] + CH - 1) / CH;
        offs[levels + 1] = need;
        need += sizes[levels + 1];
        levels++;
    }
    if (gcd_buf_need(c, &c->d_scan, 4 * need, err) != GDT_OK)
        return err->status;
    data[0] = b;
    doff[0] = 0;
    for (int l = 1; l <= levels; l++) {
        data[l] = &c->d_scan;
        doff[l] = offs[l];
    }
    for (int l = 0; l < levels; l++) {
        if (gcd_args(c->k.scan_reduce, err, "buuubu", data[l], (unsigned)doff[l],
                     (unsigned)sizes[l], CH, data[l + 1], (unsigned)doff[l + 1]) != GDT_OK ||
            gcd_launch(c, c->k.scan_reduce, sizes[l + 1], err) != GDT_OK)
            return err->status;
    }
    if (gcd_args(c->k.scan_single, err, "buubu", data[levels], (unsigned)doff[levels],
                 (unsigned)sizes[levels], &c->d_scan, 0u) != GDT_OK ||
        gcd_launch(c, c->k.scan_single, 1, err) != GDT_OK)
        return err->status;
    for (int l = levels - 1; l >= 0; l--) {
        if (gcd_args(c->k.scan_down, err, "buuubu", data[l], (unsigned)doff[l],
                     (unsigned)sizes[l], CH, data[l + 1], (unsigned)doff[l + 1]) != GDT_OK ||
            gcd_launch(c, c->k.scan_down, sizes[l + 1], err) != GDT_OK)
            return err->status;
    }
    return gcd_read_u32(c, &c->d_scan, 0, total, err);
}

gdt_status gcd_compact(gdt_core *c, gcd_buf *flags, size_t n, gcd_buf *out, size_t *count,
                       gdt_error *err)
{
    uint32_t total = 0;
    *count = 0;
    if (n == 0)
        return GDT_OK;
    if (gcd_scan(c, flags, n, &total, err) != GDT_OK)
        return err->status;
    if (total > 0) {
        if (gcd_buf_need(c, out, 4 * (size_t)total, err) != GDT_OK ||
            gcd_args(c->k.compact_index, err, "buub", flags, (unsigned)n, total, out) != GDT_OK ||
            gcd_launch(c, c->k.compact_index, n, err) != GDT_OK)
            return err->status;
    }
    *count = total;
    return GDT_OK;
}

/* Stable sort of keys[0..n) with vals (d_ buffers, sorted in place through
 * two scratch buffers) by the low `bits` bits of the keys. */
gdt_status gcd_radix_sort(gdt_core *c, gcd_buf *keys, gcd_buf *vals, size_t n, unsigned bits,
                          gdt_error *err)
{
    const uint32_t chunk = 1024;
    size_t nchunks = (n + chunk - 1) / chunk;
    uint32_t total = 0;
    if (n <= 1)
        return GDT_OK;
    if (gcd_buf_need(c, &c->d_rk, 4 * n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_rv, 4 * n, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_rhist, 4 * 256 * nchunks, err) != GDT_OK)
        return err->status;
    for (unsigned shift = 0; shift < bits; shift += 8) {
        if (gcd_args(c->k.radix_hist, err, "buuuub", keys, (unsigned)n, shift, chunk,
                     (unsigned)nchunks, &c->d_rhist) != GDT_OK ||
            gcd_launch_wg(c, c->k.radix_hist, nchunks, c->small_wg, err) != GDT_OK ||
            gcd_scan(c, &c->d_rhist, 256 * nchunks, &total, err) != GDT_OK ||
            gcd_args(c->k.radix_scatter, err, "bbuuuubbb", keys, vals, (unsigned)n, shift, chunk,
                     (unsigned)nchunks, &c->d_rhist, &c->d_rk, &c->d_rv) != GDT_OK ||
            gcd_launch_wg(c, c->k.radix_scatter, nchunks, c->small_wg, err) != GDT_OK)
            return err->status;
        gcd_buf tmp = *keys;
        *keys = c->d_rk;
        c->d_rk = tmp;
        tmp = *vals;
        *vals = c->d_rv;
        c->d_rv = tmp;
    }
    return GDT_OK;
}

/* ---- context ---- */

typedef struct kdef {
    const char *file;
    const char *name;
    size_t off; /* offset of the gdt_ocl_kernel * in gcd_kernels */
} kdef;

#define KD(f, n) {f, #n, offsetof(gcd_kernels, n)}
static const kdef KERNELS[] = {
    KD("gcd_scan.cl", scan_reduce),
    KD("gcd_scan.cl", scan_single),
    KD("gcd_scan.cl", scan_down),
    KD("gcd_scan.cl", compact_index),
    KD("gcd_scan.cl", radix_hist),
    KD("gcd_scan.cl", radix_scatter),
    KD("gcd_scan.cl", fill_u32),
    KD("gcd_pba.cl", p1_missing_keys),
    KD("gcd_pba.cl", p1_missing_range),
    KD("gcd_pba.cl", p1_splat),
    KD("gcd_pba.cl", p1_missing_flags),
    KD("gcd_pba.cl", p1_plant),
    KD("gcd_pba.cl", p1_frame),
    KD("gcd_pba.cl", p1_occ_flags),
    KD("gcd_pba.cl", p1_number_kept),
    KD("gcd_pba.cl", p1_number_missing),
    KD("gcd_pba.cl", p1_permute),
    KD("gcd_mesh.cl", m_sort_count),
    KD("gcd_mesh.cl", m_sort_scatter),
    KD("gcd_mesh.cl", m_sort_bucket),
    KD("gcd_mesh.cl", m_sort_inverse),
    KD("gcd_mesh.cl", m_sort_apply),
    KD("gcd_mesh.cl", m_sort_vt),
    KD("gcd_mesh.cl", m_slots_seq),
    KD("gcd_pba.cl", p1_cols_band),
    KD("gcd_pba.cl", p1_cols_link),
    KD("gcd_pba.cl", p1_cols),
    KD("gcd_pba.cl", p1_rows),
    KD("gcd_pba.cl", p1_debris),
    KD("gcd_pba.cl", p1_gather),
    KD("gcd_pba.cl", p1_scatter),
    KD("gcd_dual.cl", p2_count),
    KD("gcd_dual.cl", p2_write),
    KD("gcd_dual.cl", p2_kept_flags),
    KD("gcd_mesh.cl", m_vcount),
    KD("gcd_mesh.cl", m_vfill),
    KD("gcd_mesh.cl", m_vt_min),
    KD("gcd_mesh.cl", m_link),
    KD("gcd_mesh.cl", m_snap),
    KD("gcd_mesh.cl", m_frame_pos),
    KD("gcd_mesh.cl", m_real_flags),
    KD("gcd_mesh.cl", m_compact_tris),
    KD("gcd_mesh.cl", m_fix_vt_collect),
    KD("gcd_mesh.cl", m_fix_vt_apply),
    KD("gcd_flip.cl", p5_check),
    KD("gcd_flip.cl", p5_exact),
    KD("gcd_flip.cl", p5_flip),
    KD("gcd_flip.cl", p5_link),
    KD("gcd_flip.cl", p5_next),
    KD("gcd_flip.cl", p5_all),
    KD("gcd_flip.cl", p5_from_list),
    KD("gcd_flip.cl", p5_round_flags),
    KD("gcd_flip.cl", p5_local),
    KD("gcd_flip.cl", p5_local_lists),
    KD("gcd_shift.cl", p3_shift),
    KD("gcd_shift.cl", p3_bulk_check),
    KD("gcd_shift.cl", p3_bulk_star),
    KD("gcd_shift.cl", p3_bulk_apply),
    KD("gcd_shift.cl", p3_del_deg),
    KD("gcd_shift.cl", p3_del_mark),
    KD("gcd_shift.cl", p3_del_win),
    KD("gcd_shift.cl", p3_del_apply),
    KD("gcd_shift.cl", p3_del_link),
    KD("gcd_shift.cl", p3_del_next),
    KD("gcd_shift.cl", p3_del_flags),
    KD("gcd_insert.cl", p4_locate),
    KD("gcd_insert.cl", p4_mark),
    KD("gcd_insert.cl", p4_win),
    KD("gcd_insert.cl", p4_apply),
    KD("gcd_insert.cl", p4_link),
    KD("gcd_insert.cl", p4_unmark),
    KD("gcd_insert.cl", p4_nb),
    KD("gcd_insert.cl", p4_hints),
    KD("gcd_insert.cl", p4_compact),
    KD("gcd_insert.cl", p4_absent_flags),
};
#undef KD

static const char *const PROGRAMS[] = {"gcd_scan.cl", "gcd_pba.cl", "gcd_dual.cl", "gcd_mesh.cl",
                                       "gcd_flip.cl", "gcd_shift.cl", "gcd_insert.cl"};

gdt_status gdt_core_create(gdt_core **out, const gdt_core_opts *opts, gdt_error *err)
{
    gdt_core *c = NULL;
    gdt_ocl_opts oo;
    gdt_ocl **shared = NULL;
    gdt_status st;
    char extra[128];

    *out = NULL;
    c = calloc(1, sizeof *c);
    if (c == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (opts != NULL)
        c->opts = *opts;
    c->log = c->opts.log;
    memset(&oo, 0, sizeof oo);
    oo.device = c->opts.device;
    oo.local_rank = c->opts.local_rank;
    oo.cache_dir = c->opts.cache_dir;
    oo.kernel_dir = c->opts.kernel_dir;
    oo.force_no_fp64 = c->opts.force_no_fp64;
    oo.profile = c->opts.profile;
    oo.log = c->log;
    if (c->opts.nshare > 0) {
        shared = calloc(c->opts.nshare, sizeof *shared);
        if (shared == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto fail;
        }
        for (size_t i = 0; i < c->opts.nshare; i++)
            shared[i] = c->opts.share[i] != NULL ? c->opts.share[i]->ocl : NULL;
        oo.share = shared;
        oo.nshare = c->opts.nshare;
    }
    st = gdt_ocl_create(&c->ocl, &oo, err);
    free(shared);
    shared = NULL;
    c->opts.share = NULL; /* not kept: only for the creation */
    c->opts.nshare = 0;
    if (st != GDT_OK)
        goto fail;
    /* Sizes from the device's type and limits.  CPU devices run one
     * work-item per core stretch: each column-pass work-item gets a strip of
     * columns so it walks memory row by row, and small work-groups.  A GPU
     * wants one column per work-item, row bands for more of them, and
     * work-groups of whole warps or wavefronts.  Every launch is further
     * held to what the device allows for its kernel (gcd_launch_wg). */
    {
        const int gpu = !gdt_ocl_is_cpu(c->ocl) || c->opts.gpu_layout;
        size_t dmax = gdt_ocl_device_max_wg(c->ocl);
        c->strip = gpu ? 1 : 16;
        c->bands = gpu ? 8 : 1;
        c->wg = 256;
        while (c->wg > 1 && c->wg > dmax)
            c->wg /= 2;
        c->small_wg = gpu ? 64 : 16;
        while (c->small_wg > 1 && c->small_wg > dmax)
            c->small_wg /= 2;
    }
    gcd_test_set_flip_blocks(c, SIZE_MAX, 0, 0);
    snprintf(extra, sizeof extra, "-DSTRIP=%u", c->strip);
    for (size_t p = 0; p < sizeof PROGRAMS / sizeof PROGRAMS[0]; p++) {
        gdt_ocl_program *prog = NULL;
        if (c->opts.stop != NULL && *c->opts.stop != 0) {
            st = gdt_error_set(err, GDT_EINTERRUPTED, 1303,
                               "stopped by a signal before building the OpenCL program %s",
                               PROGRAMS[p]);
            goto fail;
        }
        st = gdt_ocl_build(c->ocl, PROGRAMS[p], extra, &prog, err);
        if (st != GDT_OK)
            goto fail;
        for (size_t k = 0; k < sizeof KERNELS / sizeof KERNELS[0]; k++) {
            if (strcmp(KERNELS[k].file, PROGRAMS[p]) != 0)
                continue;
            gdt_ocl_kernel **slot = (gdt_ocl_kernel **)((char *)&c->k + KERNELS[k].off);
            st = gdt_ocl_kernel_get(prog, KERNELS[k].name, slot, err);
            if (st != GDT_OK)
                goto fail;
        }
    }
    {
        unsigned cached = 0, built = 0;
        const char *dir = NULL;
        gdt_ocl_program_counts(c->ocl, &cached, &built, &dir);
        if (cached + built > 0)
            gdt_log_note(c->log, "OpenCL programs: %u from the program cache %s, %u built from "
                                 "source",
                         cached, dir != NULL ? dir : "(none)", built);
    }
#define NAME(b) c->b.what = #b
    NAME(d_pts);
    NAME(d_pos);
    NAME(d_texel);
    NAME(d_seed);
    NAME(d_tri);
    NAME(d_opp);
    NAME(d_vt);
    NAME(d_cnt);
    NAME(d_flags);
    NAME(d_list);
    NAME(d_list2);
    NAME(d_aux);
    NAME(d_aux2);
    NAME(d_aux3);
    NAME(d_scan);
    NAME(d_small);
    NAME(d_band_lo);
    NAME(d_band_hi);
    NAME(d_band_below);
    NAME(d_band_above);
    NAME(d_mark);
    NAME(d_round);
    NAME(d_small1);
    NAME(d_small2);
    NAME(d_small3);
    NAME(d_vote);
    NAME(d_inact);
    NAME(d_flipped);
    NAME(d_stat);
    NAME(d_active);
    NAME(d_next);
    NAME(d_cand);
    NAME(d_exact);
    NAME(d_chk);
    NAME(d_bad);
    NAME(d_vnew);
    NAME(d_list3);
    NAME(d_deg);
    NAME(d_off);
    NAME(d_sc);
    NAME(d_hint);
    NAME(d_hint2);
    NAME(d_cont);
    NAME(d_oldnb);
    NAME(d_rank);
    NAME(d_fix);
    NAME(d_stat34);
    NAME(d_fnext);
    NAME(d_int2in);
    NAME(d_inm);
    NAME(d_inm2);
    NAME(d_dropped);
    NAME(d_cont2);
    NAME(d_locep);
    NAME(d_locep2);
    NAME(d_rk);
    NAME(d_rv);
    NAME(d_rhist);
    NAME(d_mkeys);
    NAME(d_queue);
    NAME(d_nlist);
    NAME(d_nlist2);
    NAME(d_piv);
    NAME(d_rslot);
    NAME(d_mrange);
#undef NAME
    st = gcd_buf_need(c, &c->d_small, 64, err);
    if (st == GDT_OK)
        st = gcd_buf_need(c, &c->d_small1, 64, err);
    if (st == GDT_OK)
        st = gcd_buf_need(c, &c->d_small2, 64, err);
    if (st == GDT_OK)
        st = gcd_buf_need(c, &c->d_small3, 64, err);
    if (st != GDT_OK)
        goto fail;
    *out = c;
    return GDT_OK;
fail:
    gdt_core_destroy(c);
    return st;
}

const char *gdt_core_device_name(const gdt_core *core)
{
    return gdt_ocl_device_name(core->ocl);
}

/* Bytes per texel and per point of the core's buffers: the texel arrays of
 * phase 1 (colours, nearest sites, seeds, flags) and, per point, its
 * coordinates and ranks, about two triangles with their opposite links and
 * the sort and compaction scratch of phases 2-5.  Measured peaks (GPU
 * layout, result read back, 1024^2 and 2048^2 grids, N^2/4 and N^2/2
 * uniform and lidar points): 95-203 B per texel, 356-444 B per point,
 * every one under this bound (test_gcd.py). */
#define CORE_TEXEL_BYTES 24u
#define CORE_POINT_BYTES 400u
/* the largest single buffer: the triangles (12 B, two per point and two
 * slots per missing point) and the texel arrays */
#define CORE_BUFFER_POINT_BYTES 48u
#define CORE_BUFFER_TEXEL_BYTES 4u

uint64_t gdt_core_tile_bytes(int grid_n, uint64_t points)
{
    uint64_t texels = grid_n > 0 ? (uint64_t)grid_n * (uint64_t)grid_n : 0;
    return CORE_TEXEL_BYTES * texels + CORE_POINT_BYTES * points + ((uint64_t)16 << 20);
}

int gdt_core_auto_tile(int is_cpu, uint64_t device_mem, uint64_t max_alloc, uint64_t host_mem)
{
    if (is_cpu)
        return GDT_CORE_CPU_TILE;
    for (int n = 16384; n > GDT_CORE_CPU_TILE; n /= 2) {
        uint64_t texels = (uint64_t)n * (uint64_t)n, points = texels / 2;
        uint64_t largest = CORE_BUFFER_POINT_BYTES * points + CORE_BUFFER_TEXEL_BYTES * texels;
        if (device_mem != 0 && gdt_core_tile_bytes(n, points) > device_mem / 4 * 3)
            continue;
        if (max_alloc != 0 && largest > max_alloc)
            continue;
        if (host_mem != 0 && GDT_CORE_HOST_BYTES_PER_POINT * points > host_mem / 2)
            continue;
        return n;
    }
    return GDT_CORE_CPU_TILE;
}

uint64_t gdt_core_device_peak(const gdt_core *core)
{
    return gdt_ocl_peak_bytes(core->ocl);
}

double gdt_core_device_busy(gdt_core *core)
{
    return gdt_ocl_busy_seconds(core->ocl);
}

int gdt_core_shares_device(const gdt_core *core)
{
    return gdt_ocl_is_shared_queue(core->ocl);
}

int gdt_core_same_device(const gdt_core *a, const gdt_core *b)
{
    return gdt_ocl_same_device(a->ocl, b->ocl);
}

int gdt_core_on_cpu(const gdt_core *core)
{
    return gdt_ocl_is_cpu(core->ocl);
}

uint64_t gdt_core_device_memory(const gdt_core *core)
{
    return gdt_ocl_global_mem(core->ocl);
}

void gdt_core_profile_dump(gdt_core *core, FILE *f)
{
    gdt_ocl_profile_dump(core->ocl, f);
}

void gdt_core_destroy(gdt_core *core)
{
    if (core == NULL)
        return;
    gdt_ocl_destroy(core->ocl);
    free(core);
}

/* ---- runs ---- */

/* Validates the input and sets up the texel mapping and the device copy
 * of the points.  min_grid: smallest legal grid_n (tests use small grids). */
static gdt_status setup_run(gdt_core *c, gcd_run *r, const gdt_ipt *pts, size_t n, int grid_n,
                            int min_grid, gdt_core_stats *st, gdt_error *err)
{
    int32_t *tmp = NULL;
    void *mapped = NULL;
    int64_t span;

    memset(r, 0, sizeof *r);
    r->pts = pts;
    r->n = n;
    r->st = st;
    if (grid_n < min_grid || grid_n > 16384 || (grid_n & (grid_n - 1)) != 0)
        return gdt_error_set(err, GDT_EINPUT, 3601,
                             "grid size %d: must be a power of two in %d..16384", grid_n,
                             min_grid);
    if (n > GDT_MESH_MAX_VERTS - 64)
        return gdt_error_set(err, GDT_EINPUT, 3601, "%zu points in one tile: at most %zu", n,
                             (size_t)(GDT_MESH_MAX_VERTS - 64));
    for (size_t i = 0; i < n; i++) {
        if (pts[i].x < 0 || pts[i].y < 0 || pts[i].x > GDT_COORD_MAX || pts[i].y > GDT_COORD_MAX)
            return gdt_error_set(err, GDT_EINPUT, 3601,
                                 "point %zu (%" PRId64 ", %" PRId64 ") is outside the tile-local "
                                 "range [0, 2^31-1]",
                                 i, pts[i].x, pts[i].y);
        if (i == 0 || pts[i].x < r->xmin)
            r->xmin = pts[i].x;
        if (i == 0 || pts[i].x > r->xmax)
            r->xmax = pts[i].x;
        if (i == 0 || pts[i].y < r->ymin)
            r->ymin = pts[i].y;
        if (i == 0 || pts[i].y > r->ymax)
            r->ymax = pts[i].y;
    }
    span = (r->xmax - r->xmin > r->ymax - r->ymin ? r->xmax - r->xmin : r->ymax - r->ymin) + 1;
    r->cell = (span + grid_n - 1) / grid_n;
    if (!c->opts.full_grid) {
        /* A full tile holds about grid_n^2/4 points; a sparser one, or one
         * whose points cover only part of the square, gets coarser texels:
         * about 4 texels per point over the points' bounding box (at least
         * 64 per side), since the grid passes cost as much as the texels. */
        int64_t w = r->xmax - r->xmin + 1, h = r->ymax - r->ymin + 1, c4 = span / 64;
        double area = (double)w * (double)h / (4.0 * (double)(n > 0 ? n : 1));
        int64_t ca = (int64_t)sqrt(area);
        if (ca > c4)
            ca = c4;
        if (ca > r->cell)
            r->cell = ca;
    }
    r->W = (uint32_t)((r->xmax - r->xmin) / r->cell + 1);
    r->H = (uint32_t)((r->ymax - r->ymin) / r->cell + 1);
    r->cx = r->xmin + (r->xmax - r->xmin) / 2;
    r->cy = r->ymin + (r->ymax - r->ymin) / 2;
    r->nframe = gcd_frame_count(r->W, r->H);
    r->frame_base = n + GCD_NFAKE;
    r->nv = n + GCD_NFAKE + r->nframe;
    /* slots: the gcd path uses 2 nv - 14 (dual and ring, 2 per vertex
     * not in them reserved), the insertion path 10 + 2 n */
    r->cap_tris = 2 * r->nv + 16;
    if (st != NULL) {
        st->points = n;
        st->grid_w = r->W;
        st->grid_h = r->H;
        st->cell = r->cell;
    }
    if (n == 0)
        return GDT_OK;
    /* the points as int32 pairs, written where the buffer is mapped (its
     * own memory on a CPU device: no staging copy) */
    if (gcd_buf_need(c, GCD_PTS_IN(c), 8 * n, err) != GDT_OK ||
        gdt_ocl_map_write(c->ocl, GCD_PTS_IN(c)->b, 8 * n, &mapped, err) != GDT_OK)
        return err->status;
    tmp = mapped;
    for (size_t i = 0; i < n; i++) {
        tmp[2 * i] = (int32_t)pts[i].x;
        tmp[2 * i + 1] = (int32_t)pts[i].y;
    }
    return gdt_ocl_unmap(c->ocl, GCD_PTS_IN(c)->b, tmp, err);
}

/* Reads the current triangle list (live and dead slots) and positions into
 * m: vertices n + GCD_NFAKE (fakes at (0, 0)), triangles r->ntris. */
static gdt_status read_all(gdt_core *c, gcd_run *r, gdt_mesh *m, gdt_error *err)
{
    int32_t *pos = NULL;
    gdt_status st;

    st = gdt_mesh_reserve(m, r->nv, r->ntris, 0, err);
    if (st != GDT_OK)
        return st;
    pos = malloc(8 * r->nv);
    if (pos == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    if (gdt_ocl_read(c->ocl, c->d_pos.b, 0, pos, 8 * r->nv, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_tri.b, 0, m->tri, 12 * r->ntris, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_opp.b, 0, m->opp, 12 * r->ntris, err) != GDT_OK) {
        free(pos);
        return err->status;
    }
    for (size_t i = 0; i < r->nv; i++) {
        int fake = i >= r->n && i < r->frame_base;
        m->pts[i].x = fake ? 0 : pos[2 * i];
        m->pts[i].y = fake ? 0 : pos[2 * i + 1];
    }
    m->nverts = r->nv;
    m->ntris = r->ntris;
    free(pos);
    return GDT_OK;
}

/* Debug check between phases (opts.check_phases): the live triangles must
 * form a valid triangulation in the symbolic plane — every triangle
 * strictly counter-clockwise, every link mutual and traversing the edge the
 * other way, only the 12 fake-fake edges without neighbour, Euler's
 * relation T = 2V - 14 over the vertices in use, and (with_vt) every vertex
 * in use naming a live triangle that holds it.  O(V + T) on the host. */
static gdt_status check_phase(gdt_core *c, gcd_run *r, const char *phase, int with_vt,
                              gdt_error *err)
{
    gdt_mesh m;
    uint8_t *used = NULL;
    size_t live = 0, nused = 0, boundary = 0;
    gdt_status st;

    gdt_mesh_init(&m);
    st = read_all(c, r, &m, err);
    if (st != GDT_OK)
        goto done;
    used = calloc(m.nverts, 1);
    if (used == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (size_t t = 0; t < m.ntris; t++) {
        const int32_t *V = m.tri + 3 * t;
        gcd_spt s[3];
        if (V[0] < 0)
            continue;
        live++;
        for (int i = 0; i < 3; i++) {
            int32_t v = V[i];
            if (v < 0 || (size_t)v >= m.nverts) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7690, "after %s: triangle %zu has vertex %d",
                                   phase, t, v);
                goto done;
            }
            used[v] = 1;
            s[i] = ((size_t)v >= r->n && (size_t)v < r->frame_base)
                       ? gcd_spt_fake(v - (int32_t)r->n)
                       : gcd_spt_real(m.pts[v].x, m.pts[v].y, r->cx, r->cy);
        }
        if (gcd_orient(s[0], s[1], s[2]) <= 0) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7690,
                               "after %s: triangle %zu (%d, %d, %d) is not counter-clockwise",
                               phase, t, V[0], V[1], V[2]);
            goto done;
        }
        for (int i = 0; i < 3; i++) {
            int32_t o = m.opp[3 * t + (size_t)i];
            int32_t a = V[(i + 1) % 3], b = V[(i + 2) % 3];
            if (o < 0) {
                boundary++;
                continue;
            }
            int32_t u = gdt_opp_tri(o);
            int j = gdt_opp_slot(o);
            if ((size_t)u >= m.ntris || j > 2 || m.tri[3 * (size_t)u] < 0 ||
                m.opp[3 * (size_t)u + (size_t)j] != gdt_opp_pack((int32_t)t, i) ||
                m.tri[3 * (size_t)u + (size_t)(j + 1) % 3] != b ||
                m.tri[3 * (size_t)u + (size_t)(j + 2) % 3] != a) {
                st = gdt_error_set(err, GDT_EINTERNAL, 7690,
                                   "after %s: bad link at triangle %zu slot %d (edge %d-%d)", phase,
                                   t, i, a, b);
                goto done;
            }
        }
    }
    for (size_t v = 0; v < m.nverts; v++)
        nused += used[v];
    if (with_vt) {
        int32_t *vt = malloc(4 * r->nv);
        if (vt == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto done;
        }
        st = gdt_ocl_read(c->ocl, c->d_vt.b, 0, vt, 4 * r->nv, err);
        for (size_t v = 0; v < m.nverts && st == GDT_OK; v++) {
            int32_t t = vt[v];
            if (!used[v])
                continue;
            if (t < 0 || (size_t)t >= m.ntris || m.tri[3 * (size_t)t] < 0 ||
                (m.tri[3 * (size_t)t] != (int32_t)v && m.tri[3 * (size_t)t + 1] != (int32_t)v &&
                 m.tri[3 * (size_t)t + 2] != (int32_t)v))
                st = gdt_error_set(err, GDT_EINTERNAL, 7690,
                                   "after %s: vertex %zu names triangle %d, which does not hold it",
                                   phase, v, t);
        }
        free(vt);
        if (st != GDT_OK)
            goto done;
    }
    if (boundary != GCD_NFAKE || live != 2 * nused - GCD_NFAKE - 2)
        st = gdt_error_set(err, GDT_EINTERNAL, 7690,
                           "after %s: %zu triangles, %zu vertices, %zu boundary edges", phase,
                           live, nused, boundary);
done:
    free(used);
    gdt_mesh_free(&m);
    return st;
}

gdt_status gcd_test_phase2(gdt_core *c, const gdt_ipt *pts, size_t n, int grid_n, gdt_mesh *all,
                           int64_t centre[2], gdt_core_stats *st, gdt_error *err)
{
    gcd_run r;
    if (setup_run(c, &r, pts, n, grid_n, 2, st, err) != GDT_OK)
        return err->status;
    if (n == 0)
        return gdt_error_set(err, GDT_EINPUT, 3601, "no points");
    if (gcd_phase1(c, &r, err) != GDT_OK || gcd_voronoi_from_seeds(c, &r, err) != GDT_OK ||
        gcd_phase2(c, &r, err) != GDT_OK || gdt_ocl_finish(c->ocl, err) != GDT_OK)
        return err->status;
    centre[0] = r.cx;
    centre[1] = r.cy;
    return read_all(c, &r, all, err);
}

/* The insertion path's start: the fake polygon as a fan from fake 0. */
static gdt_status fake_fan(gdt_core *c, gcd_run *r, gdt_error *err)
{
    int32_t tri[3 * (GCD_NFAKE - 2)];
    int32_t base = (int32_t)r->n;
    for (int k = 1; k + 1 < GCD_NFAKE; k++) {
        tri[3 * (k - 1)] = base;
        tri[3 * (k - 1) + 1] = base + k;
        tri[3 * (k - 1) + 2] = base + k + 1;
    }
    r->ntris = GCD_NFAKE - 2;
    if (r->ntris + 2 * r->n > r->cap_tris)
        return gdt_error_set(err, GDT_EINTERNAL, 7643, "no room for %zu points", r->n);
    /* point p is inserted into the dead slots r->ntris + 2p and the next */
    if (gcd_buf_need(c, &c->d_tri, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_opp, 12 * r->cap_tris, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_pos, 8 * r->nv, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_rslot, 8 * r->n + 8, err) != GDT_OK ||
        gdt_ocl_copy(c->ocl, c->d_pts.b, 0, c->d_pos.b, 0, 8 * r->n, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_tri.b, 0, tri, sizeof tri, err) != GDT_OK ||
        gcd_args(c->k.m_slots_seq, err, "uuubb", 0u, (unsigned)r->n, (unsigned)r->ntris,
                 &c->d_tri, &c->d_rslot) != GDT_OK ||
        gcd_launch(c, c->k.m_slots_seq, r->n, err) != GDT_OK)
        return err->status;
    r->ntris += 2 * r->n;
    if (gcd_link_start(c, r, err) != GDT_OK)
        return err->status;
    return gcd_link_all(c, r, 0, err);
}

/* Real triangles to the output mesh.  On a CPU device the compaction
 * writes straight into out's arrays, wrapped as buffers; elsewhere (or
 * when wrapping is refused) into d_aux2 and d_aux3, dead after Phase 5,
 * which are read back. */
static gdt_status compact_into(gdt_core *c, gcd_run *r, gdt_mesh *out, uint32_t nreal,
                               gdt_error *err)
{
    size_t T = r->ntris, bytes = 12 * (size_t)nreal;
    gcd_buf wt = {NULL, 0, "mesh triangles"}, wo = {NULL, 0, "mesh links"};
    gdt_status st = GDT_OK;

    if (!c->opts.copy_out) {
        st = gdt_ocl_buf_wrap(c->ocl, out->tri, bytes, wt.what, &wt.b, err);
        if (st == GDT_OK)
            st = gdt_ocl_buf_wrap(c->ocl, out->opp, bytes, wo.what, &wo.b, err);
    }
    if (st == GDT_OK && (wt.b == NULL || wo.b == NULL)) {
        gdt_ocl_buf_release(c->ocl, wt.b);
        gdt_ocl_buf_release(c->ocl, wo.b);
        wt.b = wo.b = NULL;
        st = gcd_buf_need(c, &c->d_aux2, 12 * T, err);
        if (st == GDT_OK)
            st = gcd_buf_need(c, &c->d_aux3, 12 * T, err);
    }
    if (st == GDT_OK)
        st = gcd_args(c->k.m_compact_tris, err, "bbububbb", &c->d_tri, &c->d_opp, (unsigned)T,
                      &c->d_flags, nreal, &c->d_int2in, wt.b != NULL ? &wt : &c->d_aux2,
                      wo.b != NULL ? &wo : &c->d_aux3);
    if (st == GDT_OK)
        st = gcd_launch(c, c->k.m_compact_tris, T, err);
    if (st == GDT_OK && wt.b != NULL) {
        st = gdt_ocl_buf_sync_host(c->ocl, wt.b, err);
        if (st == GDT_OK)
            st = gdt_ocl_buf_sync_host(c->ocl, wo.b, err);
    } else if (st == GDT_OK) {
        st = gdt_ocl_read(c->ocl, c->d_aux2.b, 0, out->tri, bytes, err);
        if (st == GDT_OK)
            st = gdt_ocl_read(c->ocl, c->d_aux3.b, 0, out->opp, bytes, err);
    }
    gdt_ocl_buf_release(c->ocl, wt.b);
    gdt_ocl_buf_release(c->ocl, wo.b);
    return st;
}

static gdt_status extract(gdt_core *c, gcd_run *r, gdt_mesh *out, gdt_error *err)
{
    size_t T = r->ntris;
    uint32_t nreal = 0;
    gdt_status st;

    if (T > 0 &&
        (gcd_buf_need(c, &c->d_flags, 4 * T, err) != GDT_OK ||
         gcd_args(c->k.m_real_flags, err, "buib", &c->d_tri, (unsigned)T, (int)r->n,
                  &c->d_flags) != GDT_OK ||
         gcd_launch(c, c->k.m_real_flags, T, err) != GDT_OK ||
         gcd_scan(c, &c->d_flags, T, &nreal, err) != GDT_OK))
        return err->status;
    st = gdt_mesh_reserve(out, r->n, nreal, out->ids != NULL, err);
    if (st == GDT_OK && nreal > 0)
        st = compact_into(c, r, out, nreal, err);
    if (st != GDT_OK)
        return st;
    /* out->pts had room for n (see gdt_core_triangulate) when it is the input */
    if (r->n > 0 && out->pts != r->pts)
        memcpy(out->pts, r->pts, r->n * sizeof *out->pts);
    if (out->ids != NULL)
        for (size_t i = 0; i < r->n; i++)
            out->ids[i] = (int64_t)i;
    out->nverts = r->n;
    out->ntris = nreal;
    return GDT_OK;
}

gdt_status gdt_core_triangulate(gdt_core *core, const gdt_ipt *pts, size_t n, int grid_n,
                                gdt_mesh *out, gdt_core_stats *stats, gdt_error *err)
{
    gdt_core_stats local;
    gcd_run r;
    double t0 = gcd_now(), t1;
    gdt_core_stats *st = stats != NULL ? stats : &local;
    /* default: the digital-Voronoi path whatever the missing fraction: with
     * Phase 4's slots and hints and Phase 5's block-local flipping it beats
     * the insertion path even with 99.9% of the points in a few texels */
    double limit = core->opts.missing_limit > 0 ? core->opts.missing_limit : 1.0;

    memset(st, 0, sizeof *st);
    out->nverts = 0;
    out->ntris = 0;
    if (setup_run(core, &r, pts, n, grid_n, 64, st, err) != GDT_OK)
        return err->status;
    if (gdt_ocl_finish(core->ocl, err) != GDT_OK)
        return err->status;
    t1 = gcd_now();
    st->t_upload = t1 - t0;
    if (n == 0) {
        snprintf(st->path, sizeof st->path, "none");
        snprintf(st->path_reason, sizeof st->path_reason, "no points");
        return extract(core, &r, out, err);
    }
    if (gcd_run_buffers(core, &r, err) != GDT_OK || gcd_phase1(core, &r, err) != GDT_OK)
        return err->status;
    {
        double frac = (double)r.nmissing / (double)n;
        int insert = core->opts.path == GDT_CORE_PATH_INSERT ||
                     (core->opts.path == GDT_CORE_PATH_AUTO && frac > limit);
        snprintf(st->path, sizeof st->path, "%s", insert ? "insert" : "gcd");
        if (core->opts.path != GDT_CORE_PATH_AUTO)
            snprintf(st->path_reason, sizeof st->path_reason, "forced by the caller");
        else
            snprintf(st->path_reason, sizeof st->path_reason,
                     "%.1f%% of the points share a texel or lie on the grid border (limit %.0f%%)",
                     100.0 * frac, 100.0 * limit);
        r.all_missing = insert;
    }
    if (!r.all_missing) {
        if (gcd_voronoi_from_seeds(core, &r, err) != GDT_OK || gdt_ocl_finish(core->ocl, err) != GDT_OK)
            return err->status;
        st->t_phase1 = gcd_now() - t1;
        t1 = gcd_now();
        if (gcd_phase2(core, &r, err) != GDT_OK || gdt_ocl_finish(core->ocl, err) != GDT_OK)
            return err->status;
        st->t_phase2 = gcd_now() - t1;
        if (core->opts.check_phases && check_phase(core, &r, "phase 2", 1, err) != GDT_OK)
            return err->status;
        t1 = gcd_now();
        if (gcd_phase3(core, &r, err) != GDT_OK || gdt_ocl_finish(core->ocl, err) != GDT_OK)
            return err->status;
        st->t_phase3 = gcd_now() - t1;
        if (core->opts.check_phases && check_phase(core, &r, "phase 3", 1, err) != GDT_OK)
            return err->status;
        t1 = gcd_now();
        if (gcd_phase4(core, &r, 0, err) != GDT_OK || gdt_ocl_finish(core->ocl, err) != GDT_OK)
            return err->status;
        st->t_phase4 = gcd_now() - t1;
        if (core->opts.check_phases && check_phase(core, &r, "phase 4", 1, err) != GDT_OK)
            return err->status;
    } else {
        st->t_phase1 = gcd_now() - t1;
        t1 = gcd_now();
        if (fake_fan(core, &r, err) != GDT_OK || gcd_phase4(core, &r, 1, err) != GDT_OK ||
            gdt_ocl_finish(core->ocl, err) != GDT_OK)
            return err->status;
        st->t_phase4 = gcd_now() - t1;
        /* the flips between insertion rounds do not maintain vt */
        if (core->opts.check_phases && check_phase(core, &r, "phase 4", 0, err) != GDT_OK)
            return err->status;
    }
    t1 = gcd_now();
    /* the insertion path appends in insertion order: sort for locality */
    r.sort_tris = r.all_missing;
    if (gcd_phase5(core, &r, err) != GDT_OK || gdt_ocl_finish(core->ocl, err) != GDT_OK)
        return err->status;
    st->t_phase5 = gcd_now() - t1;
    t1 = gcd_now();
    if (extract(core, &r, out, err) != GDT_OK)
        return err->status;
    st->t_download = gcd_now() - t1;
    st->triangles = out->ntris;
    st->t_total = gcd_now() - t0;
    return GDT_OK;
}

gdt_status gcd_test_scan(gdt_core *c, const uint32_t *in, size_t n, uint32_t *out,
                         uint32_t *total, size_t *nflagged, uint32_t *flagged, gdt_error *err)
{
    size_t cnt = 0;
    if (gcd_buf_need(c, &c->d_aux3, 4 * n + 4, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux3.b, 0, in, 4 * n, err) != GDT_OK ||
        gcd_scan(c, &c->d_aux3, n, total, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_aux3.b, 0, out, 4 * n, err) != GDT_OK)
        return err->status;
    /* compaction of the nonzero entries */
    if (gcd_buf_need(c, &c->d_aux3, 4 * n + 4, err) != GDT_OK)
        return err->status;
    {
        uint32_t *flags = malloc(4 * (n ? n : 1));
        if (flags == NULL)
            return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        for (size_t i = 0; i < n; i++)
            flags[i] = in[i] != 0;
        gdt_status st = gdt_ocl_write(c->ocl, c->d_aux3.b, 0, flags, 4 * n, err);
        free(flags);
        if (st != GDT_OK)
            return st;
    }
    if (gcd_compact(c, &c->d_aux3, n, &c->d_aux2, &cnt, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_aux2.b, 0, flagged, 4 * cnt, err) != GDT_OK)
        return err->status;
    *nflagged = cnt;
    return GDT_OK;
}

void gcd_test_set_flip_blocks(gdt_core *c, size_t blocks, size_t min_block, size_t queue)
{
    /* Block-local flipping needs few long work-items: CPU devices only.
     * More blocks than compute units balance the load; the blocks stay
     * large so that few slots lie next to another block. */
    if (blocks == SIZE_MAX)
        blocks = gdt_ocl_is_cpu(c->ocl) ? 32 * (size_t)gdt_ocl_compute_units(c->ocl) : 0;
    c->flip_blocks = blocks;
    c->flip_min_block = min_block > 0 ? min_block : 4096;
    c->flip_queue = queue >= 8 ? queue : 65536;
}

gdt_status gcd_test_radix(gdt_core *c, uint32_t *keys, uint32_t *vals, size_t n, unsigned bits,
                          gdt_error *err)
{
    if (gcd_buf_need(c, &c->d_mkeys, 4 * n + 4, err) != GDT_OK ||
        gcd_buf_need(c, &c->d_aux3, 4 * n + 4, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_mkeys.b, 0, keys, 4 * n, err) != GDT_OK ||
        gdt_ocl_write(c->ocl, c->d_aux3.b, 0, vals, 4 * n, err) != GDT_OK ||
        gcd_radix_sort(c, &c->d_mkeys, &c->d_aux3, n, bits, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_mkeys.b, 0, keys, 4 * n, err) != GDT_OK ||
        gdt_ocl_read(c->ocl, c->d_aux3.b, 0, vals, 4 * n, err) != GDT_OK)
        return err->status;
    return GDT_OK;
}
