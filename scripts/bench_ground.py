#!/usr/bin/env python3
"""bench_ground.py — what --ground pmf costs a tiled gdt-tile run.

  bench_ground.py [--build-dir DIR] [--points 10M] [--tile N] [--threads N]
                  [--repeat K] [--kind lidar] [--seed S] [--workdir DIR] [--keep]
                  [--json FILE] [-- extra --pmf-* options]

One LiDAR-like LAS cloud of --points records (scripts/gen_cloud.py, with
buildings and forest; not timed, reused from --workdir) goes through
    gdt-tile CLOUD.las --tile T --threads N -o OUT.ply -q --json J
without and with --ground pmf, in turn, --repeat rounds; each reports its best
wall time, its CPU time and its lowest peak RSS.  Printed beside them, from
the runs' --json:
  - the filter's wall time and its cost per point (wall and, since it runs on
    --threads workers, per thread), over the distinct points it classified;
  - the triangulation's cost per vertex (tile stage and merge) without and
    with the filter, which leaves fewer vertices;
  - the ratio of the two runs' wall times.
No targets: the figures are for the README and the project notes.  Memory figures are
MiB (2^20 bytes).

Exit status: 0; 2 usage or a missing program; 3 a program failed.
"""
import argparse
import json
import os
import pathlib
import shutil
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_e2e as be  # noqa: E402  (cloud generation, process measuring, size parsing)
import ground_eval as ge  # noqa: E402  (the pass-through of options after --)

ROOT = pathlib.Path(__file__).resolve().parents[1]


def main(argv=None):
    argv, extra = ge.split_extra(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build-dir", default=os.environ.get("GDT_BUILD_DIR", str(ROOT / "build")))
    ap.add_argument("--points", type=be.parse_size, default=10_000_000)
    ap.add_argument("--tile", type=be.positive_int, default=4096)
    ap.add_argument("--threads", type=be.positive_int, default=os.cpu_count() or 2)
    ap.add_argument("--repeat", type=be.positive_int, default=2)
    ap.add_argument("--kind", default="lidar")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workdir", default=None, help="keep and reuse the generated cloud here")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder")
    ap.add_argument("--json", default=None, help="write every figure to this JSON file")
    a = ap.parse_args(argv)
    tmp = None
    try:
        gdt = be.need_exe(pathlib.Path(a.build_dir) / "tiler" / "gdt-tile", "gdt-tile")
        tmp = pathlib.Path(tempfile.mkdtemp(prefix="gdt-ground-"))
        work = pathlib.Path(a.workdir) if a.workdir else tmp
        work.mkdir(parents=True, exist_ok=True)
        las = be.ensure_cloud(work, a.points, a)
        with open(las, "rb") as f:  # the LAS in the page cache
            while f.read(1 << 24):
                pass
        ply, js = tmp / "out.ply", tmp / "out.json"
        base = [gdt, las, "-o", ply, "-q", "--json", js, "--tile", a.tile, "--threads", a.threads]
        cmds = [("plain", base), ("--ground pmf", base + ["--ground", "pmf", *extra])]
        print(f"bench_ground: {be.size_label(a.points)} points, --tile {a.tile}, {a.threads} "
              f"threads, best of {a.repeat}", file=sys.stderr, flush=True)
        res = {name: None for name, _ in cmds}
        for k in range(a.repeat):
            for name, cmd in cmds:
                ply.unlink(missing_ok=True)
                shutil.rmtree(str(ply) + ".gdt-job", ignore_errors=True)
                log = str(tmp / f"run-{k}-{len(name)}")
                rc, wall, rss, cpu = be.run_measured(cmd, log)
                be.check_run(rc, cmd, log, "gdt-tile")
                s = json.loads(js.read_text())
                print(f"  {name} run {k + 1}/{a.repeat}: {wall:8.2f} s, CPU {cpu:8.2f} s, "
                      f"peak RSS {rss / 2**20:8.1f} MiB", file=sys.stderr, flush=True)
                r = res[name]
                if r is None or wall < r["wall_s"]:
                    res[name] = {"wall_s": wall, "cpu_s": cpu, "summary": s,
                                 "peak_rss_mb": min(rss, r["peak_rss_mb"] * 2**20
                                                    if r else rss) / 2**20}
                else:
                    r["peak_rss_mb"] = min(r["peak_rss_mb"], rss / 2**20)
        p, g = res["plain"], res["--ground pmf"]
        ps, gs = p["summary"], g["summary"]
        gd = gs["ground"]
        distinct = gd["ground_points"] + gd["nonground_points"]
        t_filter = gd["seconds"]
        tri_p = ps["times"]["tiles"] + ps["times"]["merge"]
        tri_g = gs["times"]["tiles"] + gs["times"]["merge"]
        out = {
            "points": a.points, "tile": a.tile, "threads": a.threads, "extra": extra,
            "plain": {k: p[k] for k in ("wall_s", "cpu_s", "peak_rss_mb")},
            "ground": {k: g[k] for k in ("wall_s", "cpu_s", "peak_rss_mb")},
            "distinct_points": distinct, "ground_points": gd["ground_points"],
            "filter_s": t_filter,
            "filter_ns_per_point": 1e9 * t_filter / distinct,
            "filter_thread_ns_per_point": 1e9 * t_filter * a.threads / distinct,
            "triangulation_ns_per_vertex_plain": 1e9 * tri_p / ps["vertices"],
            "triangulation_ns_per_vertex_ground": 1e9 * tri_g / max(1, gs["vertices"]),
            "wall_ratio": g["wall_s"] / p["wall_s"],
            "rss_ratio": g["peak_rss_mb"] / p["peak_rss_mb"],
        }
        print(f"\nbench_ground: {be.size_label(a.points)} points ({distinct} distinct), --tile "
              f"{a.tile}, {a.threads} threads")
        print(f"  {'run':<14} {'wall s':>8} {'CPU s':>8} {'RSS MiB':>8} {'vertices':>10}")
        for name, r, s in (("plain", p, ps), ("--ground pmf", g, gs)):
            print(f"  {name:<14} {r['wall_s']:8.2f} {r['cpu_s']:8.2f} {r['peak_rss_mb']:8.1f} "
                  f"{s['vertices']:10d}")
        print(f"  ground filter: {t_filter:.2f} s for {distinct} points: "
              f"{out['filter_ns_per_point']:.0f} ns/point wall, "
              f"{out['filter_thread_ns_per_point']:.0f} ns/point per thread; ground "
              f"{gd['ground_points']} ({100 * gd['ground_points'] / distinct:.1f} %)")
        print(f"  triangulation (tiles + merge): {out['triangulation_ns_per_vertex_plain']:.0f} "
              f"ns/vertex plain, {out['triangulation_ns_per_vertex_ground']:.0f} ns/vertex on "
              f"the ground points")
        print(f"  with/without --ground: time {out['wall_ratio']:.3f}, peak RSS "
              f"{out['rss_ratio']:.3f}")
        if a.json:
            pathlib.Path(a.json).write_text(json.dumps(out, indent=2) + "\n")
        return 0
    except be.BenchError as e:
        print(f"bench_ground: {e}", file=sys.stderr)
        return e.status
    finally:
        if tmp is not None and not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
