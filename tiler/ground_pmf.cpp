// ground_pmf.cpp — the ground filter of gdt_ground.h on PCL's approximate
// progressive morphological filter, which runs in the module of
// private/ground_pcl.h, loaded on the first call.
#include "gdt_ground.h"
#include "private/ground_pcl.h"
#include "private/plugin.h"

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <exception>
#include <limits>
#include <new>
#include <vector>

// A cell index of PCL's grid must be exact in float with its 1/2 added.
static const int64_t MAX_CELLS_SIDE = (int64_t)1 << 22;

extern "C" void gdt_pmf_defaults(gdt_pmf_params *p)
{
    p->max_window = 33.0;
    p->slope = 1.0;
    p->initial_distance = 0.15;
    p->max_distance = 2.5;
    p->cell = 1.0;
    p->exponential = 1;
}

extern "C" void gdt_pmf_describe(const gdt_pmf_params *p, char *buf, size_t cap)
{
    std::snprintf(buf, cap,
                  "ground pmf max-window %.15g slope %.15g initial-distance %.15g "
                  "max-distance %.15g cell %.15g exponential %s",
                  p->max_window, p->slope, p->initial_distance, p->max_distance, p->cell,
                  p->exponential ? "true" : "false");
}

extern "C" gdt_status gdt_pmf_check(const gdt_pmf_params *p, gdt_error *err)
{
    struct {
        const char *name;
        double v;
        int positive;
    } const v[] = {
        {"--pmf-max-window", p->max_window, 1},
        {"--pmf-slope", p->slope, 0},
        {"--pmf-initial-distance", p->initial_distance, 0},
        {"--pmf-max-distance", p->max_distance, 0},
        {"--pmf-cell", p->cell, 1},
    };
    for (const auto &e : v) {
        if (!std::isfinite(e.v) || e.v < 0.0 || (e.positive && e.v == 0.0))
            return gdt_error_set(err, GDT_EUSAGE, 2701, "%s %g: must be a finite number %s", e.name,
                                 e.v, e.positive ? "above 0" : "of at least 0");
        // float32 inside PCL: a value it would turn into infinity is refused too
        if (e.v > 1e30)
            return gdt_error_set(err, GDT_EUSAGE, 2701, "%s %g: too large", e.name, e.v);
    }
    if (p->max_window < p->cell)
        return gdt_error_set(err, GDT_EUSAGE, 2701,
                             "--pmf-max-window %g: smaller than one cell (--pmf-cell %g)",
                             p->max_window, p->cell);
    if (p->max_window / p->cell > 1e6)
        return gdt_error_set(err, GDT_EUSAGE, 2701,
                             "--pmf-max-window %g: more than a million cells of %g", p->max_window,
                             p->cell);
    return GDT_OK;
}

extern "C" gdt_status gdt_pmf_init(gdt_pmf *f, const gdt_pmf_params *p, const gdt_lattice *lat,
                                   double z0, gdt_error *err)
{
    gdt_status st = gdt_pmf_check(p, err);
    if (st != GDT_OK)
        return st;
    std::memset(f, 0, sizeof *f);
    f->p = *p;
    f->fx = lat->sx / p->cell;
    f->fy = lat->sy / p->cell;
    f->z0 = z0;
    f->max_window_cells = (int)std::ceil(p->max_window / p->cell);
    f->pcl_slope = (float)(p->slope * p->cell);
    // PCL's loop, in its types: windows while the previous one is below the
    // maximum (an int); half sizes from a float power of the base 2.
    float window = 0.0f;
    const float base = 2.0f;
    int it = 0;
    while (window < (float)f->max_window_cells) {
        if (it == GDT_PMF_MAX_ROUNDS)
            return gdt_error_set(err, GDT_EUSAGE, 2701,
                                 "--pmf-max-window %g: more than %d rounds of the filter",
                                 p->max_window, GDT_PMF_MAX_ROUNDS);
        int half = p->exponential ? (int)std::pow(base, (float)it) : (int)((float)(it + 1) * base);
        window = (float)(2 * half + 1);
        f->half[it] = half;
        f->reach_cells += 2 * (int64_t)half;
        it++;
    }
    f->rounds = it;
    // Cells within D of p's column hold points whose x * fx lies within
    // D + 1 of p's (plus the rounding of the products): reach covers that.
    double rx = std::ceil((double)(f->reach_cells + 1) / f->fx) + 1.0;
    double ry = std::ceil((double)(f->reach_cells + 1) / f->fy) + 1.0;
    double r = rx > ry ? rx : ry;
    if (!(r <= (double)((int64_t)1 << 40)))
        return gdt_error_set(
            err, GDT_EUSAGE, 2701,
            "--pmf-max-window %g with --pmf-cell %g: the filter reaches %g lattice "
            "steps, beyond 2^40",
            p->max_window, p->cell, r);
    f->reach = (int64_t)r;
    return GDT_OK;
}

extern "C" int64_t gdt_pmf_cell_x(const gdt_pmf *f, int64_t x)
{
    return (int64_t)std::floor((double)x * f->fx);
}

extern "C" int64_t gdt_pmf_cell_y(const gdt_pmf *f, int64_t y)
{
    return (int64_t)std::floor((double)y * f->fy);
}

extern "C" gdt_status gdt_pmf_classify(const gdt_pmf *f, const gdt_point *pts0, size_t n0,
                                       const gdt_point *more, size_t nmore,
                                       const gdt_pmf_box *cloud, const gdt_pmf_box *roi,
                                       uint8_t *ground, uint64_t max_bytes, gdt_error *err)
{
    const size_t n = n0 + nmore;
    auto at = [&](size_t i) -> const gdt_point & { return i < n0 ? pts0[i] : more[i - n0]; };
    if (n == 0)
        return GDT_OK;
    std::memset(ground, 0, n);
    // The cells of the cloud's grid within D of roi's: the call's grid must
    // hold them all (and holds only cells of the cloud's grid).
    const int64_t D = f->reach_cells;
    int64_t wx0 = gdt_pmf_cell_x(f, roi->x0) - D, wx1 = gdt_pmf_cell_x(f, roi->x1) + D;
    int64_t wy0 = gdt_pmf_cell_y(f, roi->y0) - D, wy1 = gdt_pmf_cell_y(f, roi->y1) + D;
    const int64_t gx0 = gdt_pmf_cell_x(f, cloud->x0), gx1 = gdt_pmf_cell_x(f, cloud->x1);
    const int64_t gy0 = gdt_pmf_cell_y(f, cloud->y0), gy1 = gdt_pmf_cell_y(f, cloud->y1);
    wx0 = wx0 < gx0 ? gx0 : wx0;
    wx1 = wx1 > gx1 ? gx1 : wx1;
    wy0 = wy0 < gy0 ? gy0 : wy0;
    wy1 = wy1 > gy1 ? gy1 : wy1;
    int64_t cx0 = wx0, cx1 = wx1, cy0 = wy0, cy1 = wy1;
    for (size_t i = 0; i < n; i++) {
        int64_t cx = gdt_pmf_cell_x(f, at(i).x), cy = gdt_pmf_cell_y(f, at(i).y);
        cx0 = cx < cx0 ? cx : cx0;
        cx1 = cx > cx1 ? cx : cx1;
        cy0 = cy < cy0 ? cy : cy0;
        cy1 = cy > cy1 ? cy : cy1;
    }
    const int64_t cols = cx1 - cx0 + 1, rows = cy1 - cy0 + 1;
    if (cols > MAX_CELLS_SIDE || rows > MAX_CELLS_SIDE)
        return gdt_error_set(err, GDT_EUSAGE, 2702,
                             "the ground filter's grid of %" PRId64 " x %" PRId64
                             " cells exceeds 2^22 cells a side: use a larger --pmf-cell or a "
                             "smaller --tile",
                             cols, rows);
    // PCL's three float grids, our cloud for it, its copy per round and the
    // index lists
    const double bytes =
        GDT_PMF_BYTES_PER_CELL * (double)cols * (double)rows + GDT_PMF_BYTES_PER_POINT * (double)n;
    if (max_bytes > 0 && bytes > (double)max_bytes)
        return gdt_error_set(err, GDT_EUSAGE, 2702,
                             "the ground filter needs %.0f MiB for %zu points on %" PRId64
                             " x %" PRId64 " cells, more than its budget of %.0f MiB: use a "
                             "larger --pmf-cell, a smaller --tile or a larger --mem-budget",
                             bytes / 1048576.0, n, cols, rows, (double)max_bytes / 1048576.0);
    gdt_ground_pcl_fn run = nullptr;
    {
        void *sym = nullptr;
        gdt_status st = gdt_plugin_symbol(GDT_GROUND_PCL_MODULE, GDT_GROUND_PCL_SYMBOL,
                                          "the ground filter (PCL)", &sym, err);
        if (st != GDT_OK)
            return st;
        std::memcpy(&run, &sym, sizeof run);
    }
    // PCL's cloud: the points, then the two corners of the window, z NaN:
    // PCL's box (is_dense, so not skipped there) covers the window; a NaN z
    // never replaces a cell's lowest z (it neither compares below one nor
    // fills a cell that a point fills later), and is never below a threshold
    struct fill_ctx {
        const gdt_pmf *f;
        const gdt_point *pts0, *more;
        size_t n0, n;
        int64_t cx0, cy0, wx0, wy0, wx1, wy1;
    } fc = {f, pts0, more, n0, n, cx0, cy0, wx0, wy0, wx1, wy1};
    auto fill = [](void *ctx, float *xyz, size_t stride) {
        const fill_ctx &c = *static_cast<const fill_ctx *>(ctx);
        for (size_t i = 0; i < c.n; i++, xyz += stride) {
            const gdt_point &p = i < c.n0 ? c.pts0[i] : c.more[i - c.n0];
            xyz[0] = (float)(gdt_pmf_cell_x(c.f, p.x) - c.cx0) + 0.5f;
            xyz[1] = (float)(gdt_pmf_cell_y(c.f, p.y) - c.cy0) + 0.5f;
            xyz[2] = (float)(p.z - c.f->z0);
        }
        xyz[0] = (float)(c.wx0 - c.cx0) + 0.5f;
        xyz[1] = (float)(c.wy0 - c.cy0) + 0.5f;
        xyz[2] = std::numeric_limits<float>::quiet_NaN();
        xyz += stride;
        xyz[0] = (float)(c.wx1 - c.cx0) + 0.5f;
        xyz[1] = (float)(c.wy1 - c.cy0) + 0.5f;
        xyz[2] = std::numeric_limits<float>::quiet_NaN();
    };
    gdt_ground_pcl_job job;
    std::memset(&job, 0, sizeof job);
    job.n = n + 2;
    job.fill = fill;
    job.fill_ctx = &fc;
    job.ground = ground;
    job.nflag = n;
    job.max_window_cells = f->max_window_cells;
    job.exponential = f->p.exponential != 0;
    job.slope = f->pcl_slope;
    job.initial_distance = (float)f->p.initial_distance;
    job.max_distance = (float)f->p.max_distance;
    char msg[256] = "";
    switch (run(&job, msg, sizeof msg)) {
    case GDT_GROUND_PCL_OK: break;
    case GDT_GROUND_PCL_NOMEM:
        return gdt_error_set(err, GDT_EINTERNAL, 7001,
                             "out of memory in the ground filter (%zu points)", n);
    default: return gdt_error_set(err, GDT_EINTERNAL, 7701, "%s", msg);
    }
    return GDT_OK;
}
