#!/usr/bin/env python3
"""Checks a gdt-tile mesh exactly.

  validate_mesh.py MESH.ply [--input CLOUD.las|.pcd|.xyz ...] [--quantum Q]
                   [--chunk N] [--tmpdir DIR] [-v]
  validate_mesh.py TRIMMED.ply --trimmed-from FULL.ply [--max-edge L]
                   [--concavity L] [--input ...]

Recovers the lattice integers of every vertex from "comment lattice sx sy ox
oy" and checks, in exact integer arithmetic: valid CCW faces, edge-manifold
with consistent orientation, boundary = convex hull (collinear hull points
included), F = 2V - h - 2, no duplicate vertices, every interior edge locally
Delaunay with the Dyken-Floater tie-break (d1 = (1,0), d2 = (1,1)); with
--input, that the distinct (x, y) lattice points of the inputs are exactly the
vertices.  See gdtmesh/validate.py for the argument and the memory bound.

A mesh written with --max-edge or --concavity is no triangulation of its
vertices: check it against the untrimmed mesh of the same input with
--trimmed-from FULL.ply.  FULL is checked exactly as above; then the trimmed
mesh must have the same vertices and exactly the faces of FULL that the rules
keep, applied by brute force (the rules from TRIMMED's "comment trim" line
unless --max-edge/--concavity are given; see gdtmesh/trim.py, which holds
the faces in memory).

Prints one line: "OK: V vertices, F faces, h hull vertices, E interior edges
checked" or "FAIL: <counts and first example per kind of violation>".
Exit status: 0 valid, 1 violation, 2 usage (also: lon/lat input, which gdt-tile
projects before triangulating, cannot be compared), 3 unreadable mesh or input.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from gdtmesh.validate import EXIT_OK, validate  # noqa: E402


def positive_float(s):
    v = float(s)
    if not (v > 0 and v < float("inf")):
        raise argparse.ArgumentTypeError("must be a positive number")
    return v


def positive_int(s):
    v = int(s)
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="validate_mesh.py",
        description="Exact validity, Delaunay and tie-break check of a gdt-tile PLY mesh.",
        epilog="exit status: 0 valid, 1 violation, 2 usage, 3 unreadable mesh or input")
    ap.add_argument("mesh", help="binary little-endian PLY written by gdt-tile")
    ap.add_argument("--input", action="append", default=[], metavar="CLOUD",
                    help="input point cloud (LAS, PCD or XYZ text); repeat for several inputs, "
                         "which are one cloud")
    ap.add_argument("--quantum", type=positive_float, metavar="Q",
                    help="lattice step to assume (origin 0, 0) when the mesh has no "
                         "'comment lattice' line; must agree with it otherwise")
    ap.add_argument("--chunk", type=positive_int, default=1 << 20, metavar="N",
                    help="records per processing chunk; memory grows linearly with it "
                         "(default 1048576)")
    ap.add_argument("--tmpdir", metavar="DIR",
                    help="directory for temporary bucket files (default: the system's)")
    ap.add_argument("--trimmed-from", metavar="FULL.ply",
                    help="MESH is trimmed (--max-edge, --concavity): check it against this "
                         "untrimmed mesh of the same input")
    ap.add_argument("--max-edge", type=positive_float, metavar="L",
                    help="with --trimmed-from: the --max-edge rule (default: MESH's comment)")
    ap.add_argument("--concavity", type=positive_float, metavar="L",
                    help="with --trimmed-from: the --concavity rule (default: MESH's comment)")
    ap.add_argument("-v", "--verbose", action="store_true",
                    help="progress and predicate statistics on stderr")
    args = ap.parse_args(argv)
    if (args.max_edge or args.concavity) and not args.trimmed_from:
        ap.error("--max-edge and --concavity go with --trimmed-from")
    full = args.trimmed_from or args.mesh
    code, line = validate(full, args.input, args.quantum, args.chunk, args.tmpdir,
                          log=sys.stderr if args.verbose else None)
    if code == EXIT_OK and args.trimmed_from:
        from gdtmesh.ply import MeshFileError
        from gdtmesh.trim import check_trimmed
        try:
            code, line = check_trimmed(args.mesh, full, args.max_edge, args.concavity)
        except (MeshFileError, ValueError) as e:
            code, line = 3, f"FAIL: {e}"
    elif args.trimmed_from:
        line = f"{line} (in the untrimmed mesh {full})"
    print(line, file=sys.stdout if code in (EXIT_OK, 1) else sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
