#!/usr/bin/env python3
"""gen_cloud.py — writes a synthetic, LiDAR-like LAS point cloud.

  gen_cloud.py OUT.las --points N [--seed S] [--kind lidar|grid|uniform|dem|mixed]
               [--las-version 1.1|1.2|1.3|1.4] [--point-format F] [--scale 0.01]
               [--offset X Y] [--epsg 26910] [--crs auto|geotiff|wkt]
               [--extent W H | --density D] [--chunk K] [--describe FILE.json]

Kinds:
  lidar    airborne survey: overlapping zig-zag scan strips and cross strips
           over a hilly terrain, lakes without returns, buildings and forest
           (multiple returns at identical X/Y with distinct Z), gridded DEM
           patches on the exact lattice, a few duplicated records and noise
  grid     one square lattice grid, row by row
  uniform  independent uniform points on the lattice
  dem      four gridded DEM tiles, two axis-aligned and two rotated
  mixed    a survey over the western 60 %, grid/uniform/dem bands in the east

All points are on the LAS integer lattice.  The output is a pure function of
the parameters and the seed: --chunk (points evaluated per step, which bounds
memory) does not change a single byte.  Needs only numpy.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from lasgen.cloud import KINDS, generate  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="output LAS file")
    ap.add_argument("--points", type=int, required=True, help="exact number of points")
    ap.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    ap.add_argument("--kind", choices=KINDS, default="lidar", help="cloud kind (default lidar)")
    ap.add_argument("--las-version", default="1.2", choices=["1.1", "1.2", "1.3", "1.4"],
                    help="LAS version (default 1.2)")
    ap.add_argument("--point-format", type=int, default=None,
                    help="point data format (default 3; 1 for LAS 1.1; 6 for LAS 1.4)")
    ap.add_argument("--scale", type=float, default=0.01, help="x/y/z scale (default 0.01)")
    ap.add_argument("--offset", type=float, nargs=2, default=(480000.0, 4860000.0),
                    metavar=("X", "Y"), help="x/y offset = south-west corner (default UTM 10N)")
    ap.add_argument("--epsg", type=int, default=26910,
                    help="projected CRS code (default 26910, NAD83 / UTM 10N; 0 = none)")
    ap.add_argument("--crs", choices=["auto", "geotiff", "wkt"], default="auto",
                    help="CRS record: GeoKeys, or WKT (auto: WKT for formats 6-10)")
    ap.add_argument("--extent", type=float, nargs=2, default=None, metavar=("W", "H"),
                    help="width and height in CRS units (default from --density)")
    ap.add_argument("--density", type=float, default=8.0,
                    help="points per square unit when --extent is not given (default 8)")
    ap.add_argument("--chunk", type=int, default=1 << 16,
                    help="pulses/points per step (memory bound; no effect on the output)")
    ap.add_argument("--dem-fraction", type=float, default=0.04,
                    help="lidar: share of points in gridded DEM patches (default 0.04)")
    ap.add_argument("--dup-fraction", type=float, default=0.002,
                    help="lidar: share of pulses recorded twice (default 0.002)")
    ap.add_argument("--describe", default=None, help="write the layout and counts as JSON")
    ap.add_argument("-q", "--quiet", action="store_true", help="no summary on stderr")
    a = ap.parse_args(argv)
    try:
        s = generate(a.out, a.points, seed=a.seed, kind=a.kind, version=a.las_version,
                     fmt=a.point_format, scale=a.scale, offset=a.offset, epsg=a.epsg,
                     crs=a.crs, extent=a.extent, density=a.density, chunk=a.chunk,
                     dem_fraction=a.dem_fraction, dup_fraction=a.dup_fraction,
                     describe=a.describe)
    except (ValueError, OSError) as e:
        print("gen_cloud: %s" % e, file=sys.stderr)
        return 2
    if not a.quiet:
        mb = s["bytes"] / 1e6
        rate = s["points"] / s["seconds"] / 1e6 if s["seconds"] > 0 else 0.0
        print("gen_cloud: %s: %d points (%s, LAS %s format %d), %.1f MB in %.2f s "
              "(%.2f Mpts/s, %.0f MB/s)" % (a.out, s["points"], a.kind, s["las_version"],
                                            s["point_format"], mb, s["seconds"], rate,
                                            mb / s["seconds"] if s["seconds"] > 0 else 0.0),
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
