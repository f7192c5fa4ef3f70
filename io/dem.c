/* dem.c — the streaming DEM writer (gdt_dem.h): the block cache, its
 * scratch file, and the ordered hand-over of every block to the GDAL side
 * (private/dem_gdal.h).
 *
 * Invariants:
 *   - a block is in at most one cache slot; slot_block[s] is its index or
 *     -1, and the hash map block -> slot holds exactly the occupied slots;
 *   - spilled[b] is set once block b has been written to the scratch file;
 *     the file then holds its latest contents whenever it is not cached
 *     (a cached block is written back whole when evicted);
 *   - a cell is 0 (never written) or the float32 bits of its value plus one
 *     (the one NaN pattern 0xffffffff becomes the quiet NaN 0x7fc00000);
 *   - when the whole raster fits the budget (every block would fit the
 *     cache) it is one row-major array, raster, instead of the cache; the
 *     build decodes it in place and GDAL's in-memory intermediate takes it
 *     as its band, with no copy. */
#define _GNU_SOURCE 1 /* mkstemp, MADV_POPULATE_WRITE */
#include "gdt_dem.h"

#include <errno.h>
#include <fcntl.h>
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "gdt_outfile.h"
#include "private/dem_gdal.h"
#include "private/plugin.h"

#define BLOCK_CELLS ((size_t)GDT_DEM_BLOCK * GDT_DEM_BLOCK)
#define BLOCK_BYTES (BLOCK_CELLS * sizeof(uint32_t))
#define DEFAULT_BUDGET ((uint64_t)256 << 20)

struct gdt_dem {
    const gdt_dem_gdal_fns *gdal; /* the GDAL plug-in's entry points */
    gdt_dem_geo geo;
    char *path, *tmp_path, *scratch_dir, *preview, *preview_tmp, *wkt, *tiles_path;
    double nodata;
    int epsg;
    uint64_t mem_budget;
    int64_t bcols, brows, nblocks;
    size_t nslots, used;
    uint32_t *raster;    /* the whole raster fits the budget: ncols x nrows cells,
                          * row-major, and no block cache (cells NULL) */
    void *raster_map;    /* the mapping raster lies in, raster_len bytes */
    size_t raster_len;
    pthread_t populate_tid; /* the raster's pages being populated (populating) */
    int populating;
    int populate_stop; /* __atomic accesses */
    uint32_t *cells;     /* nslots * BLOCK_CELLS */
    int64_t *slot_block; /* block in each slot, -1 free */
    uint64_t *slot_tick; /* last use (LRU) */
    int64_t *hkey;       /* hash map block -> slot, open addressing; -1 empty */
    size_t *hval;
    size_t hmask;
    uint8_t *spilled; /* bitmap of blocks in the scratch file */
    int fd;           /* scratch file, -1 until the first spill */
    uint64_t tick;
    int64_t last_block; /* the slot of the last block used, a fast path */
    size_t last_slot;
    int cells_aligned; /* cells is page-aligned memory of its own (posix_memalign) */
    uint32_t *xfer;    /* one block read back during gdt_dem_build */
    gdt_dem_stats stats;
    int built;             /* gdt_dem_build succeeded: the temporaries are complete */
    gdt_status preview_st; /* the preview's failure in gdt_dem_build, told by the commit */
    gdt_error preview_err;
};

static char *dup_str(const char *s)
{
    return s != NULL ? strdup(s) : NULL;
}

/* path followed by suffix, where a "%ld" in suffix becomes v. */
static char *with_suffix(const char *path, const char *suffix, long v)
{
    size_t len = strlen(path) + strlen(suffix) + 24;
    char *p = malloc(len);
    const char *pct = strstr(suffix, "%ld");
    if (p != NULL) {
        if (pct == NULL)
            snprintf(p, len, "%s%s", path, suffix);
        else
            snprintf(p, len, "%s%.*s%ld%s", path, (int)(pct - suffix), suffix, v, pct + 3);
    }
    return p;
}

static size_t hash_of(const gdt_dem *w, int64_t b)
{
    return (size_t)(((uint64_t)b * UINT64_C(0x9E3779B97F4A7C15)) >> 17) & w->hmask;
}

static int map_find(const gdt_dem *w, int64_t b, size_t *slot)
{
    for (size_t i = hash_of(w, b);; i = (i + 1) & w->hmask) {
        if (w->hkey[i] == -1)
            return 0;
        if (w->hkey[i] == b) {
            *slot = w->hval[i];
            return 1;
        }
    }
}

static void map_insert(gdt_dem *w, int64_t b, size_t slot)
{
    size_t i = hash_of(w, b);
    while (w->hkey[i] != -1)
        i = (i + 1) & w->hmask;
    w->hkey[i] = b;
    w->hval[i] = slot;
}

/* Linear probing with backward-shift deletion (no tombstones). */
static void map_remove(gdt_dem *w, int64_t b)
{
    size_t i = hash_of(w, b);
    while (w->hkey[i] != b)
        i = (i + 1) & w->hmask;
    for (size_t j = i;;) {
        size_t home;
        j = (j + 1) & w->hmask;
        if (w->hkey[j] == -1)
            break;
        home = hash_of(w, w->hkey[j]);
        /* move j back to i unless its home lies cyclically in (i, j] */
        if ((j > i && (home <= i || home > j)) || (j < i && home <= i && home > j)) {
            w->hkey[i] = w->hkey[j];
            w->hval[i] = w->hval[j];
            i = j;
        }
    }
    w->hkey[i] = -1;
}

static gdt_status open_scratch(gdt_dem *w, gdt_error *err)
{
    char *tmpl = with_suffix(w->scratch_dir, "/gdt-dem-blocks-%ld-XXXXXX", (long)getpid());
    if (tmpl == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->fd = mkstemp(tmpl);
    if (w->fd < 0) {
        gdt_status st =
            gdt_error_set(err, GDT_EIO, 4650, "%s: cannot create a scratch file in %s: %s", w->path,
                          w->scratch_dir, strerror(errno));
        free(tmpl);
        return st;
    }
    unlink(tmpl); /* anonymous from now on: gone with the descriptor */
    free(tmpl);
    return GDT_OK;
}

static gdt_status scratch_io(gdt_dem *w, int writing, int64_t b, uint32_t *buf, gdt_error *err)
{
    off_t off = (off_t)b * (off_t)BLOCK_BYTES;
    size_t done = 0;
    while (done < BLOCK_BYTES) {
        ssize_t n =
            writing ? pwrite(w->fd, (const char *)buf + done, BLOCK_BYTES - done, off + (off_t)done)
                    : pread(w->fd, (char *)buf + done, BLOCK_BYTES - done, off + (off_t)done);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return gdt_error_set(err, GDT_EIO, 4651,
                                 "%s: %s of the DEM scratch file in %s "
                                 "failed: %s",
                                 w->path, writing ? "write" : "read", w->scratch_dir,
                                 n < 0 ? strerror(errno) : "unexpected end");
        done += (size_t)n;
    }
    return GDT_OK;
}

/* The block cache: every slot is written whole before it is read (zeroed
 * or reloaded), so it is faulted in once per slot; 2 MiB pages where the
 * kernel offers them on request (transparent huge pages in "madvise"
 * mode) make that 512 times fewer faults.  Released with free(). */
static uint32_t *cells_alloc(size_t bytes, int *aligned)
{
    enum { HUGE = 2u << 20 };
    void *p = NULL;
    *aligned = 0;
    if (bytes < HUGE)
        return malloc(bytes);
    if (posix_memalign(&p, HUGE, bytes) != 0)
        return NULL;
    *aligned = 1;
#ifdef MADV_HUGEPAGE
    (void)madvise(p, bytes, MADV_HUGEPAGE); /* advice only: no huge pages is fine */
#endif
    return p;
}

/* bytes of zeros (pages zeroed by the kernel as they are first touched,
 * so cells never written cost nothing) in a private mapping, from a 2 MiB
 * boundary and advised onto huge pages where the system gives them: a
 * face's cells are a few rows of a large array, and with 4 KiB pages
 * nearly every row is a TLB miss.  NULL when it cannot be had. */
static uint32_t *raster_alloc(gdt_dem *w, size_t bytes)
{
    const size_t huge = (size_t)2 << 20;
    uintptr_t a;
    void *p;
    if (bytes > SIZE_MAX - huge)
        return NULL;
    p = mmap(NULL, bytes + huge, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED)
        return NULL;
    w->raster_map = p;
    w->raster_len = bytes + huge;
    a = ((uintptr_t)p + huge - 1) & ~(uintptr_t)(huge - 1);
#ifdef MADV_HUGEPAGE
    (void)madvise((void *)a, bytes, MADV_HUGEPAGE); /* advice only */
#endif
    return (uint32_t *)a;
}

/* The raster's pages made present and writable ahead of the rasteriser,
 * 2 MiB at a time, on a thread of its own as soon as the raster is mapped:
 * the first touch of fresh memory (the kernel zeroing it, a virtual
 * machine's host backing it: 0.3 CPU-s for the 40 MB of a 10M-point cloud
 * at its spacing here) then falls in the partly idle start of the tile
 * stage instead of the middle of the rasterising.  An ordinary thread, not
 * an idle-class one: this one holds the address space's lock while it
 * faults, and an idle-class thread that other programs keep off the CPU
 * would hold it indefinitely.  MADV_POPULATE_WRITE never changes a page's
 * contents, so the rasteriser may write cells meanwhile; where the kernel
 * lacks it (before Linux 5.14) the first call fails and the thread ends.
 * Advice only: nothing depends on it having run. */
static void *populate_main(void *arg)
{
    gdt_dem *w = arg;
#ifdef MADV_POPULATE_WRITE
    const size_t step = (size_t)2 << 20;
    const size_t len = (size_t)w->geo.ncols * (size_t)w->geo.nrows * sizeof *w->raster;
    for (size_t at = 0; at < len && !__atomic_load_n(&w->populate_stop, __ATOMIC_RELAXED);
         at += step)
        if (madvise((char *)w->raster + at, len - at < step ? len - at : step,
                    MADV_POPULATE_WRITE) != 0)
            break;
#else
    (void)w;
#endif
    return NULL;
}

static void populate_start(gdt_dem *w)
{
#ifdef MADV_POPULATE_WRITE
    __atomic_store_n(&w->populate_stop, 0, __ATOMIC_RELAXED);
    w->populating = pthread_create(&w->populate_tid, NULL, populate_main, w) == 0;
#else
    (void)w;
#endif
}

/* Stops the populating thread and waits for it: before the raster is read
 * whole or unmapped. */
static void populate_join(gdt_dem *w)
{
    if (!w->populating)
        return;
    __atomic_store_n(&w->populate_stop, 1, __ATOMIC_RELAXED);
    pthread_join(w->populate_tid, NULL);
    w->populating = 0;
}

void gdt_dem_preload(void)
{
    void *sym;
    gdt_error e;
    gdt_error_clear(&e);
    (void)gdt_plugin_symbol(GDT_DEM_GDAL_MODULE, GDT_DEM_GDAL_SYMBOL, "the DEM writer (GDAL)", &sym,
                            &e);
}

gdt_status gdt_dem_create(gdt_dem **out, const gdt_dem_geo *geo, const char *path,
                          const gdt_dem_opts *opts, gdt_error *err)
{
    gdt_dem *w;
    const gdt_dem_gdal_fns *gdal;
    uint64_t budget = opts->mem_budget != 0 ? opts->mem_budget : DEFAULT_BUDGET;
    size_t hcap = 4;

    *out = NULL;
    {
        /* the plug-in first: without it the writer fails before it
         * allocates anything (the run keeps its job for a rerun) */
        void *sym;
        gdt_status st = gdt_plugin_symbol(GDT_DEM_GDAL_MODULE, GDT_DEM_GDAL_SYMBOL,
                                          "the DEM writer (GDAL)", &sym, err);
        if (st != GDT_OK)
            return st;
        gdal = sym;
    }
    if (!(geo->ncols >= 1 && geo->nrows >= 1 && geo->ncols <= GDT_DEM_MAX_SIDE &&
          geo->nrows <= GDT_DEM_MAX_SIDE &&
          (double)geo->ncols * (double)geo->nrows <= (double)GDT_DEM_MAX_CELLS &&
          geo->res_x > 0.0 && geo->res_y > 0.0 && isfinite(geo->west) && isfinite(geo->north) &&
          isfinite(geo->res_x) && isfinite(geo->res_y)))
        return gdt_error_set(err, GDT_EUSAGE, 2611,
                             "%s: a DEM of %lld x %lld cells of %g x %g at (%g, %g) cannot be "
                             "written",
                             path, (long long)geo->ncols, (long long)geo->nrows, geo->res_x,
                             geo->res_y, geo->west, geo->north);
    if (!isfinite(opts->nodata) || fabs(opts->nodata) > FLT_MAX ||
        (double)(float)opts->nodata != opts->nodata)
        return gdt_error_set(err, GDT_EUSAGE, 2611,
                             "%s: the nodata value %.17g is not a finite float32", path,
                             opts->nodata);
    w = calloc(1, sizeof *w);
    if (w == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    w->gdal = gdal;
    w->fd = -1;
    w->last_block = -1;
    w->geo = *geo;
    w->nodata = opts->nodata;
    w->epsg = opts->epsg;
    w->mem_budget = budget;
    w->bcols = (geo->ncols + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;
    w->brows = (geo->nrows + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;
    w->nblocks = w->bcols * w->brows;
    w->nslots = (size_t)(budget / BLOCK_BYTES);
    if (w->nslots < 2)
        w->nslots = 2;
    if ((int64_t)w->nslots > w->nblocks)
        w->nslots = (size_t)w->nblocks;
    while (hcap < 2 * w->nslots)
        hcap *= 2;
    w->hmask = hcap - 1;
    w->path = dup_str(path);
    w->tmp_path = gdt_outfile_temp(path);
    w->scratch_dir = opts->scratch_dir != NULL ? dup_str(opts->scratch_dir) : gdt_outfile_dir(path);
    w->wkt = dup_str(opts->crs_wkt);
    if (opts->preview != NULL) {
        w->preview = dup_str(opts->preview);
        w->preview_tmp = gdt_outfile_temp(opts->preview);
    }
    if ((int64_t)w->nslots >= w->nblocks) {
        w->raster = raster_alloc(w, (size_t)geo->ncols * (size_t)geo->nrows * sizeof *w->raster);
        if (w->raster != NULL)
            populate_start(w);
    } else {
        w->cells = cells_alloc(w->nslots * BLOCK_BYTES, &w->cells_aligned);
        w->slot_block = malloc(w->nslots * sizeof *w->slot_block);
        w->slot_tick = calloc(w->nslots, sizeof *w->slot_tick);
        w->hkey = malloc(hcap * sizeof *w->hkey);
        w->hval = malloc(hcap * sizeof *w->hval);
        w->spilled = calloc((size_t)(w->nblocks + 7) / 8, 1);
    }
    if (w->path == NULL || w->tmp_path == NULL || w->scratch_dir == NULL ||
        (opts->crs_wkt != NULL && w->wkt == NULL) ||
        (opts->preview != NULL && (w->preview == NULL || w->preview_tmp == NULL)) ||
        (w->raster == NULL &&
         (w->cells == NULL || w->slot_block == NULL || w->slot_tick == NULL ||
          w->hkey == NULL || w->hval == NULL || w->spilled == NULL))) {
        gdt_dem_abort(w);
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory (DEM block cache of "
                             "%zu blocks)",
                             w->nslots);
    }
    for (size_t s = 0; w->raster == NULL && s < w->nslots; s++)
        w->slot_block[s] = -1;
    for (size_t i = 0; w->raster == NULL && i < hcap; i++)
        w->hkey[i] = -1;
    w->stats.blocks = (uint64_t)w->nblocks;
    w->stats.cache_blocks = w->nslots;
    *out = w;
    return GDT_OK;
}

static int is_spilled(const gdt_dem *w, int64_t b)
{
    return (w->spilled[b >> 3] >> (b & 7)) & 1;
}

/* The slot of block b, loading it (and evicting the least recently used
 * block) when it is not cached. */
static gdt_status slot_of(gdt_dem *w, int64_t b, size_t *slot, gdt_error *err)
{
    size_t s;
    gdt_status st;

    if (b == w->last_block) {
        *slot = w->last_slot;
        w->slot_tick[*slot] = ++w->tick;
        return GDT_OK;
    }
    if (!map_find(w, b, &s)) {
        if (w->used < w->nslots) {
            s = w->used++;
        } else {
            int64_t old;
            s = 0;
            for (size_t k = 1; k < w->nslots; k++)
                if (w->slot_tick[k] < w->slot_tick[s])
                    s = k;
            old = w->slot_block[s];
            if (w->fd < 0 && (st = open_scratch(w, err)) != GDT_OK)
                return st;
            st = scratch_io(w, 1, old, w->cells + s * BLOCK_CELLS, err);
            if (st != GDT_OK)
                return st;
            w->spilled[old >> 3] |= (uint8_t)(1u << (old & 7));
            map_remove(w, old);
            if (old == w->last_block)
                w->last_block = -1;
            w->stats.spills++;
        }
        if (is_spilled(w, b)) {
            st = scratch_io(w, 0, b, w->cells + s * BLOCK_CELLS, err);
            if (st != GDT_OK)
                return st;
            w->stats.reloads++;
        } else {
            memset(w->cells + s * BLOCK_CELLS, 0, BLOCK_BYTES);
        }
        w->slot_block[s] = b;
        map_insert(w, b, s);
    }
    w->slot_tick[s] = ++w->tick;
    w->last_block = b;
    w->last_slot = s;
    *slot = s;
    return GDT_OK;
}

/* Cells (row, col .. col + n - 1), at cell[0 .. n), take z (encoded: the
 * invariants above); a cell written before is an error. */
static gdt_status put_cells(gdt_dem *w, uint32_t *cell, int64_t row, int64_t col, int64_t n,
                            const float *z, gdt_error *err)
{
    for (int64_t k = 0; k < n; k++) {
        uint32_t bits;
        memcpy(&bits, &z[k], sizeof bits);
        if (bits == UINT32_MAX)
            bits = UINT32_C(0x7fc00000);
        if (cell[k] != 0)
            return gdt_error_set(err, GDT_EINTERNAL, 7662,
                                 "%s: DEM cell (%lld, %lld) given a value twice", w->path,
                                 (long long)row, (long long)(col + k));
        cell[k] = bits + 1;
    }
    w->stats.cells_written += (uint64_t)n;
    return GDT_OK;
}

gdt_status gdt_dem_put(gdt_dem *w, int64_t row, int64_t col, int64_t n, const float *z,
                       gdt_error *err)
{
    if (n <= 0)
        return GDT_OK;
    if (row < 0 || row >= w->geo.nrows || col < 0 || n > w->geo.ncols - col)
        return gdt_error_set(err, GDT_EINTERNAL, 7661,
                             "%s: cells (%lld, %lld..%lld) outside the DEM of %lld x %lld", w->path,
                             (long long)row, (long long)col, (long long)(col + n - 1),
                             (long long)w->geo.nrows, (long long)w->geo.ncols);
    if (w->raster != NULL)
        return put_cells(w, w->raster + (size_t)row * (size_t)w->geo.ncols + (size_t)col, row, col,
                         n, z, err);
    while (n > 0) {
        int64_t b = (row / GDT_DEM_BLOCK) * w->bcols + col / GDT_DEM_BLOCK;
        int64_t in = col % GDT_DEM_BLOCK, m = GDT_DEM_BLOCK - in < n ? GDT_DEM_BLOCK - in : n;
        size_t s;
        uint32_t *cell;
        gdt_status st = slot_of(w, b, &s, err);
        if (st != GDT_OK)
            return st;
        cell =
            w->cells + s * BLOCK_CELLS + (size_t)(row % GDT_DEM_BLOCK) * GDT_DEM_BLOCK + (size_t)in;
        st = put_cells(w, cell, row, col, m, z, err);
        if (st != GDT_OK)
            return st;
        z += m;
        col += m;
        n -= m;
    }
    return GDT_OK;
}

gdt_status gdt_dem_sink(void *ctx, int64_t row, int64_t col, int64_t n, const float *z,
                        gdt_error *err)
{
    return gdt_dem_put((gdt_dem *)ctx, row, col, n, z, err);
}

gdt_dem_stats gdt_dem_get_stats(const gdt_dem *w)
{
    return w->stats;
}

/* gdt_dem_block_fn: block (bx, by) from the cache or the scratch file. */
static gdt_status next_block(void *ctx, int64_t bx, int64_t by, float *buf, int *empty,
                             gdt_error *err)
{
    gdt_dem *w = ctx;
    int64_t b = by * w->bcols + bx;
    const uint32_t *src;
    size_t s = 0;
    int any = 0, cached = 0;
    float nd = (float)w->nodata;

    if (map_find(w, b, &s)) {
        src = w->cells + s * BLOCK_CELLS;
        cached = 1;
    } else if (is_spilled(w, b)) {
        gdt_status st = scratch_io(w, 0, b, w->xfer, err);
        if (st != GDT_OK)
            return st;
        src = w->xfer;
    } else {
        *empty = 1;
        return GDT_OK;
    }
    for (size_t i = 0; i < BLOCK_CELLS; i++) {
        if (src[i] == 0) {
            buf[i] = nd;
        } else {
            uint32_t bits = src[i] - 1;
            memcpy(&buf[i], &bits, sizeof bits);
            any = 1;
        }
    }
    *empty = !any;
    if (any)
        w->stats.blocks_written++;
#ifdef MADV_DONTNEED
    /* each block is asked for once: its memory goes back now, so that an
     * in-memory intermediate grows as the cache shrinks */
    if (cached && w->cells_aligned)
        (void)madvise(w->cells + s * BLOCK_CELLS, BLOCK_BYTES, MADV_DONTNEED);
#endif
    return GDT_OK;
}

/* The raster decoded in place to float32 bits, nodata where never
 * written; counts the blocks with a value as the cache's build does.
 * returns: GDT_OK; GDT_EINTERNAL 7001. */
static gdt_status decode_raster(gdt_dem *w, gdt_error *err)
{
    const size_t ncols = (size_t)w->geo.ncols;
    float nd = (float)w->nodata;
    uint32_t nd_bits;
    unsigned char *any = calloc((size_t)w->bcols, 1);

    if (any == NULL)
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
    memcpy(&nd_bits, &nd, sizeof nd_bits);
    for (int64_t r = 0; r < w->geo.nrows; r++) {
        uint32_t *row = w->raster + (size_t)r * ncols;
        for (size_t c = 0; c < ncols; c++) {
            if (row[c] == 0) {
                row[c] = nd_bits;
            } else {
                row[c] -= 1;
                any[c / GDT_DEM_BLOCK] = 1;
            }
        }
        if (r % GDT_DEM_BLOCK == GDT_DEM_BLOCK - 1 || r == w->geo.nrows - 1) {
            for (int64_t b = 0; b < w->bcols; b++)
                w->stats.blocks_written += any[b];
            memset(any, 0, (size_t)w->bcols);
        }
    }
    free(any);
    return GDT_OK;
}

static void free_cache(gdt_dem *w)
{
    populate_join(w);
    if (w->raster_map != NULL)
        munmap(w->raster_map, w->raster_len);
    w->raster_map = NULL;
    w->raster = NULL;
    free(w->cells);
    free(w->slot_block);
    free(w->slot_tick);
    free(w->hkey);
    free(w->hval);
    free(w->spilled);
    free(w->xfer);
    w->cells = NULL;
    w->slot_block = NULL;
    w->slot_tick = NULL;
    w->hkey = NULL;
    w->hval = NULL;
    w->spilled = NULL;
    w->xfer = NULL;
    if (w->fd >= 0)
        close(w->fd);
    w->fd = -1;
}

static void remove_tiles(gdt_dem *w)
{
    if (w->tiles_path != NULL)
        unlink(w->tiles_path);
    free(w->tiles_path);
    w->tiles_path = NULL;
}

/* The directory of path synced; a failure there is not an error (the file
 * is complete at its path; only the name's durability is at stake). */
static void sync_dir_of(const char *path)
{
    char *d = gdt_outfile_dir(path);
    if (d != NULL)
        (void)gdt_outfile_sync_dir(d);
    free(d);
}

/* Renames tmp over path after checking path is still absent or a regular
 * file. */
static gdt_status publish(const char *tmp, const char *path, gdt_error *err)
{
    gdt_status st = gdt_outfile_check(path, err);
    if (st != GDT_OK)
        return st;
    if (rename(tmp, path) != 0)
        return gdt_error_set(err, GDT_EIO, 4653, "%s: cannot rename %s to it: %s", path, tmp,
                             strerror(errno));
    sync_dir_of(path);
    return GDT_OK;
}

gdt_status gdt_dem_build(gdt_dem *w, gdt_dem_stats *stats, gdt_error *err)
{
    gdt_status st;
    uint64_t gdal_cache = w->mem_budget / 2;
    int fd;

    /* The intermediate raster in memory when the cache holds every block
     * (it never spilled): it grows as the cache gives its blocks back, by
     * a third more for the overviews; else a GeoTIFF in the scratch
     * directory. */
    const int in_memory = w->raster != NULL;
    void *mem_ds = NULL;

    if ((w->cells == NULL && w->raster == NULL) || w->built)
        return gdt_error_set(err, GDT_EINTERNAL, 7664,
                             "%s: the DEM was built (or failed to build) already", w->path);
    populate_join(w); /* every cell is read from here on */
    w->xfer = malloc(BLOCK_BYTES);
    if (w->xfer == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    if (!in_memory) {
        w->tiles_path = with_suffix(w->scratch_dir, "/gdt-dem-tiles-%ld-XXXXXX", (long)getpid());
        if (w->tiles_path == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto done;
        }
        fd = mkstemp(w->tiles_path);
        if (fd < 0) {
            st = gdt_error_set(err, GDT_EIO, 4650, "%s: cannot create a scratch file in %s: %s",
                               w->path, w->scratch_dir, strerror(errno));
            free(w->tiles_path);
            w->tiles_path = NULL;
            goto done;
        }
        close(fd);
    }
    if (in_memory && (st = decode_raster(w, err)) != GDT_OK)
        goto done;
    st = w->gdal->tiles(&w->geo, w->nodata, w->epsg, w->wkt, w->tiles_path, (float *)w->raster,
                        gdal_cache, next_block, w, &mem_ds, err);
    if (!in_memory)
        free_cache(w); /* its blocks are in the intermediate file */
    if (st == GDT_OK)
        st = w->gdal->cog(w->tiles_path, mem_ds, w->tmp_path, w->path, gdal_cache, err);
    else
        w->gdal->discard(mem_ds);
    free_cache(w); /* the raster outlives the in-memory intermediate, its band */
    remove_tiles(w);
    /* the preview from the complete temporary; its failure alone is told by
     * the commit, after the DEM is in place */
    if (st == GDT_OK && w->preview != NULL) {
        gdt_error_clear(&w->preview_err);
        w->preview_st =
            w->gdal->preview(w->tmp_path, w->preview_tmp, w->preview, gdal_cache, &w->preview_err);
    }
    w->built = st == GDT_OK;
done:
    if (stats != NULL)
        *stats = w->stats;
    return st;
}

gdt_status gdt_dem_commit(gdt_dem *w, gdt_error *err)
{
    gdt_status st = w->built
                        ? GDT_OK
                        : gdt_error_set(err, GDT_EINTERNAL, 7664,
                                        "%s: the DEM is committed before it is built", w->path);
    if (st == GDT_OK)
        st = publish(w->tmp_path, w->path, err);
    if (st == GDT_OK && w->preview != NULL) {
        if (w->preview_st != GDT_OK) {
            *err = w->preview_err;
            st = w->preview_st;
        } else {
            st = publish(w->preview_tmp, w->preview, err);
        }
    }
    gdt_dem_abort(w);
    return st;
}

gdt_status gdt_dem_finish(gdt_dem *w, gdt_dem_stats *stats, gdt_error *err)
{
    gdt_status st = gdt_dem_build(w, stats, err);
    if (st != GDT_OK) {
        gdt_dem_abort(w);
        return st;
    }
    return gdt_dem_commit(w, err);
}

void gdt_dem_abort(gdt_dem *w)
{
    if (w == NULL)
        return;
    free_cache(w);
    remove_tiles(w);
    if (w->tmp_path != NULL) {
        char *ovr = with_suffix(w->tmp_path, ".ovr.tmp", 0); /* GDAL's overview scratch */
        unlink(w->tmp_path);
        if (ovr != NULL)
            unlink(ovr);
        free(ovr);
    }
    if (w->preview_tmp != NULL)
        unlink(w->preview_tmp);
    free(w->path);
    free(w->tmp_path);
    free(w->scratch_dir);
    free(w->preview);
    free(w->preview_tmp);
    free(w->wkt);
    free(w);
}
