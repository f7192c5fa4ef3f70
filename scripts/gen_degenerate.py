#!/usr/bin/env python3
"""Writes a seeded degenerate point cloud for tests and experiments.

  gen_degenerate.py KIND OUT [--n N] [--seed S] [--format las|pcd|xyz]
                    [--scale S] [--offset OX OY]

KIND is one of: grid, rotgrid, circle, thincircle, collinear, duplicates,
clusters, one, two, three, extreme, sparse, uniform, mixed (see
gdtmesh/degenerate.py for what each one promises).  Points are generated as
lattice integers; the file stores x = offset + scale * integer:
  las  LAS 1.2, point format 0, the integers as the X/Y/Z records
       (scale S for x, y and z; default 0.001; offset default 0, 0, 0)
  pcd  PCD 0.7 binary, x y z as F8 (doubles); with the default scale these
       snap back to the same integers at gdt-tile's default --quantum 0.001
  xyz  "x y z" text lines, exact decimals when S is a power of ten
The output is a pure function of (KIND, N, SEED, format, scale, offset).
Prints one line: "wrote P points (KIND, seed S) to OUT".
Exit status: 0 written, 2 usage, 4 the file cannot be written.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from gdtmesh import cloudio, degenerate  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(prog="gen_degenerate.py",
                                 description="Write a seeded degenerate point cloud.")
    ap.add_argument("kind", choices=degenerate.KINDS)
    ap.add_argument("out")
    ap.add_argument("--n", type=int, default=1000, help="number of points (default 1000; "
                    "'one', 'two', 'three' fix it, 'circle' caps it at 6804)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--format", choices=("las", "pcd", "xyz"), default=None,
                    help="default: from the extension of OUT, else las")
    ap.add_argument("--scale", type=float, default=0.001, help="lattice step in CRS units (default 0.001)")
    ap.add_argument("--offset", type=float, nargs=2, default=(0.0, 0.0), metavar=("OX", "OY"))
    args = ap.parse_args(argv)
    if args.n < 1:
        ap.error("--n must be >= 1")
    if not args.scale > 0:
        ap.error("--scale must be positive")
    fmt = args.format
    if fmt is None:
        ext = os.path.splitext(args.out)[1].lower().lstrip(".")
        fmt = ext if ext in ("las", "pcd", "xyz") else "las"
    X, Y, Z = degenerate.make(args.kind, args.n, args.seed, scale_z=args.scale)
    scale = (args.scale, args.scale, args.scale)
    offset = (args.offset[0], args.offset[1], 0.0)
    try:
        if fmt == "las":
            cloudio.write_las(args.out, X, Y, Z, scale, offset)
        elif fmt == "pcd":
            cloudio.write_pcd(args.out, offset[0] + scale[0] * X.astype(float),
                              offset[1] + scale[1] * Y.astype(float), scale[2] * Z.astype(float))
        else:
            cloudio.write_xyz(args.out, X, Y, Z, scale, offset)
    except ValueError as e:
        print("gen_degenerate.py: error: %s" % e, file=sys.stderr)
        return 2
    except OSError as e:
        print("gen_degenerate.py: error: %s: %s" % (args.out, e.strerror or e), file=sys.stderr)
        return 4
    print("wrote %d points (%s, seed %d) to %s" % (X.shape[0], args.kind, args.seed, args.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
