// tiler_vdb_dump — reads a gdt-tile index.vdb with OpenVDB's own API
// (openvdb::io::File), independently of the tiler's code, and prints:
//   grid NAME voxels N leaves L           for every grid in the file
//   meta GRID NAME VALUE                  for every metadata item "gdt_*"
//   xform GRID SIZE X Y                   voxel size and the world position of
//                                         voxel (0, 0, 0)'s centre
//   tile CI CJ COUNT                      every active voxel of "tile_points"
//   density VX VY COUNT                   every active voxel of "density" (with --density)
// Exit status: 0 ok, 3 the file cannot be read or lacks a grid, 2 usage.
#include <openvdb/io/File.h>
#include <openvdb/openvdb.h>

#include <cstdio>
#include <cstring>
#include <exception>
#include <string>

static void print_meta(const openvdb::GridBase &g)
{
    for (openvdb::MetaMap::ConstMetaIterator it = g.beginMeta(); it != g.endMeta(); ++it) {
        if (it->first.compare(0, 4, "gdt_") != 0)
            continue;
        std::printf("meta %s %s %s\n", g.getName().c_str(), it->first.c_str(),
                    it->second->str().c_str());
    }
}

static int dump(const openvdb::Int64Grid &g, const char *tag)
{
    for (openvdb::Int64Grid::ValueOnCIter it = g.cbeginValueOn(); it; ++it) {
        if (!it.isVoxelValue())
            return 3;
        openvdb::Coord c = it.getCoord();
        std::printf("%s %d %d %lld\n", tag, c.x(), c.y(), (long long)*it);
    }
    return 0;
}

int main(int argc, char **argv)
{
    if (argc < 2 || argc > 3 || (argc == 3 && std::strcmp(argv[2], "--density") != 0)) {
        std::fprintf(stderr, "usage: tiler_vdb_dump INDEX.vdb [--density]\n");
        return 2;
    }
    try {
        openvdb::initialize();
        openvdb::io::File file(argv[1]);
        file.open();
        openvdb::GridPtrVecPtr grids = file.getGrids();
        file.close();
        openvdb::Int64Grid::Ptr tiles, density;
        for (const openvdb::GridBase::Ptr &g : *grids) {
            std::printf("grid %s voxels %llu leaves %llu\n", g->getName().c_str(),
                        (unsigned long long)g->activeVoxelCount(),
                        (unsigned long long)g->baseTree().leafCount());
            print_meta(*g);
            {
                const openvdb::math::Transform &xf = g->transform();
                openvdb::Vec3d o = xf.indexToWorld(openvdb::Vec3d(0.0, 0.0, 0.0));
                std::printf("xform %s %.17g %.17g %.17g\n", g->getName().c_str(),
                            xf.voxelSize()[0], o[0], o[1]);
            }
            if (g->getName() == "tile_points")
                tiles = openvdb::gridPtrCast<openvdb::Int64Grid>(g);
            else if (g->getName() == "density")
                density = openvdb::gridPtrCast<openvdb::Int64Grid>(g);
        }
        if (!tiles || !density) {
            std::fprintf(stderr, "%s: int64 grids tile_points and density expected\n", argv[1]);
            return 3;
        }
        if (dump(*tiles, "tile") != 0)
            return 3;
        if (argc == 3 && dump(*density, "density") != 0)
            return 3;
        return 0;
    } catch (const std::exception &e) {
        std::fprintf(stderr, "%s: %s\n", argv[1], e.what());
        return 3;
    }
}
