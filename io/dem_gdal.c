/* dem_gdal.c — the GDAL side of the DEM writer (private/dem_gdal.h), on
 * GDAL's C API. */
#include "private/dem_gdal.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_string.h>
#include <gdal.h>
#include <gdal_utils.h>
#include <ogr_srs_api.h>

static pthread_once_t register_once = PTHREAD_ONCE_INIT;

static void register_drivers(void)
{
    GDALAllRegister();
}

/* The state every entry point sets up and restores: GDAL registered, its
 * messages kept quiet, no .aux.xml side files (PAM off: everything the
 * outputs need is in their own tags), the block cache bounded. */
typedef struct gdal_scope {
    GIntBig old_cache;
    char *old_pam;
} gdal_scope;

static void scope_enter(gdal_scope *s, uint64_t gdal_cache)
{
    const char *pam;
    pthread_once(&register_once, register_drivers);
    CPLPushErrorHandler(CPLQuietErrorHandler);
    CPLErrorReset();
    pam = CPLGetThreadLocalConfigOption("GDAL_PAM_ENABLED", NULL);
    s->old_pam = pam != NULL ? strdup(pam) : NULL;
    CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", "NO");
    s->old_cache = GDALGetCacheMax64();
    if (gdal_cache < ((uint64_t)8 << 20))
        gdal_cache = (uint64_t)8 << 20;
    GDALSetCacheMax64((GIntBig)gdal_cache);
}

static void scope_leave(gdal_scope *s)
{
    GDALSetCacheMax64(s->old_cache);
    CPLSetThreadLocalConfigOption("GDAL_PAM_ENABLED", s->old_pam);
    free(s->old_pam);
    CPLPopErrorHandler();
}

static gdt_status gdal_fail(gdt_error *err, const char *path, const char *what)
{
    const char *m = CPLGetLastErrorMsg();
    return gdt_error_set(err, GDT_EIO, 4652, "%s: GDAL could not %s: %s", path, what,
                         m != NULL && m[0] != '\0' ? m : "no message");
}

static gdt_status sync_file(const char *tmp, const char *path, gdt_error *err)
{
    int fd = open(tmp, O_RDONLY | O_CLOEXEC);
    if (fd < 0 || fsync(fd) != 0) {
        int e = errno;
        if (fd >= 0)
            close(fd);
        return gdt_error_set(err, GDT_EIO, 4653, "%s: fsync of %s failed: %s", path, tmp,
                             strerror(e));
    }
    close(fd);
    return GDT_OK;
}

/* Closes ds (written to tmp), which flushes it, then syncs tmp and renames
 * it to path.  what names the step in a GDAL failure. */
static gdt_status close_and_commit(GDALDatasetH ds, const char *tmp, const char *path,
                                   const char *what, gdt_error *err)
{
    CPLErrorReset();
    GDALClose(ds);
    if (CPLGetLastErrorType() >= CE_Failure)
        return gdal_fail(err, path, what);
    return sync_file(tmp, path, err);
}

/* ---- overviews -------------------------------------------------------
 *
 * The intermediate file carries its own overviews, computed here from each
 * full-resolution block as it is written, so that the COG step only
 * compresses them (GDAL's own generation re-reads the raster, writes a
 * compressed scratch file and reads it back: about half of the COG time).
 * Level k (1 .. OVR_MAX_LEVELS) has factor 2^k and ceil(n / 2^k) cells per
 * side; a cell is the mean of the full-resolution cells with a value in
 * its 2^k x 2^k footprint (nodata when there are none), summed in double
 * in a fixed order: first 2 x 2 groups of full-resolution cells, then 2 x 2
 * groups of the level below.  With 2^k dividing the block side every
 * footprint lies inside one block, so a block gives its part of every
 * level at once and memory stays one block.  Levels are added while the
 * previous one is wider than a block; a raster that would need more than
 * OVR_MAX_LEVELS (a side over 512 x 512 cells) gets its overviews from
 * GDAL's averaging instead. */
#define OVR_MAX_LEVELS 9

/* The number of own overview levels of geo, or -1 when GDAL must make them. */
static int own_levels(const gdt_dem_geo *geo)
{
    int64_t side = geo->ncols > geo->nrows ? geo->ncols : geo->nrows;
    int levels = 0;
    while (side > GDT_DEM_BLOCK) {
        side = (side + 1) / 2;
        levels++;
    }
    return levels > OVR_MAX_LEVELS ? -1 : levels;
}

typedef struct ovr_work {
    double *sum[2];
    uint32_t *count[2];
    float *out;
} ovr_work;

/* Writes the part of every overview level that block (bx, by) gives: buf
 * holds its w x h cells (rows stride cells apart), nodata where nd_bits. */
static gdt_status block_overviews(GDALRasterBandH band, int levels, const float *buf, size_t stride,
                                  int w, int h, int64_t bx, int64_t by, uint32_t nd_bits, float nd,
                                  const gdt_dem_geo *geo, ovr_work *o, const char *path,
                                  gdt_error *err)
{
    int pw = w, ph = h; /* the level below: full resolution first */
    for (int k = 1; k <= levels; k++) {
        const int cur = (k - 1) & 1, prev = cur ^ 1, s = GDT_DEM_BLOCK >> k;
        const int cw = (pw + 1) / 2, ch = (ph + 1) / 2;
        int64_t ovw = (geo->ncols + ((int64_t)1 << k) - 1) >> k;
        int64_t ovh = (geo->nrows + ((int64_t)1 << k) - 1) >> k;
        int any = 0;
        GDALRasterBandH ob = GDALGetOverview(band, k - 1);

        for (int j = 0; j < ch; j++)
            for (int i = 0; i < cw; i++) {
                double sum = 0.0;
                uint32_t cnt = 0;
                if (k == 1 && 2 * j + 1 < ph && 2 * i + 1 < pw) {
                    /* a whole 2 x 2 group of the block, without branches: a
                     * cell without a value adds -0.0, which leaves every
                     * sum as it is (also -0.0), so the sum is the loop's
                     * below, bit for bit */
                    const float *q0 = buf + (size_t)(2 * j) * stride + (size_t)(2 * i);
                    const float *q1 = q0 + stride;
                    float v[4];
                    v[0] = q0[0];
                    v[1] = q0[1];
                    v[2] = q1[0];
                    v[3] = q1[1];
                    for (int t = 0; t < 4; t++) {
                        uint32_t bits;
                        memcpy(&bits, &v[t], sizeof bits);
                        sum += bits != nd_bits ? (double)v[t] : -0.0;
                        cnt += bits != nd_bits;
                    }
                    o->sum[cur][(size_t)j * GDT_DEM_BLOCK + (size_t)i] = sum;
                    o->count[cur][(size_t)j * GDT_DEM_BLOCK + (size_t)i] = cnt;
                    o->out[(size_t)j * (size_t)cw + (size_t)i] = cnt > 0 ? (float)(sum / cnt) : nd;
                    any |= cnt > 0;
                    continue;
                }
                for (int dj = 0; dj < 2; dj++)
                    for (int di = 0; di < 2; di++) {
                        int r = 2 * j + dj, c = 2 * i + di;
                        if (r >= ph || c >= pw)
                            continue;
                        if (k == 1) {
                            float v = buf[(size_t)r * stride + (size_t)c];
                            uint32_t bits;
                            memcpy(&bits, &v, sizeof bits);
                            if (bits != nd_bits) {
                                sum += (double)v;
                                cnt++;
                            }
                        } else {
                            sum += o->sum[prev][(size_t)r * GDT_DEM_BLOCK + (size_t)c];
                            cnt += o->count[prev][(size_t)r * GDT_DEM_BLOCK + (size_t)c];
                        }
                    }
                o->sum[cur][(size_t)j * GDT_DEM_BLOCK + (size_t)i] = sum;
                o->count[cur][(size_t)j * GDT_DEM_BLOCK + (size_t)i] = cnt;
                o->out[(size_t)j * (size_t)cw + (size_t)i] = cnt > 0 ? (float)(sum / cnt) : nd;
                any |= cnt > 0;
            }
        if (ob == NULL)
            return gdal_fail(err, path, "find an overview of the intermediate GeoTIFF");
        if (any && bx * s < ovw && by * s < ovh &&
            GDALRasterIO(ob, GF_Write, (int)(bx * s), (int)(by * s), cw, ch, o->out, cw, ch,
                         GDT_Float32, 0, 0) != CE_None)
            return gdal_fail(err, path, "write an overview block of the intermediate GeoTIFF");
        pw = cw;
        ph = ch;
    }
    return GDT_OK;
}

gdt_status gdt_dem_gdal_tiles(const gdt_dem_geo *geo, double nodata, int epsg, const char *wkt,
                              const char *tiles_path, float *raster, uint64_t gdal_cache,
                              gdt_dem_block_fn fn, void *ctx, void **mem_ds, gdt_error *err)
{
    const int in_memory = tiles_path == NULL;
    const char *name = in_memory ? "the in-memory DEM" : tiles_path;
    gdal_scope scope;
    GDALDriverH drv;
    GDALDatasetH ds = NULL;
    GDALRasterBandH band;
    OGRSpatialReferenceH srs = NULL;
    char **co = NULL;
    float *buf = NULL, ndf;
    double gt[6];
    gdt_status st = GDT_OK;
    int levels = 0;
    uint32_t nd_bits;
    ovr_work ow = {{NULL, NULL}, {NULL, NULL}, NULL};
    int64_t bcols = (geo->ncols + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;
    int64_t brows = (geo->nrows + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;

    scope_enter(&scope, gdal_cache);
    if (epsg > 0 || wkt != NULL) {
        srs = OSRNewSpatialReference(NULL);
        char *wp = (char *)wkt; /* OSRImportFromWkt reads it, never writes */
        if (srs == NULL ||
            (epsg > 0 ? OSRImportFromEPSG(srs, epsg) : OSRImportFromWkt(srs, &wp)) != OGRERR_NONE) {
            const char *m = CPLGetLastErrorMsg();
            if (epsg > 0)
                st = gdt_error_set(err, GDT_EINPUT, 3650,
                                   "the input's CRS EPSG:%d is unknown to GDAL/PROJ: %s", epsg,
                                   m != NULL && m[0] != '\0' ? m : "no message");
            else
                st = gdt_error_set(err, GDT_EINPUT, 3650,
                                   "the input's CRS (WKT) is not understood by GDAL/PROJ: %s",
                                   m != NULL && m[0] != '\0' ? m : "no message");
            goto done;
        }
    }
    if (mem_ds != NULL)
        *mem_ds = NULL;
    drv = GDALGetDriverByName(in_memory ? "MEM" : "GTiff");
    if (drv == NULL) {
        st = gdal_fail(err, name, in_memory ? "find its MEM driver" : "find its GTiff driver");
        goto done;
    }
    if (!in_memory) {
        co = CSLSetNameValue(co, "TILED", "YES");
        co = CSLSetNameValue(co, "BLOCKXSIZE", "512");
        co = CSLSetNameValue(co, "BLOCKYSIZE", "512");
        /* uncompressed: it is read once, by the COG step, and compressing
         * it too cost as much as the final compression (empty blocks stay
         * sparse) */
        co = CSLSetNameValue(co, "COMPRESS", "NONE");
        co = CSLSetNameValue(co, "BIGTIFF", "YES");
        co = CSLSetNameValue(co, "SPARSE_OK", "TRUE");
    }
    if (in_memory && raster == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7665, "%s: no raster for the in-memory DEM", name);
        goto done;
    }
    /* in memory: the caller's raster is the band, not a copy of it */
    ds = GDALCreate(drv, in_memory ? "" : tiles_path, (int)geo->ncols, (int)geo->nrows,
                    in_memory ? 0 : 1, GDT_Float32, co);
    if (ds == NULL) {
        st = gdal_fail(err, name, "create the intermediate raster");
        goto done;
    }
    if (in_memory) {
        char **bo = NULL;
        char v[64];
        snprintf(v, sizeof v, "%p", (void *)raster);
        bo = CSLSetNameValue(bo, "DATAPOINTER", v);
        bo = CSLSetNameValue(bo, "PIXELOFFSET", "4");
        snprintf(v, sizeof v, "%lld", (long long)geo->ncols * 4);
        bo = CSLSetNameValue(bo, "LINEOFFSET", v);
        if (GDALAddBand(ds, GDT_Float32, bo) != CE_None)
            st = gdal_fail(err, name, "take the DEM raster as the intermediate's band");
        CSLDestroy(bo);
        if (st != GDT_OK)
            goto done;
    }
    gt[0] = geo->west;
    gt[1] = geo->res_x;
    gt[2] = 0.0;
    gt[3] = geo->north;
    gt[4] = 0.0;
    gt[5] = -geo->res_y;
    band = GDALGetRasterBand(ds, 1);
    if (GDALSetGeoTransform(ds, gt) != CE_None ||
        (srs != NULL && GDALSetSpatialRef(ds, srs) != CE_None) ||
        GDALSetRasterNoDataValue(band, nodata) != CE_None ||
        /* what GDAL reads back from the GeoTIFF's raster type key */
        (in_memory && GDALSetMetadataItem(ds, "AREA_OR_POINT", "Area", NULL) != CE_None)) {
        st = gdal_fail(err, name, "set the georeferencing");
        goto done;
    }
    /* blocks from fn go through buf; in memory the raster is the band */
    if (!in_memory)
        buf = malloc((size_t)GDT_DEM_BLOCK * GDT_DEM_BLOCK * sizeof *buf);
    if (!in_memory && buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    levels = own_levels(geo);
    if (levels > 0) {
        int factors[OVR_MAX_LEVELS];
        size_t half = (size_t)(GDT_DEM_BLOCK / 2) * GDT_DEM_BLOCK;
        for (int k = 1; k <= levels; k++)
            factors[k - 1] = 1 << k;
        for (int q = 0; q < 2; q++) {
            ow.sum[q] = malloc(half * sizeof *ow.sum[q]);
            ow.count[q] = malloc(half * sizeof *ow.count[q]);
        }
        ow.out = malloc(half * sizeof *ow.out);
        if (ow.sum[0] == NULL || ow.sum[1] == NULL || ow.count[0] == NULL || ow.count[1] == NULL ||
            ow.out == NULL) {
            st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
            goto done;
        }
        /* "NONE": the levels are created empty; block_overviews fills them */
        if (GDALBuildOverviews(ds, "NONE", levels, factors, 0, NULL, NULL, NULL) != CE_None) {
            st = gdal_fail(err, name, "create the overviews of the intermediate raster");
            goto done;
        }
    }
    /* MEM overviews start as zeros: cells never written must read nodata,
     * as the sparse GeoTIFF's missing blocks do (the full resolution is the
     * caller's raster, nodata where it has no value) */
    if (in_memory) {
        for (int k = 1; k <= levels && st == GDT_OK; k++) {
            GDALRasterBandH b = GDALGetOverview(band, k - 1);
            if (b == NULL || GDALFillRaster(b, nodata, 0.0) != CE_None)
                st = gdal_fail(err, name, "fill the intermediate raster with nodata");
        }
        if (st != GDT_OK)
            goto done;
    }
    ndf = (float)nodata;
    memcpy(&nd_bits, &ndf, sizeof nd_bits);
    for (int64_t by = 0; by < brows && st == GDT_OK; by++)
        for (int64_t bx = 0; bx < bcols && st == GDT_OK; bx++) {
            int empty = 0;
            int64_t x = bx * GDT_DEM_BLOCK, y = by * GDT_DEM_BLOCK;
            int w = (int)(geo->ncols - x < GDT_DEM_BLOCK ? geo->ncols - x : GDT_DEM_BLOCK);
            int h = (int)(geo->nrows - y < GDT_DEM_BLOCK ? geo->nrows - y : GDT_DEM_BLOCK);
            if (in_memory) {
                /* the band holds the block already; an empty one adds
                 * nothing to the overviews */
                if (levels > 0)
                    st = block_overviews(band, levels, raster + (size_t)y * (size_t)geo->ncols +
                                                           (size_t)x,
                                         (size_t)geo->ncols, w, h, bx, by, nd_bits, ndf, geo, &ow,
                                         name, err);
                continue;
            }
            st = fn(ctx, bx, by, buf, &empty, err);
            if (st != GDT_OK || empty)
                continue;
            if (GDALRasterIO(band, GF_Write, (int)x, (int)y, w, h, buf, w, h, GDT_Float32, 0,
                             (int)(GDT_DEM_BLOCK * sizeof *buf)) != CE_None)
                st = gdal_fail(err, name, "write a block of the intermediate raster");
            else if (levels > 0)
                st = block_overviews(band, levels, buf, GDT_DEM_BLOCK, w, h, bx, by, nd_bits, ndf,
                                     geo, &ow, name, err);
        }
done:
    if (ds != NULL && in_memory && st == GDT_OK && mem_ds != NULL) {
        *mem_ds = ds; /* for gdt_dem_gdal_cog */
    } else if (ds != NULL) {
        GDALFlushCache(ds);
        if (st == GDT_OK && CPLGetLastErrorType() >= CE_Failure)
            st = gdal_fail(err, name, "write the intermediate GeoTIFF");
        GDALClose(ds);
        if (st == GDT_OK && CPLGetLastErrorType() >= CE_Failure)
            st = gdal_fail(err, name, "complete the intermediate GeoTIFF");
    }
    free(buf);
    for (int q = 0; q < 2; q++) {
        free(ow.sum[q]);
        free(ow.count[q]);
    }
    free(ow.out);
    CSLDestroy(co);
    if (srs != NULL)
        OSRDestroySpatialReference(srs);
    scope_leave(&scope);
    return st;
}

void gdt_dem_gdal_discard(void *mem_ds)
{
    if (mem_ds != NULL)
        GDALClose((GDALDatasetH)mem_ds);
}

gdt_status gdt_dem_gdal_cog(const char *tiles_path, void *mem_ds, const char *tmp_path,
                            const char *path, uint64_t gdal_cache, gdt_error *err)
{
    gdal_scope scope;
    GDALDriverH drv;
    GDALDatasetH src = NULL, dst = NULL;
    char **co = NULL;
    gdt_status st = GDT_OK;

    scope_enter(&scope, gdal_cache);
    drv = GDALGetDriverByName("COG");
    if (drv == NULL) {
        gdt_dem_gdal_discard(mem_ds);
        st = gdal_fail(err, path, "find its COG driver (GDAL 3.1 or later is needed)");
        goto done;
    }
    src = mem_ds != NULL ? (GDALDatasetH)mem_ds : GDALOpen(tiles_path, GA_ReadOnly);
    mem_ds = NULL; /* src now */
    if (src == NULL) {
        st = gdal_fail(err, path, "open the intermediate GeoTIFF");
        goto done;
    }
    co = CSLSetNameValue(co, "COMPRESS", "DEFLATE");
    co = CSLSetNameValue(co, "PREDICTOR", "FLOATING_POINT");
    /* libdeflate level 1: measured 27% less time than the default 6 for a
     * file 1% larger on a 10M-cell DEM */
    co = CSLSetNameValue(co, "LEVEL", "1");
    co = CSLSetNameValue(co, "BIGTIFF", "IF_SAFER");
    co = CSLSetNameValue(co, "BLOCKSIZE", "512");
    co = CSLSetNameValue(co, "RESAMPLING", "AVERAGE");
    /* the intermediate file's own overviews when it has them (see
     * own_levels), else GDAL's averaging */
    co = CSLSetNameValue(co, "OVERVIEWS",
                         GDALGetOverviewCount(GDALGetRasterBand(src, 1)) > 0 ? "FORCE_USE_EXISTING"
                                                                             : "IGNORE_EXISTING");
    /* the blocks are compressed on worker threads but written in block
     * order: the bytes do not depend on the thread count (tested) */
    co = CSLSetNameValue(co, "NUM_THREADS", "ALL_CPUS");
    /* the options above are fixed and valid: checking them would build the
     * COG driver's option list, which reads every tiling scheme GDAL ships
     * (about 12 ms) */
    CPLSetThreadLocalConfigOption("GDAL_VALIDATE_CREATION_OPTIONS", "NO");
    dst = GDALCreateCopy(drv, tmp_path, src, FALSE, co, NULL, NULL);
    CPLSetThreadLocalConfigOption("GDAL_VALIDATE_CREATION_OPTIONS", NULL);
    if (dst == NULL) {
        st = gdal_fail(err, path, "write the Cloud Optimized GeoTIFF");
        goto done;
    }
    st = close_and_commit(dst, tmp_path, path, "complete the Cloud Optimized GeoTIFF", err);
    dst = NULL;
done:
    if (src != NULL)
        GDALClose(src);
    CSLDestroy(co);
    scope_leave(&scope);
    return st;
}

gdt_status gdt_dem_gdal_preview(const char *dem_path, const char *tmp_path, const char *path,
                                uint64_t gdal_cache, gdt_error *err)
{
    gdal_scope scope;
    GDALDatasetH src = NULL, small = NULL, shade = NULL, png = NULL;
    GDALTranslateOptions *to = NULL;
    GDALDEMProcessingOptions *po = NULL;
    GDALDriverH drv;
    char **targv = NULL, **pargv = NULL;
    char ws[32], hs[32];
    int64_t nc, nr, w, h, longest;
    int usage = 0;
    gdt_status st = GDT_OK;

    scope_enter(&scope, gdal_cache);
    src = GDALOpen(dem_path, GA_ReadOnly);
    if (src == NULL) {
        st = gdal_fail(err, path, "open the DEM for the preview");
        goto done;
    }
    nc = GDALGetRasterXSize(src);
    nr = GDALGetRasterYSize(src);
    longest = nc > nr ? nc : nr;
    w = nc;
    h = nr;
    if (longest > GDT_DEM_PREVIEW_MAX) {
        /* the long side becomes GDT_DEM_PREVIEW_MAX, the short one is
         * rounded, at least 1 */
        w = (nc * GDT_DEM_PREVIEW_MAX + longest / 2) / longest;
        h = (nr * GDT_DEM_PREVIEW_MAX + longest / 2) / longest;
        if (w < 1)
            w = 1;
        if (h < 1)
            h = 1;
    }
    snprintf(ws, sizeof ws, "%lld", (long long)w);
    snprintf(hs, sizeof hs, "%lld", (long long)h);
    targv = CSLAddString(targv, "-of");
    targv = CSLAddString(targv, "MEM");
    targv = CSLAddString(targv, "-outsize");
    targv = CSLAddString(targv, ws);
    targv = CSLAddString(targv, hs);
    targv = CSLAddString(targv, "-r");
    targv = CSLAddString(targv, "average");
    to = GDALTranslateOptionsNew(targv, NULL);
    if (to == NULL) {
        st = gdal_fail(err, path, "set up the downsampling");
        goto done;
    }
    small = GDALTranslate("", src, to, &usage);
    if (small == NULL) {
        st = gdal_fail(err, path, "downsample the DEM");
        goto done;
    }
    pargv = CSLAddString(pargv, "-of");
    pargv = CSLAddString(pargv, "MEM");
    pargv = CSLAddString(pargv, "-compute_edges");
    po = GDALDEMProcessingOptionsNew(pargv, NULL);
    if (po == NULL) {
        st = gdal_fail(err, path, "set up the hillshade");
        goto done;
    }
    shade = GDALDEMProcessing("", small, "hillshade", NULL, po, &usage);
    if (shade == NULL) {
        st = gdal_fail(err, path, "compute the hillshade");
        goto done;
    }
    drv = GDALGetDriverByName("PNG");
    if (drv == NULL) {
        st = gdal_fail(err, path, "find its PNG driver");
        goto done;
    }
    {
        char **co = CSLSetNameValue(NULL, "WORLDFILE", "NO");
        png = GDALCreateCopy(drv, tmp_path, shade, FALSE, co, NULL, NULL);
        CSLDestroy(co);
    }
    if (png == NULL) {
        st = gdal_fail(err, path, "write the preview PNG");
        goto done;
    }
    st = close_and_commit(png, tmp_path, path, "complete the preview PNG", err);
    png = NULL;
done:
    if (shade != NULL)
        GDALClose(shade);
    if (small != NULL)
        GDALClose(small);
    if (src != NULL)
        GDALClose(src);
    GDALTranslateOptionsFree(to);
    GDALDEMProcessingOptionsFree(po);
    CSLDestroy(targv);
    CSLDestroy(pargv);
    scope_leave(&scope);
    return st;
}

__attribute__((visibility("default"))) extern const gdt_dem_gdal_fns gdt_dem_gdal_api;
const gdt_dem_gdal_fns gdt_dem_gdal_api = {gdt_dem_gdal_tiles, gdt_dem_gdal_cog,
                                           gdt_dem_gdal_discard, gdt_dem_gdal_preview};
