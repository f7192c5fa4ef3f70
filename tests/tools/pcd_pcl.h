/* pcd_pcl.h — reference PCD reader through the Point Cloud Library.
 *
 * Reads a whole PCD file with pcl::PCDReader into a pcl::PCLPointCloud2 and
 * hands out x/y/z of every point as doubles.  The fields are found by name
 * in any case ("x" or "X") and may have any PCL numeric type, which typed
 * clouds such as pcl::PointXYZ cannot do.  It holds the whole cloud in
 * memory: it is the oracle the tests compare the streaming reader against,
 * not a production path.  No C++ exception crosses this interface.
 */
#ifndef GDT_PCD_PCL_H
#define GDT_PCD_PCL_H

#include <stdint.h>

#include "gdt_error.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Called once per point in file order, invalid (NaN) points included.
 * A non-zero return stops the reading (gdt_pcd_pcl_read then returns
 * GDT_EINTERNAL with message 7290). */
typedef int (*gdt_pcd_pcl_point_fn)(void *ctx, double x, double y, double z);

/* Reads path through PCL and calls fn for each point; *count (may be NULL)
 * receives the number of points in the cloud (WIDTH x HEIGHT).
 * returns: GDT_OK, or GDT_EINPUT (message 329x) when PCL refuses the file,
 * when x, y or z is missing or named twice, or when PCL throws. */
gdt_status gdt_pcd_pcl_read(const char *path, gdt_pcd_pcl_point_fn fn, void *ctx, uint64_t *count,
                            gdt_error *err);

#ifdef __cplusplus
}
#endif
#endif
