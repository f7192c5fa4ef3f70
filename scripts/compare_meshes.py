#!/usr/bin/env python3
"""Compares two meshes as canonical triangle sets in lattice integers.

  compare_meshes.py A.ply B.ply [--quantum Q] [--chunk N] [--tmpdir DIR]

Each triangle is rotated to start at its smallest vertex (x, then y; the
orientation is kept) and the two multisets are compared, as are the vertex
lattice points; vertex order, face order and rotation do not matter.
Prints "EQUAL: ..." or "DIFFERENT: counts" followed by a few examples.
Exit status: 0 equal, 1 different, 2 usage (including incompatible
lattices), 3 unreadable mesh.
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from gdtmesh.compare import EXIT_DIFFERENT, EXIT_EQUAL, compare  # noqa: E402


def positive(kind):
    def conv(s):
        v = kind(s)
        if not v > 0:
            raise argparse.ArgumentTypeError("must be positive")
        return v
    return conv


def main(argv=None):
    ap = argparse.ArgumentParser(
        prog="compare_meshes.py",
        description="Compare two gdt-tile meshes as canonical triangle sets.",
        epilog="exit status: 0 equal, 1 different, 2 usage, 3 unreadable mesh")
    ap.add_argument("a", help="first mesh (PLY)")
    ap.add_argument("b", help="second mesh (PLY)")
    ap.add_argument("--quantum", type=positive(float), metavar="Q",
                    help="lattice step to assume (origin 0, 0) for a mesh without a lattice comment")
    ap.add_argument("--chunk", type=positive(int), default=1 << 20, metavar="N",
                    help="records per processing chunk (default 1048576)")
    ap.add_argument("--tmpdir", metavar="DIR", help="directory for temporary bucket files")
    args = ap.parse_args(argv)
    code, lines = compare(args.a, args.b, args.quantum, args.chunk, args.tmpdir)
    out = sys.stdout if code in (EXIT_EQUAL, EXIT_DIFFERENT) else sys.stderr
    try:
        for ln in lines:
            print(ln, file=out)
        out.flush()
    except BrokenPipeError:
        # The reader went away (e.g. "| head"); the verdict is the exit status.
        os.dup2(os.open(os.devnull, os.O_WRONLY), out.fileno())
    return code


if __name__ == "__main__":
    sys.exit(main())
