// vdb_index.cpp — OpenVDB behind the C interface of gdt_vdb_index.h.
//
// Invariants: only voxel values are ever set (never tile values), so
// walking the active values visits exactly the active voxels; density voxel
// indices have magnitude below 2^30, far from the int32 limits of
// openvdb::Coord.  No exception leaves this file: every extern "C" function
// has a try/catch-all that turns it into a gdt_status.
#include "gdt_vdb_index.h"

#include <openvdb/io/File.h>
#include <openvdb/math/Maps.h>
#include <openvdb/math/Transform.h>
#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdint>
#include <exception>
#include <new>
#include <string>
#include <cstring>
#include <cerrno>
#include <sys/statvfs.h>
#include <sys/stat.h>
#include <sys/resource.h>

namespace {

const int64_t kCoordLimit = int64_t(1) << 30;

gdt_status fail_from_exception(gdt_error *err, const char *what)
{
    try {
        throw;
    } catch (const std::bad_alloc &) {
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory in the OpenVDB index (%s)",
                             what);
    } catch (const openvdb::IoError &e) {
        return gdt_error_set(err, GDT_EIO, 4511, "OpenVDB index: %s: %s", what, e.what());
    } catch (const std::exception &e) {
        return gdt_error_set(err, GDT_EINTERNAL, 7511, "OpenVDB index: %s: %s", what, e.what());
    } catch (...) {
        return gdt_error_set(err, GDT_EINTERNAL, 7511, "OpenVDB index: %s: unknown exception",
                             what);
    }
}

// The grids' world space is the lattice: a world unit is one lattice step,
// so the transform depends on the plan alone and any lattice (a scale of
// 1e-9 degrees as well as one of 1000 m) gives a transform OpenVDB accepts
// (its maps refuse scales below about 1.4e-5).  Voxel (u, v) covers lattice
// [(base + u) * cells, (base + u + 1) * cells): its centre is at world
// (base + u + 0.5) * cells, and at CRS ox + sx * world (gdt_lattice_* and
// gdt_world metadata).
openvdb::math::Transform::Ptr make_transform(double cells, double base_x, double base_y)
{
    openvdb::Vec3d scale(cells, cells, cells);
    openvdb::Vec3d trans(cells * (base_x + 0.5), cells * (base_y + 0.5), 0.0);
    openvdb::math::MapBase::Ptr map(new openvdb::math::ScaleTranslateMap(scale, trans));
    return openvdb::math::Transform::Ptr(new openvdb::math::Transform(map));
}

void put_meta(openvdb::GridBase &g, const gdt_vdb_meta *m)
{
    g.insertMeta("gdt_tile", openvdb::Int64Metadata(m->tile));
    g.insertMeta("gdt_cell", openvdb::Int64Metadata(m->cell));
    g.insertMeta("gdt_halo", openvdb::Int64Metadata(m->halo));
    g.insertMeta("gdt_span", openvdb::Int64Metadata(m->span));
    g.insertMeta("gdt_tile_i0", openvdb::Int64Metadata(m->tile_i0));
    g.insertMeta("gdt_tile_j0", openvdb::Int64Metadata(m->tile_j0));
    g.insertMeta("gdt_density_shift", openvdb::Int64Metadata(m->density_shift));
    g.insertMeta("gdt_points", openvdb::Int64Metadata(m->points));
    g.insertMeta("gdt_lattice_sx", openvdb::DoubleMetadata(m->lattice.sx));
    g.insertMeta("gdt_lattice_sy", openvdb::DoubleMetadata(m->lattice.sy));
    g.insertMeta("gdt_lattice_ox", openvdb::DoubleMetadata(m->lattice.ox));
    g.insertMeta("gdt_lattice_oy", openvdb::DoubleMetadata(m->lattice.oy));
    g.insertMeta("gdt_dup", openvdb::StringMetadata(m->dup != nullptr ? m->dup : "first"));
    g.insertMeta("gdt_world", openvdb::StringMetadata("lattice steps: CRS x = gdt_lattice_ox + "
                                                      "gdt_lattice_sx * world x, y likewise"));
}

int64_t get_i64(const openvdb::GridBase &g, const char *name)
{
    openvdb::Int64Metadata::ConstPtr v = g.getMetadata<openvdb::Int64Metadata>(name);
    if (!v)
        throw openvdb::LookupError(std::string("missing metadata ") + name);
    return v->value();
}

double get_f64(const openvdb::GridBase &g, const char *name)
{
    openvdb::DoubleMetadata::ConstPtr v = g.getMetadata<openvdb::DoubleMetadata>(name);
    if (!v)
        throw openvdb::LookupError(std::string("missing metadata ") + name);
    return v->value();
}

} // namespace

struct gdt_vdb_index {
    openvdb::Int64Grid::Ptr density;
    openvdb::Int64Grid::Ptr tiles;
};

extern "C" gdt_status gdt_vdb_index_create(gdt_vdb_index **out, gdt_error *err)
{
    *out = nullptr;
    try {
        openvdb::initialize();
        gdt_vdb_index *ix = new gdt_vdb_index;
        ix->density = openvdb::Int64Grid::create(0);
        ix->tiles = openvdb::Int64Grid::create(0);
        *out = ix;
        return GDT_OK;
    } catch (...) {
        return fail_from_exception(err, "cannot create the grids");
    }
}

extern "C" void gdt_vdb_index_destroy(gdt_vdb_index *ix)
{
    delete ix; // destructors of shared grid pointers do not throw
}

extern "C" void gdt_vdb_node_bytes(size_t bytes[3])
{
    using Tree = openvdb::Int64Tree;
    using Leaf = Tree::LeafNodeType;
    using Lower = Tree::RootNodeType::ChildNodeType::ChildNodeType;
    using Upper = Tree::RootNodeType::ChildNodeType;
    static_assert(Leaf::DIM == 8 && Lower::DIM == 128 && Upper::DIM == 4096,
                  "the density rules assume OpenVDB's default 5-4-3 tree");
    bytes[0] = sizeof(Leaf);
    bytes[1] = sizeof(Lower);
    bytes[2] = sizeof(Upper);
}

extern "C" gdt_status gdt_vdb_density_set(gdt_vdb_index *ix, int64_t vx, int64_t vy,
                                          uint64_t count, gdt_error *err)
{
    if (vx <= -kCoordLimit || vx >= kCoordLimit || vy <= -kCoordLimit || vy >= kCoordLimit ||
        count > uint64_t(INT64_MAX))
        return gdt_error_set(err, GDT_EINTERNAL, 7511,
                             "OpenVDB index: density voxel (%lld, %lld) out of range",
                             (long long)vx, (long long)vy);
    try {
        ix->density->tree().setValue(openvdb::Coord(int32_t(vx), int32_t(vy), 0),
                                     int64_t(count));
        return GDT_OK;
    } catch (...) {
        return fail_from_exception(err, "cannot set a density count");
    }
}

extern "C" gdt_status gdt_vdb_tiles_set(gdt_vdb_index *ix, int64_t ci, int64_t cj,
                                        uint64_t count, gdt_error *err)
{
    if (ci < 0 || cj < 0 || ci > INT32_MAX || cj > INT32_MAX || count > uint64_t(INT64_MAX))
        return gdt_error_set(err, GDT_EINTERNAL, 7511,
                             "OpenVDB index: tile voxel (%lld, %lld) out of range",
                             (long long)ci, (long long)cj);
    try {
        ix->tiles->tree().setValue(openvdb::Coord(int32_t(ci), int32_t(cj), 0), int64_t(count));
        return GDT_OK;
    } catch (...) {
        return fail_from_exception(err, "cannot set a tile count");
    }
}

/* Why a written file came out short, as far as the system can tell: the
 * process's file size limit reached (EFBIG) or no space left (ENOSPC). */
static const char *short_write_reason(const char *path)
{
    struct stat sb;
    struct rlimit rl;
    struct statvfs vfs;
    std::string dir(path);
    size_t slash = dir.rfind('/');
    dir = slash == std::string::npos ? std::string(".") : dir.substr(0, slash + 1);
    if (stat(path, &sb) == 0 && getrlimit(RLIMIT_FSIZE, &rl) == 0 &&
        rl.rlim_cur != RLIM_INFINITY && (rlim_t)sb.st_size >= rl.rlim_cur)
        return std::strerror(EFBIG);
    if (statvfs(dir.c_str(), &vfs) == 0 && vfs.f_bavail == 0)
        return std::strerror(ENOSPC);
    return "short write (disk full?)";
}

extern "C" gdt_status gdt_vdb_index_write(gdt_vdb_index *ix, const gdt_vdb_meta *meta,
                                          const char *path, gdt_error *err)
{
    try {
        double v = std::ldexp(1.0, int(meta->density_shift));
        openvdb::Int64Grid::Ptr density = ix->density;
        openvdb::Int64Grid::Ptr tiles = ix->tiles;
        density->setName("density");
        density->setTransform(make_transform(v, 0.0, 0.0));
        density->setGridClass(openvdb::GRID_UNKNOWN);
        tiles->setName("tile_points");
        tiles->setTransform(
            make_transform(double(meta->span), double(meta->tile_i0), double(meta->tile_j0)));
        tiles->setGridClass(openvdb::GRID_UNKNOWN);
        put_meta(*density, meta);
        put_meta(*tiles, meta);
        openvdb::GridPtrVec grids;
        grids.push_back(tiles);
        grids.push_back(density);
        openvdb::io::File file(path);
        file.write(grids);
        file.close();
        /* io::File does not report a short write (a full disk, a file size
         * limit): read the file back, which fails on any missing byte. */
        try {
            openvdb::io::File check(path);
            check.open();
            openvdb::GridBase::Ptr a = check.readGrid("tile_points");
            openvdb::GridBase::Ptr b = check.readGrid("density");
            check.close();
        } catch (...) {
            return gdt_error_set(err, GDT_EIO, 4512,
                                 "cannot write the index %s: the file is incomplete after "
                                 "writing: %s",
                                 path, short_write_reason(path));
        }
        return GDT_OK;
    } catch (const std::bad_alloc &) {
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory writing %s", path);
    } catch (const std::exception &e) {
        return gdt_error_set(err, GDT_EIO, 4511, "cannot write the index %s: %s", path,
                             e.what());
    } catch (...) {
        return gdt_error_set(err, GDT_EIO, 4511, "cannot write the index %s", path);
    }
}

extern "C" gdt_status gdt_vdb_index_read_tiles(const char *path, gdt_vdb_meta *meta,
                                               gdt_vdb_visit_fn fn, void *ctx, gdt_error *err)
{
    try {
        openvdb::initialize();
        openvdb::io::File file(path);
        file.open();
        openvdb::GridBase::Ptr base = file.readGrid("tile_points");
        file.close();
        openvdb::Int64Grid::Ptr g = openvdb::gridPtrCast<openvdb::Int64Grid>(base);
        if (!g)
            return gdt_error_set(err, GDT_EINPUT, 3511,
                                 "%s: grid tile_points is not a grid of int64 counts", path);
        meta->tile = get_i64(*g, "gdt_tile");
        meta->cell = get_i64(*g, "gdt_cell");
        meta->halo = get_i64(*g, "gdt_halo");
        meta->span = get_i64(*g, "gdt_span");
        meta->tile_i0 = get_i64(*g, "gdt_tile_i0");
        meta->tile_j0 = get_i64(*g, "gdt_tile_j0");
        meta->density_shift = get_i64(*g, "gdt_density_shift");
        meta->points = get_i64(*g, "gdt_points");
        meta->lattice.sx = get_f64(*g, "gdt_lattice_sx");
        meta->lattice.sy = get_f64(*g, "gdt_lattice_sy");
        meta->lattice.ox = get_f64(*g, "gdt_lattice_ox");
        meta->lattice.oy = get_f64(*g, "gdt_lattice_oy");
        {
            std::string dup = g->metaValue<std::string>("gdt_dup");
            meta->dup = dup == "first" ? "first"
                        : dup == "min-z" ? "min-z"
                        : dup == "max-z" ? "max-z"
                                         : "unknown";
        }
        for (openvdb::Int64Grid::ValueOnCIter it = g->cbeginValueOn(); it; ++it) {
            if (!it.isVoxelValue() || *it < 0)
                return gdt_error_set(err, GDT_EINPUT, 3511,
                                     "%s: grid tile_points holds a value that is not a tile count",
                                     path);
            openvdb::Coord c = it.getCoord();
            if (fn(ctx, c.x(), c.y(), uint64_t(*it)) != 0)
                break;
        }
        return GDT_OK;
    } catch (const std::bad_alloc &) {
        return gdt_error_set(err, GDT_EINTERNAL, 7001, "out of memory reading %s", path);
    } catch (const std::exception &e) {
        return gdt_error_set(err, GDT_EINPUT, 3511, "%s: not a readable gdt-tile index: %s",
                             path, e.what());
    } catch (...) {
        return gdt_error_set(err, GDT_EINPUT, 3511, "%s: not a readable gdt-tile index", path);
    }
}
