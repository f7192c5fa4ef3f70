#!/usr/bin/env python3
"""bench_core.py — the per-tile OpenCL core against CGAL's Delaunay triangulation.

  bench_core.py [--build-dir DIR] [--sizes 1M,4M] [--kinds uniform,lidar,grid]
                [--repeat K] [--device SPEC] [--workdir DIR] [--json FILE]

For every kind and size, one LiDAR-like (or uniform, or gridded) LAS cloud is
generated with scripts/gen_cloud.py, read once by gcd_run (duplicates merged,
tile-local coordinates), and the same point set is triangulated by
  - the core (gdt_core_triangulate on one tile of N x N texels, N = 2048 for
    about 1M points and 4096 for about 4M: a tile holds about N^2/4 points),
  - CGAL::Delaunay_triangulation_2 (Epick), single-threaded (tests/tools/cgal_bench).
Both times cover the triangulation only (best of --repeat runs; the core's
includes moving the points to the device and the triangles back).  The
table gives both times, the ratio CGAL / core (above 1: the core is faster),
and the core's per-phase breakdown (Fig. 11 of the gCD paper) with its
counts.  Needs the build targets gcd_run and cgal_bench (CGAL installed:
libcgal-dev), and numpy for the generator.
"""
import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[1]
KIND_TO_GEN = {"uniform": "uniform", "lidar": "lidar", "grid": "grid"}


def parse_size(s):
    s = s.strip().upper()
    mult = 1
    if s.endswith("M"):
        mult, s = 1000000, s[:-1]
    elif s.endswith("K"):
        mult, s = 1000, s[:-1]
    return int(float(s) * mult)


def grid_for(points):
    n = 256
    while n * n // 4 < points and n < 16384:
        n *= 2
    return n


def run(cmd, **kw):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    if r.returncode != 0:
        sys.exit(f"bench_core: {' '.join(map(str, cmd))} failed ({r.returncode}):\n{r.stderr}")
    return r.stdout


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--build-dir", default=os.environ.get("GDT_BUILD_DIR", str(ROOT / "build")))
    ap.add_argument("--sizes", default="1M,4M")
    ap.add_argument("--kinds", default="uniform,lidar,grid")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--device", default=None)
    ap.add_argument("--workdir", default=None, help="keep generated files here")
    ap.add_argument("--json", default=None, help="also write the results as JSON")
    args = ap.parse_args(argv)

    tools = pathlib.Path(args.build_dir) / "tests"
    gcd_run, cgal = tools / "gcd_run", tools / "cgal_bench"
    for exe in (gcd_run, cgal):
        if not exe.exists():
            sys.exit(f"bench_core: {exe} not built (targets gcd_run, cgal_bench)")
    tmp = None
    if args.workdir:
        work = pathlib.Path(args.workdir)
        work.mkdir(parents=True, exist_ok=True)
    else:
        tmp = tempfile.TemporaryDirectory(prefix="gdt-bench-")
        work = pathlib.Path(tmp.name)

    results = []
    for size in [parse_size(s) for s in args.sizes.split(",")]:
        for kind in args.kinds.split(","):
            las = work / f"{kind}-{size}.las"
            pts = work / f"{kind}-{size}.pts"
            if not las.exists():
                run([sys.executable, ROOT / "scripts" / "gen_cloud.py", las, "--points", size,
                     "--kind", KIND_TO_GEN[kind], "--seed", 1])
            grid = grid_for(size)
            cmd = [gcd_run, "--cloud", las, "--grid", grid, "--repeat", args.repeat, "--json",
                   "--dump-points", pts]
            if args.device:
                cmd += ["--device", args.device]
            core = json.loads(run(cmd))
            cg = json.loads(run([cgal, pts, "--repeat", args.repeat]))
            res = {"kind": kind, "size": size, "points": core["points"], "grid": grid,
                   "core": core, "cgal": cg,
                   "speedup": cg["seconds"] / core["times_s"]["total"]}
            results.append(res)
            t = core["times_s"]
            print(f"{kind:8s} {core['points']:9d} pts grid {grid:5d}: core {t['total']:7.3f}s "
                  f"({core['path']}), CGAL {cg['seconds']:7.3f}s, CGAL/core "
                  f"{res['speedup']:5.2f}x", flush=True)
            print(f"{'':8s} phases: upload {t['upload']:.3f}  1 voronoi {t['phase1']:.3f}  "
                  f"2 dual {t['phase2']:.3f}  3 shift {t['phase3']:.3f}  4 insert "
                  f"{t['phase4']:.3f}  5 flip {t['phase5']:.3f}  download {t['download']:.3f}",
                  flush=True)
            print(f"{'':8s} missing {core['missing_phase1']}, bad cases {core['bad_cases']}, "
                  f"flips {core['flips']} ({core['flip_iterations']} rounds), exact "
                  f"{core['exact_escalations']}, faces {core['triangles']} (CGAL "
                  f"{cg['faces']})", flush=True)
    print(f"\ndevice: {results[0]['core']['device'] if results else '-'}")
    print(f"{'kind':8s} {'points':>9s} {'core s':>8s} {'CGAL s':>8s} {'CGAL/core':>9s}")
    for r in results:
        print(f"{r['kind']:8s} {r['points']:9d} {r['core']['times_s']['total']:8.3f} "
              f"{r['cgal']['seconds']:8.3f} {r['speedup']:9.2f}")
    if args.json:
        pathlib.Path(args.json).write_text(json.dumps(results, indent=2))
    if tmp is not None:
        tmp.cleanup()
    return 0


if __name__ == "__main__":
    sys.exit(main())
