#!/usr/bin/env python3
"""bench_e2e.py — gdt-tile end to end (LAS in, PLY out) against CGAL's in-memory Delaunay.

  bench_e2e.py [--build-dir DIR] [--sizes 10M,50M] [--tile N] [--device SPEC]
               [--repeat K] [--kind lidar] [--seed S] [--workdir DIR] [--keep]
               [--cgal-size SIZE | --no-cgal] [--validate] [--gdt-args "..."]
               [--target-speedup 1.5] [--target-rss-ratio 1.10] [--json FILE]

For every size, a LiDAR-like LAS cloud is generated with scripts/gen_cloud.py
(not timed; reused from --workdir when it already holds one with that many
points), then
    gdt-tile CLOUD.las --tile N -o OUT.ply --json S.json [--device SPEC]
runs --repeat times.  The wall time covers the whole process (reading the
LAS, the tiled pipeline, writing the PLY); the best run counts.  The peak
RSS is the child's own ru_maxrss (os.wait4), the largest over the repeats;
its CPU time (user + system, all threads) is printed beside the wall time.
Mpts/s is input records per second of the best wall time.  The per-stage
times (core and post are parts of tiles), the tile count and the certified
fraction come from the run's --json summary (best run).  The LAS is in the page cache when the timing starts.

At the CGAL size (default: the smallest size), the distinct points of the
same cloud, duplicates merged and in input order, exactly as bench_core.py
feeds them (tests/tools/gcd_run --cloud --dump-points; not timed), are
triangulated by CGAL::Delaunay_triangulation_2 (tests/tools/cgal_bench),
--repeat times, one process per run.  Reported: the triangulation time
(cgal_bench's own clock, best run) and the process wall time, which adds
reading the points file (best run), with the peak RSS.  Memory figures are
MiB (2^20 bytes).

Targets, each reported PASS or MISS:
  speedup    CGAL triangulation time / gdt-tile wall time at the CGAL size
             >= --target-speedup (the ratio with CGAL's process time is
             printed as well);
  RSS ratio  peak RSS at the largest size / peak RSS at the smallest size
             <= --target-rss-ratio.
--validate checks the CGAL-size output exactly with scripts/validate_mesh.py
(with --input, so the vertex set is compared with the cloud as well).

Outputs (PLY, summaries, job folders) are deleted after each size; without
--workdir everything lives in a temporary folder removed at the end; --keep
keeps all of it.  Needs the build targets gdt-tile, gcd_run and cgal_bench
(CGAL: libcgal-dev; --no-cgal skips it), and numpy for the generator.

Exit status: 0 every run succeeded and every target was met; 1 a target was
missed or the validation failed; 2 usage or a missing program; 3 a program
failed (its exit status and the tail of its stderr are printed).
"""
import argparse
import json
import os
import pathlib
import shlex
import shutil
import struct
import subprocess
import sys
import tempfile
import time

ROOT = pathlib.Path(__file__).resolve().parents[1]
GEN = ROOT / "scripts" / "gen_cloud.py"
VALIDATE = ROOT / "scripts" / "validate_mesh.py"
# "core" (the OpenCL triangulation) and "post" (the previous tile's certification, seam,
# face sort and tile file, beside it) are both inside "tiles"
STAGES = ("pass1", "pass2", "tiles", "core", "post", "merge", "write", "total")
# Disk use per input record, for the free-space warning: LAS point format 3
# (34 bytes), the PLY (about 2 faces per vertex) and the job folder's spills.
LAS_BYTES_PER_POINT = 34
RUN_BYTES_PER_POINT = 120


class BenchError(Exception):
    """A failure with its exit status (2 usage or missing program, 3 a program failed)."""

    def __init__(self, status, message):
        super().__init__(message)
        self.status = status


def parse_size(s):
    t = s.strip().upper()
    mult = 1
    if t.endswith("M"):
        mult, t = 1000000, t[:-1]
    elif t.endswith("K"):
        mult, t = 1000, t[:-1]
    try:
        v = int(round(float(t) * mult))
    except ValueError:
        raise argparse.ArgumentTypeError(f"bad size {s!r} (e.g. 500K, 10M, 2000000)")
    if v < 1:
        raise argparse.ArgumentTypeError(f"bad size {s!r}: must be at least 1 point")
    return v


def size_list(s):
    sizes = [parse_size(x) for x in s.split(",") if x.strip()]
    if not sizes:
        raise argparse.ArgumentTypeError("no sizes given")
    if len(set(sizes)) != len(sizes):
        raise argparse.ArgumentTypeError("a size is listed twice")
    return sizes


def size_label(n):
    if n % 1000000 == 0:
        return f"{n // 1000000}M"
    if n % 1000 == 0:
        return f"{n // 1000}K"
    return str(n)


def positive_int(s):
    v = int(s)
    if v < 1:
        raise argparse.ArgumentTypeError("must be >= 1")
    return v


def grid_for(points):
    """The single-tile grid gcd_run needs for `points` points (a tile holds about N^2/4)."""
    n = 256
    while n * n // 4 < points and n < 16384:
        n *= 2
    return n


def las_points(path):
    """Point count from a LAS header, or None when the file is absent or not LAS."""
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


def pts_count(path):
    """Point count of a complete GDTPTS1 points file, or None."""
    try:
        size = os.path.getsize(path)
        with open(path, "rb") as f:
            h = f.read(16)
    except OSError:
        return None
    if len(h) != 16 or h[:8] != b"GDTPTS1\n":
        return None
    n = struct.unpack_from("<Q", h, 8)[0]
    return n if size == 16 + 16 * n else None


def tail(path, limit=2000):
    try:
        with open(path, "rb") as f:
            f.seek(0, os.SEEK_END)
            f.seek(max(0, f.tell() - limit))
            return f.read().decode("utf-8", "replace").strip()
    except OSError:
        return ""


# The measured program is started by this small launcher, not by the
# benchmark's own process: Linux carries a process's peak RSS across fork and
# exec into the child's ru_maxrss, so a child forked from a benchmark holding
# a large subset in memory would report the benchmark's peak, not its own.
# The launcher (a bare interpreter, a few MiB) forks and execs the program,
# waits for exactly it and writes "rc maxrss_kib cpu_s" to the descriptor
# named by its first argument, which the program does not inherit.
_LAUNCHER = r"""
import os, sys
fd = int(sys.argv[1])
pid = os.fork()
if pid == 0:
    os.close(fd)
    try:
        os.execvp(sys.argv[2], sys.argv[2:])
    except OSError as e:
        os.write(2, ("cannot start %s: %s\n" % (sys.argv[2], e)).encode())
        os._exit(127)
_, status, ru = os.wait4(pid, 0)
os.write(fd, ("%d %d %r" % (os.waitstatus_to_exitcode(status), ru.ru_maxrss,
                            ru.ru_utime + ru.ru_stime)).encode())
"""


def run_measured(cmd, log_prefix):
    """Runs cmd with stdout/stderr in log files.

    returns: (exit status, wall seconds, peak RSS bytes and CPU seconds (user +
    system, all its threads) of exactly that program)."""
    cmd = [str(c) for c in cmd]
    rfd, wfd = os.pipe()
    try:
        with open(f"{log_prefix}.out", "wb") as out, open(f"{log_prefix}.err", "wb") as err:
            t0 = time.perf_counter()
            try:
                p = subprocess.Popen([sys.executable, "-S", "-c", _LAUNCHER, str(wfd), *cmd],
                                     stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                     pass_fds=(wfd,))
            except OSError as e:
                raise BenchError(2, f"cannot start {cmd[0]}: {e}")
            os.close(wfd)
            wfd = -1
            report = b""
            while True:
                chunk = os.read(rfd, 256)
                if not chunk:
                    break
                report += chunk
            p.wait()
            wall = time.perf_counter() - t0
    finally:
        os.close(rfd)
        if wfd >= 0:
            os.close(wfd)
    fields = report.decode(errors="replace").split()
    if p.returncode != 0 or len(fields) != 3:
        raise BenchError(2, f"cannot start {cmd[0]} (see {log_prefix}.err)")
    rc = int(fields[0])
    if rc == 127 and b"cannot start" in pathlib.Path(f"{log_prefix}.err").read_bytes()[-300:]:
        raise BenchError(2, f"cannot start {cmd[0]}")
    # Linux reports ru_maxrss in KiB.
    return rc, wall, int(fields[1]) * 1024, float(fields[2])


def check_run(rc, cmd, log_prefix, what):
    if rc != 0:
        raise BenchError(3, f"{what} failed (exit status {rc}): {' '.join(map(str, cmd))}\n"
                            f"{tail(f'{log_prefix}.err')}")


def need_exe(path, target):
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise BenchError(2, f"{path} not found (build the target {target}, or give --build-dir)")
    return path


def warn_space(folder, need, what):
    free = shutil.disk_usage(folder).free
    if free < need:
        print(f"bench_e2e: warning: {folder} has {free / 1e9:.1f} GB free, {what} needs about "
              f"{need / 1e9:.1f} GB", file=sys.stderr)


def ensure_cloud(work, n, a):
    """The LAS file of n points (kind, seed) in work; generated unless already there."""
    las = work / f"e2e-{a.kind}-{n}-s{a.seed}.las"
    if las_points(las) == n:
        return las
    warn_space(work, LAS_BYTES_PER_POINT * n, f"a {size_label(n)} cloud")
    print(f"bench_e2e: generating {size_label(n)} points into {las} ...", file=sys.stderr,
          flush=True)
    part = las.with_name(las.name + ".part")
    cmd = [sys.executable, GEN, part, "--points", n, "--seed", a.seed, "--kind", a.kind, "-q"]
    rc, _, _, _ = run_measured(cmd, str(part))
    check_run(rc, cmd, str(part), "gen_cloud.py")
    os.replace(part, las)
    for ext in (".out", ".err"):
        pathlib.Path(f"{part}{ext}").unlink(missing_ok=True)
    return las


def ensure_points(work, las, n, gcd_run, a):
    """The distinct points of las as a GDTPTS1 file (gcd_run --cloud --dump-points)."""
    pts = las.with_suffix(".pts")
    if pts_count(pts) is not None and pts.stat().st_mtime >= las.stat().st_mtime:
        return pts
    print(f"bench_e2e: extracting the distinct points of {las.name} (gcd_run) ...",
          file=sys.stderr, flush=True)
    part = pts.with_name(pts.name + ".part")
    cmd = [gcd_run, "--cloud", las, "--grid", grid_for(n), "--json", "--dump-points", part]
    if a.device:
        cmd += ["--device", a.device]
    rc, _, _, _ = run_measured(cmd, str(part))
    check_run(rc, cmd, str(part), "gcd_run")
    if pts_count(part) is None:
        raise BenchError(3, f"gcd_run wrote an incomplete points file {part}")
    os.replace(part, pts)
    for ext in (".out", ".err"):
        pathlib.Path(f"{part}{ext}").unlink(missing_ok=True)
    return pts


def bench_gdt(gdt, las, n, run_dir, a):
    """Runs gdt-tile --repeat times on las; returns the figures of this size."""
    warn_space(run_dir, RUN_BYTES_PER_POINT * n, f"a {size_label(n)} run")
    out, summ = run_dir / "out.ply", run_dir / "summary.json"
    job = run_dir / "out.ply.gdt-job"  # gdt-tile's default job folder
    runs, best = [], None
    for k in range(a.repeat):
        for p in (out, summ):
            p.unlink(missing_ok=True)
        shutil.rmtree(job, ignore_errors=True)
        cmd = [gdt, las, "--tile", a.tile, "-o", out, "--json", summ]
        if a.device:
            cmd += ["--device", a.device]
        cmd += shlex.split(a.gdt_args)
        log = str(run_dir / f"gdt-tile-{k}")
        rc, wall, rss, cpu = run_measured(cmd, log)
        check_run(rc, cmd, log, "gdt-tile")
        try:
            summary = json.loads(summ.read_text())
        except (OSError, ValueError) as e:
            raise BenchError(3, f"gdt-tile wrote no readable --json summary {summ}: {e}")
        runs.append({"wall_s": wall, "cpu_s": cpu, "peak_rss_bytes": rss, "summary": summary})
        print(f"  {size_label(n):>5} run {k + 1}/{a.repeat}: {wall:8.2f} s, CPU {cpu:8.2f} s, "
              f"peak RSS {rss / 2**20:8.1f} MiB", file=sys.stderr, flush=True)
        if best is None or wall < best["wall_s"]:
            best = runs[-1]
    s = best["summary"]
    times = s.get("times") if isinstance(s.get("times"), dict) else {}
    return {
        "size": n, "las": str(las), "las_mb": las.stat().st_size / 1e6,
        "wall_s": best["wall_s"], "cpu_s": best["cpu_s"], "mpts_s": n / best["wall_s"] / 1e6,
        "peak_rss_bytes": max(r["peak_rss_bytes"] for r in runs),
        "peak_rss_mb": max(r["peak_rss_bytes"] for r in runs) / 2**20,
        "times": times, "tiles": s.get("tiles"), "vertices": s.get("vertices"),
        "faces": s.get("faces"), "certified_fraction": s.get("certified_fraction"),
        "device": s.get("device"), "runs": runs, "output": str(out),
    }


def bench_cgal(cgal, pts, run_dir, a):
    """cgal_bench --repeat times (one process each) on the points file."""
    runs = []
    for k in range(a.repeat):
        cmd = [cgal, pts]
        log = str(run_dir / f"cgal-{k}")
        rc, wall, rss, cpu = run_measured(cmd, log)
        check_run(rc, cmd, log, "cgal_bench")
        try:
            r = json.loads(pathlib.Path(f"{log}.out").read_text())
            if not all(isinstance(r.get(k), (int, float))
                       for k in ("points", "vertices", "faces", "seconds")):
                raise ValueError("missing points, vertices, faces or seconds")
        except (OSError, ValueError, AttributeError) as e:
            raise BenchError(3, f"cgal_bench printed no usable JSON object: {e}")
        r.update(process_s=wall, process_cpu_s=cpu, peak_rss_bytes=rss)
        runs.append(r)
        print(f"  CGAL run {k + 1}/{a.repeat}: triangulation {r['seconds']:.2f} s, process "
              f"{wall:.2f} s, peak RSS {rss / 2**20:.1f} MiB", file=sys.stderr, flush=True)
    return {"points": runs[0]["points"], "vertices": runs[0]["vertices"],
            "faces": runs[0]["faces"], "seconds": min(r["seconds"] for r in runs),
            "process_s": min(r["process_s"] for r in runs),
            "process_cpu_s": min(r["process_cpu_s"] for r in runs),
            "peak_rss_mb": max(r["peak_rss_bytes"] for r in runs) / 2**20, "runs": runs}


def validate(ply, las, run_dir):
    """validate_mesh.py on the output; returns its exit status, time and verdict line."""
    cmd = [str(c) for c in (sys.executable, VALIDATE, ply, "--input", las, "--tmpdir", run_dir)]
    print(f"bench_e2e: validating {ply} ...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if r.returncode not in (0, 1):
        raise BenchError(3, f"validate_mesh.py failed (exit status {r.returncode}): "
                            f"{' '.join(cmd)}\n{r.stderr[-2000:]}")
    lines = (r.stdout.strip() or r.stderr.strip()).splitlines()
    return {"exit": r.returncode, "seconds": seconds, "message": lines[-1] if lines else ""}


def fmt(v, spec, width):
    return f"{v:{width}{spec}}" if isinstance(v, (int, float)) else f"{'-':>{width}}"


def print_table(a, rows, cgal, targets, val):
    dev = next((r["device"] for r in rows if r.get("device")), None)
    print(f"\ngdt-tile end to end: --tile {a.tile}, kind {a.kind}, seed {a.seed}, best of "
          f"{a.repeat}, device {dev or a.device or 'default'}")
    print("stage times (s) from the --json summary; CPU s = user + system time of the best "
          "run, all threads (steadier than wall time on a shared machine); cert = certified "
          "fraction")
    hdr = (f"{'size':>6} {'vertices':>10} {'wall s':>8} {'CPU s':>7} {'Mpts/s':>7} {'RSS MiB':>8} "
           + " ".join(f"{s:>7}" for s in STAGES) + f" {'cert':>6} {'#tiles':>6}")
    print(hdr)
    print("-" * len(hdr))
    for r in rows:
        t = r["times"]
        print(f"{size_label(r['size']):>6} {fmt(r['vertices'], 'd', 10)} {r['wall_s']:8.2f} "
              f"{r['cpu_s']:7.2f} {r['mpts_s']:7.2f} {r['peak_rss_mb']:8.1f} "
              + " ".join(fmt(t.get(s), '.2f', 7) for s in STAGES)
              + f" {fmt(r['certified_fraction'], '.4f', 6)} {fmt(r['tiles'], 'd', 6)}")
    if cgal is not None:
        print(f"\nCGAL Delaunay_triangulation_2 (Epick) at {size_label(cgal['size'])}: "
              f"{cgal['points']} distinct points, triangulation {cgal['seconds']:.2f} s, "
              f"process (reading included) {cgal['process_s']:.2f} s (CPU "
              f"{cgal['process_cpu_s']:.2f} s), peak RSS {cgal['peak_rss_mb']:.1f} MiB, faces "
              f"{cgal['faces']}")
        print(f"CGAL process time / gdt-tile wall time: {cgal['speedup_process']:.3f}")
    for t in targets:
        print(f"{t['name']}: {t['text']} = {t['value']:.3f} (target {t['op']} {t['target']}) "
              f"{'PASS' if t['pass'] else 'MISS'}")
    if val is not None:
        print(f"validate_mesh.py at {size_label(val['size'])}: {val['message']} "
              f"({val['seconds']:.1f} s)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build-dir", default=os.environ.get("GDT_BUILD_DIR", str(ROOT / "build")),
                    help="build folder (default $GDT_BUILD_DIR, else build/)")
    ap.add_argument("--sizes", type=size_list, default=size_list("10M,50M"),
                    help="cloud sizes in input records (default 10M,50M)")
    ap.add_argument("--tile", type=positive_int, default=4096, help="gdt-tile --tile (4096)")
    ap.add_argument("--device", default=None, help="gdt-tile --device (default device)")
    ap.add_argument("--repeat", type=positive_int, default=1, help="runs per size, best counts")
    ap.add_argument("--kind", default="lidar", help="gen_cloud.py --kind (lidar)")
    ap.add_argument("--seed", type=int, default=1, help="gen_cloud.py --seed (1)")
    ap.add_argument("--workdir", default=None,
                    help="keep and reuse the generated clouds and points files here")
    ap.add_argument("--tmpdir", default=None, help="parent of the temporary folder")
    ap.add_argument("--keep", action="store_true", help="keep outputs and temporary files")
    ap.add_argument("--cgal-size", type=parse_size, default=None,
                    help="size at which CGAL runs (default: the smallest size)")
    ap.add_argument("--no-cgal", action="store_true", help="skip the CGAL comparison")
    ap.add_argument("--validate", action="store_true",
                    help="check the CGAL-size output with validate_mesh.py")
    ap.add_argument("--gdt-args", default="", help="extra gdt-tile options, shell-quoted")
    ap.add_argument("--target-speedup", type=float, default=1.5)
    ap.add_argument("--target-rss-ratio", type=float, default=1.10)
    ap.add_argument("--json", default=None, help="write every figure to this JSON file")
    a = ap.parse_args(argv)

    sizes = sorted(a.sizes)
    ref_size = a.cgal_size if a.cgal_size is not None else sizes[0]
    if ref_size not in sizes:
        ap.error(f"--cgal-size {size_label(ref_size)} is not one of --sizes")

    tmp = None
    try:
        build = pathlib.Path(a.build_dir)
        gdt = need_exe(build / "tiler" / "gdt-tile", "gdt-tile")
        gcd_run = cgal_exe = None
        if not a.no_cgal:
            gcd_run = need_exe(build / "tests" / "gcd_run", "gcd_run (or use --no-cgal)")
            cgal_exe = need_exe(build / "tests" / "cgal_bench",
                                "cgal_bench (needs libcgal-dev; or use --no-cgal)")
        if not GEN.is_file():
            raise BenchError(2, f"{GEN} not found")

        tmp = pathlib.Path(tempfile.mkdtemp(prefix="gdt-e2e-", dir=a.tmpdir))
        work = pathlib.Path(a.workdir) if a.workdir else tmp
        work.mkdir(parents=True, exist_ok=True)

        rows, cgal, val = [], None, None
        for n in sizes:
            las = ensure_cloud(work, n, a)
            run_dir = tmp / f"run-{n}"
            run_dir.mkdir()
            row = bench_gdt(gdt, las, n, run_dir, a)
            rows.append(row)
            if n == ref_size and a.validate:
                val = validate(pathlib.Path(row["output"]), las, run_dir)
                val["size"] = n
            if n == ref_size and not a.no_cgal:
                pts = ensure_points(work, las, n, gcd_run, a)
                cgal = bench_cgal(cgal_exe, pts, run_dir, a)
                cgal["size"] = n
                if not a.workdir and not a.keep:
                    pts.unlink(missing_ok=True)
            if not a.keep:
                shutil.rmtree(run_dir, ignore_errors=True)
                if not a.workdir:
                    las.unlink(missing_ok=True)

        targets = []
        ref = next(r for r in rows if r["size"] == ref_size)
        if cgal is not None:
            v = cgal["seconds"] / ref["wall_s"]
            targets.append({"name": "speedup", "value": v, "target": a.target_speedup,
                            "op": ">=", "pass": v >= a.target_speedup,
                            "text": f"CGAL {cgal['seconds']:.2f} s / gdt-tile "
                                    f"{ref['wall_s']:.2f} s at {size_label(ref_size)}"})
            cgal["speedup_process"] = cgal["process_s"] / ref["wall_s"]
        if len(rows) > 1:
            lo, hi = rows[0], rows[-1]
            v = hi["peak_rss_mb"] / lo["peak_rss_mb"]
            targets.append({"name": "RSS ratio", "value": v, "target": a.target_rss_ratio,
                            "op": "<=", "pass": v <= a.target_rss_ratio,
                            "text": f"peak RSS {size_label(hi['size'])} {hi['peak_rss_mb']:.1f}"
                                    f" MiB / {size_label(lo['size'])} {lo['peak_rss_mb']:.1f} MiB"})
        print_table(a, rows, cgal, targets, val)
        if a.keep:
            print(f"bench_e2e: kept {tmp}", file=sys.stderr)
        if a.json:
            config = {k: v for k, v in vars(a).items() if k != "json"}
            pathlib.Path(a.json).write_text(json.dumps(
                {"config": config, "runs": rows, "cgal": cgal, "targets": targets,
                 "validation": val}, indent=1) + "\n")
        ok = all(t["pass"] for t in targets) and (val is None or val["exit"] == 0)
        return 0 if ok else 1
    except KeyboardInterrupt:
        print("bench_e2e: interrupted", file=sys.stderr)
        return 130
    except BenchError as e:
        print(f"bench_e2e: {e}", file=sys.stderr)
        if tmp is not None and a.keep:
            print(f"bench_e2e: kept {tmp}", file=sys.stderr)
        return e.status
    finally:
        if tmp is not None and not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
