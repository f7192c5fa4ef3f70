// ground_pcl.cpp — PCL's approximate progressive morphological filter
// behind the C boundary of private/ground_pcl.h.  Built into its own
// module, libgdt-tile-pcl.so, so that only runs with --ground pmf load PCL.
#include "private/ground_pcl.h"

#include <cstdio>
#include <exception>
#include <new>

#include <pcl/point_cloud.h>
#include <pcl/point_types.h>
#include <pcl/segmentation/approximate_progressive_morphological_filter.h>

extern "C" __attribute__((visibility("default"))) int
gdt_ground_pcl_run(const gdt_ground_pcl_job *job, char *msg, size_t cap)
{
    try {
        pcl::PointCloud<pcl::PointXYZ>::Ptr pc(new pcl::PointCloud<pcl::PointXYZ>);
        pc->resize(job->n);
        if (job->n > 0)
            job->fill(job->fill_ctx, &(*pc)[0].x, sizeof(pcl::PointXYZ) / sizeof(float));
        pc->is_dense = true;
        pcl::ApproximateProgressiveMorphologicalFilter<pcl::PointXYZ> pmf;
        pmf.setInputCloud(pc);
        pmf.setMaxWindowSize(job->max_window_cells);
        pmf.setSlope(job->slope);
        pmf.setInitialDistance(job->initial_distance);
        pmf.setMaxDistance(job->max_distance);
        pmf.setCellSize(1.0f);
        pmf.setBase(2.0f);
        pmf.setExponential(job->exponential != 0);
        pmf.setNumberOfThreads(1);
        pcl::Indices idx;
        pmf.extract(idx);
        for (auto i : idx) {
            if (i < 0 || (size_t)i >= job->n) {
                std::snprintf(msg, cap, "PCL's ground filter returned index %d of %zu points",
                              (int)i, job->n);
                return GDT_GROUND_PCL_FAILED;
            }
            if ((size_t)i < job->nflag)
                job->ground[i] = 1;
        }
    } catch (const std::bad_alloc &) {
        return GDT_GROUND_PCL_NOMEM;
    } catch (const std::exception &e) {
        std::snprintf(msg, cap, "PCL's ground filter failed: %s", e.what());
        return GDT_GROUND_PCL_FAILED;
    }
    return GDT_GROUND_PCL_OK;
}
