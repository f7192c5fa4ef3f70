#!/usr/bin/env python3
"""bench_tiler.py — throughput and peak memory of the out-of-core tiler.

  bench_tiler.py [--points 10000000 50000000] [--tile 1024] [--workdir DIR]
                 [--tiler-run PATH] [--rss-limit-mb 256] [--rss-spread 0.10]
                 [--kind lidar] [--seed 1] [--clean] [--json FILE]

For each size, generates a LAS file with gen_cloud.py (reused when the work
folder already holds one with that many points), then runs the tiler on it
in a fresh job folder through the test driver tiler_run (pass 1: index,
pass 2: spill files, the --dup merge, then every tile loaded with its halo)
and measures the child's wall time and peak RSS (wait4 rusage of exactly
that process).  Prints one table: points, file MB, the time and Mpts/s of
pass 1, pass 2, the merge and the tile loads, tiles, and peak RSS MB.

The job folder is removed after each run; the LAS files stay unless --clean.

Exit status: 0 ok; 1 a peak RSS reached --rss-limit-mb, or the peak RSS of
the sizes differ by --rss-spread or more (relative to the smallest); 2 usage;
3 the tiler failed.
"""
import argparse
import json
import os
import shutil
import struct
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GEN = os.path.join(ROOT, "scripts", "gen_cloud.py")


def las_points(path):
    """Point count of a LAS file from its header, or None."""
    try:
        with open(path, "rb") as f:
            h = f.read(255)
    except OSError:
        return None
    if len(h) < 227 or h[:4] != b"LASF":
        return None
    n = struct.unpack_from("<I", h, 107)[0]
    if h[25] >= 4 and len(h) >= 255:
        n = struct.unpack_from("<Q", h, 247)[0] or n
    return n


def run_measured(cmd, stdout_path):
    """Runs cmd; returns (exit code, wall seconds, peak RSS bytes, stderr tail)."""
    with open(stdout_path, "wb") as out:
        t0 = time.perf_counter()
        p = subprocess.Popen(cmd, stdout=out, stderr=subprocess.PIPE)
        err = p.stderr.read()
        _, status, ru = os.wait4(p.pid, 0)
        wall = time.perf_counter() - t0
        p.returncode = os.waitstatus_to_exitcode(status)
    return p.returncode, wall, ru.ru_maxrss * 1024, err.decode("utf-8", "replace")[-2000:]


def parse(stdout_path):
    res = {"plan": {}, "time": {}, "stats": {}}
    with open(stdout_path, "r", encoding="utf-8", errors="replace") as f:
        for line in f:
            head, _, rest = line.partition(" ")
            if head in res:
                for kv in rest.split():
                    k, _, v = kv.partition("=")
                    res[head][k] = float(v) if "." in v else int(v)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, nargs="+", default=[10_000_000, 50_000_000])
    ap.add_argument("--tile", type=int, default=1024)
    ap.add_argument("--workdir", default=os.path.join(ROOT, "build-bench-tiler"))
    ap.add_argument("--tiler-run", default=None,
                    help="tiler_run binary (default: $GDT_BUILD_DIR/tests/tiler_run, "
                         "else build/tests/tiler_run)")
    ap.add_argument("--rss-limit-mb", type=float, default=256.0)
    ap.add_argument("--rss-spread", type=float, default=0.10)
    ap.add_argument("--kind", default="lidar")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--clean", action="store_true", help="remove the LAS files at the end")
    ap.add_argument("--json", default=None, help="write the results as JSON")
    a = ap.parse_args(argv)

    exe = a.tiler_run or os.path.join(
        os.environ.get("GDT_BUILD_DIR", os.path.join(ROOT, "build")), "tests", "tiler_run")
    if not os.access(exe, os.X_OK):
        print(f"bench_tiler: {exe} not found (build the project, or give --tiler-run)",
              file=sys.stderr)
        return 2
    os.makedirs(a.workdir, exist_ok=True)
    rows = []
    for n in a.points:
        las = os.path.join(a.workdir, f"tiler-{a.kind}-{n}-s{a.seed}.las")
        if las_points(las) != n:
            print(f"generating {n} points into {las} ...", file=sys.stderr)
            r = subprocess.run([sys.executable, GEN, las, "--points", str(n), "--seed",
                                str(a.seed), "--kind", a.kind, "-q"])
            if r.returncode != 0:
                print("bench_tiler: gen_cloud.py failed", file=sys.stderr)
                return 3
        job = os.path.join(a.workdir, f"job-{n}")
        shutil.rmtree(job, ignore_errors=True)
        os.makedirs(job)
        out = os.path.join(a.workdir, f"tiler-run-{n}.txt")
        cmd = [exe, job, las, "--tile", str(a.tile), "--load-all"]
        print(f"running {' '.join(cmd)}", file=sys.stderr)
        rc, wall, rss, err = run_measured(cmd, out)
        shutil.rmtree(job, ignore_errors=True)
        if rc != 0:
            print(f"bench_tiler: tiler_run exited with {rc}:\n{err}", file=sys.stderr)
            return 3
        res = parse(out)
        t = res["time"]
        rows.append({"points": n, "file_mb": os.path.getsize(las) / 1e6, "wall": wall,
                     "pass1": t["pass1"], "pass2": t["pass2"], "merge": t["merge"],
                     "load": t["load"], "tiles": res["plan"].get("tiles"),
                     "cell": res["plan"].get("cell"), "halo": res["plan"].get("halo"),
                     "peak_rss_mb": rss / 1e6, "stats": res["stats"]})
        if a.clean:
            os.remove(las)

    def mpts(n, s):
        return n / s / 1e6 if s > 0 else float("inf")

    print(f"tiler benchmark: --tile {a.tile}, kind {a.kind}, seed {a.seed}")
    hdr = (f"{'points':>11} {'file MB':>8} {'pass1 s':>8} {'Mpts/s':>7} {'pass2 s':>8} "
           f"{'Mpts/s':>7} {'merge s':>8} {'Mpts/s':>7} {'load s':>7} {'tiles':>6} "
           f"{'cell':>5} {'halo':>5} {'wall s':>7} {'peak RSS MB':>12}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        n = r["points"]
        print(f"{n:>11} {r['file_mb']:>8.0f} {r['pass1']:>8.2f} {mpts(n, r['pass1']):>7.1f} "
              f"{r['pass2']:>8.2f} {mpts(n, r['pass2']):>7.1f} {r['merge']:>8.2f} "
              f"{mpts(n, r['merge']):>7.1f} {r['load']:>7.2f} {r['tiles']:>6} {r['cell']:>5} "
              f"{r['halo']:>5} {r['wall']:>7.1f} {r['peak_rss_mb']:>12.1f}")
    status = 0
    rss = [r["peak_rss_mb"] for r in rows]
    spread = (max(rss) - min(rss)) / min(rss) if rss else 0.0
    print(f"peak RSS spread across sizes: {100 * spread:.1f} % (limit {100 * a.rss_spread:.0f} %); "
          f"largest {max(rss):.1f} MB (limit {a.rss_limit_mb:.0f} MB)")
    if max(rss) >= a.rss_limit_mb:
        print("FAIL: peak RSS reached the limit", file=sys.stderr)
        status = 1
    if len(rss) > 1 and spread >= a.rss_spread:
        print("FAIL: peak RSS grows with the input size", file=sys.stderr)
        status = 1
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"tile": a.tile, "kind": a.kind, "seed": a.seed, "runs": rows,
                       "rss_spread": spread}, f, indent=1)
    return status


if __name__ == "__main__":
    sys.exit(main())
