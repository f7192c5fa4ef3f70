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

gdt_status gdt_dem_gdal_tiles(const gdt_dem_geo *geo, double nodata, int epsg, const char *wkt,
                              const char *tiles_path, uint64_t gdal_cache, gdt_dem_block_fn fn,
                              void *ctx, gdt_error *err)
{
    gdal_scope scope;
    GDALDriverH drv;
    GDALDatasetH ds = NULL;
    GDALRasterBandH band;
    OGRSpatialReferenceH srs = NULL;
    char **co = NULL;
    float *buf = NULL;
    double gt[6];
    gdt_status st = GDT_OK;
    int64_t bcols = (geo->ncols + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;
    int64_t brows = (geo->nrows + GDT_DEM_BLOCK - 1) / GDT_DEM_BLOCK;

    scope_enter(&scope, gdal_cache);
    if (epsg > 0 || wkt != NULL) {
        srs = OSRNewSpatialReference(NULL);
        char *wp = (char *)wkt; /* OSRImportFromWkt reads it, never writes */
        if (srs == NULL ||
            (epsg > 0 ? OSRImportFromEPSG(srs, epsg) : OSRImportFromWkt(srs, &wp)) !=
                OGRERR_NONE) {
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
    drv = GDALGetDriverByName("GTiff");
    if (drv == NULL) {
        st = gdal_fail(err, tiles_path, "find its GTiff driver");
        goto done;
    }
    co = CSLSetNameValue(co, "TILED", "YES");
    co = CSLSetNameValue(co, "BLOCKXSIZE", "512");
    co = CSLSetNameValue(co, "BLOCKYSIZE", "512");
    /* uncompressed: it is read once, by the COG step, and compressing it
     * too cost as much as the final compression (empty blocks stay sparse) */
    co = CSLSetNameValue(co, "COMPRESS", "NONE");
    co = CSLSetNameValue(co, "BIGTIFF", "YES");
    co = CSLSetNameValue(co, "SPARSE_OK", "TRUE");
    ds = GDALCreate(drv, tiles_path, (int)geo->ncols, (int)geo->nrows, 1, GDT_Float32, co);
    if (ds == NULL) {
        st = gdal_fail(err, tiles_path, "create the intermediate GeoTIFF");
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
        GDALSetRasterNoDataValue(band, nodata) != CE_None) {
        st = gdal_fail(err, tiles_path, "set the georeferencing");
        goto done;
    }
    buf = malloc((size_t)GDT_DEM_BLOCK * GDT_DEM_BLOCK * sizeof *buf);
    if (buf == NULL) {
        st = gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory");
        goto done;
    }
    for (int64_t by = 0; by < brows && st == GDT_OK; by++)
        for (int64_t bx = 0; bx < bcols && st == GDT_OK; bx++) {
            int empty = 0;
            int64_t x = bx * GDT_DEM_BLOCK, y = by * GDT_DEM_BLOCK;
            int w = (int)(geo->ncols - x < GDT_DEM_BLOCK ? geo->ncols - x : GDT_DEM_BLOCK);
            int h = (int)(geo->nrows - y < GDT_DEM_BLOCK ? geo->nrows - y : GDT_DEM_BLOCK);
            st = fn(ctx, bx, by, buf, &empty, err);
            if (st != GDT_OK || empty)
                continue;
            if (GDALRasterIO(band, GF_Write, (int)x, (int)y, w, h, buf, w, h, GDT_Float32, 0,
                             (int)(GDT_DEM_BLOCK * sizeof *buf)) != CE_None)
                st = gdal_fail(err, tiles_path, "write a block of the intermediate GeoTIFF");
        }
done:
    if (ds != NULL) {
        GDALFlushCache(ds);
        if (st == GDT_OK && CPLGetLastErrorType() >= CE_Failure)
            st = gdal_fail(err, tiles_path, "write the intermediate GeoTIFF");
        GDALClose(ds);
        if (st == GDT_OK && CPLGetLastErrorType() >= CE_Failure)
            st = gdal_fail(err, tiles_path, "complete the intermediate GeoTIFF");
    }
    free(buf);
    CSLDestroy(co);
    if (srs != NULL)
        OSRDestroySpatialReference(srs);
    scope_leave(&scope);
    return st;
}

gdt_status gdt_dem_gdal_cog(const char *tiles_path, const char *tmp_path, const char *path,
                            uint64_t gdal_cache, gdt_error *err)
{
    gdal_scope scope;
    GDALDriverH drv;
    GDALDatasetH src = NULL, dst = NULL;
    char **co = NULL;
    gdt_status st = GDT_OK;

    scope_enter(&scope, gdal_cache);
    drv = GDALGetDriverByName("COG");
    if (drv == NULL) {
        st = gdal_fail(err, path, "find its COG driver (GDAL 3.1 or later is needed)");
        goto done;
    }
    src = GDALOpen(tiles_path, GA_ReadOnly);
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
    co = CSLSetNameValue(co, "OVERVIEWS", "IGNORE_EXISTING");
    /* the blocks are compressed on worker threads but written in block
     * order: the bytes do not depend on the thread count (tested) */
    co = CSLSetNameValue(co, "NUM_THREADS", "ALL_CPUS");
    dst = GDALCreateCopy(drv, tmp_path, src, FALSE, co, NULL, NULL);
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
        if (w < 1) w = 1;
        if (h < 1) h = 1;
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
