#!/usr/bin/env python3
"""bench_info.py — reading benchmark: `gdt-tile FILE --info` against raw disk reads.

  bench_info.py [--points 50000000] [--workdir DIR] [--keep] [--input FILE]
                [--gdt-tile PATH] [--args "{file} --info"] [--rss-limit-mb 100]
                [--kind lidar] [--seed 1] [--las-version 1.2] [--point-format F]
                [--json FILE]

Generates a LAS file with gen_cloud.py (or reuses one left in the work
folder by an earlier --keep run of the same generator, or takes --input),
then measures in the same run, first with the file evicted from the page
cache and then with it cached:

  raw read   the whole file with 8 MiB reads (the speed the disk allows)
  command    the measured command (default `gdt-tile FILE --info`): wall time
             and peak RSS of the child (getrusage RUSAGE_CHILDREN in a fresh
             wrapper process, so nothing else is counted)

and prints one table: points, file MB, time, MB/s, Mpts/s, peak RSS MB and
the command's speed as a fraction of the raw read speed in the same cache
state.  Eviction uses posix_fadvise(DONTNEED) after fsync and is verified
with mincore(2); when it does not work the table says "cached".

Exit status: 0 ok; 1 the command's peak RSS reached the limit (default
100 MB); 2 usage (missing binary or file); 3 the command failed.
"""
import argparse
import ctypes
import ctypes.util
import json
import mmap
import os
import shlex
import struct
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GEN = os.path.join(ROOT, "scripts", "gen_cloud.py")

# Runs argv[1:] and reports its wall time and the peak RSS of its process
# tree (only processes it waited for), as JSON on stdout.  The child's stdout
# goes to the file named in the environment (it may be large).
_WRAPPER = r"""
import json, os, resource, subprocess, sys, time
with open(os.environ["BENCH_STDOUT"], "wb") as out:
    t = time.perf_counter()
    p = subprocess.run(sys.argv[1:], stdout=out, stderr=subprocess.PIPE)
    wall = time.perf_counter() - t
ru = resource.getrusage(resource.RUSAGE_CHILDREN)
json.dump({"rc": p.returncode, "wall": wall, "maxrss_kb": ru.ru_maxrss,
           "user": ru.ru_utime, "sys": ru.ru_stime,
           "stderr": p.stderr.decode("utf-8", "replace")[-4000:]}, sys.stdout)
"""


def las_point_count(path):
    """Point count from a LAS header (64-bit count for 1.4), or None."""
    try:
        with open(path, "rb") as f:
            h = f.read(375)
    except OSError:
        return None
    if len(h) < 227 or h[:4] != b"LASF":
        return None
    minor = h[25]
    legacy = struct.unpack_from("<I", h, 107)[0]
    if minor >= 4 and len(h) >= 255:
        return struct.unpack_from("<Q", h, 247)[0] or legacy
    return legacy


def generator_mtime():
    """Newest modification time of the generator's sources (a kept file older
    than that was made by another version and is not reused)."""
    pkg = os.path.join(ROOT, "scripts", "lasgen")
    files = [GEN] + [os.path.join(pkg, f) for f in os.listdir(pkg) if f.endswith(".py")]
    return max(os.path.getmtime(f) for f in files)


def resident_fraction(path):
    """Fraction of the file's pages in the page cache (mincore), or None."""
    libc_name = ctypes.util.find_library("c")
    if not libc_name:
        return None
    libc = ctypes.CDLL(libc_name, use_errno=True)
    libc.mmap.restype = ctypes.c_void_p
    libc.mmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_int, ctypes.c_int,
                          ctypes.c_int, ctypes.c_long]
    libc.munmap.argtypes = [ctypes.c_void_p, ctypes.c_size_t]
    libc.mincore.argtypes = [ctypes.c_void_p, ctypes.c_size_t, ctypes.c_void_p]
    size = os.path.getsize(path)
    if size == 0:
        return 0.0
    page = mmap.PAGESIZE
    npages = (size + page - 1) // page
    fd = os.open(path, os.O_RDONLY)
    try:
        addr = libc.mmap(None, size, mmap.PROT_READ, mmap.MAP_SHARED, fd, 0)
        if addr in (None, ctypes.c_void_p(-1).value):
            return None
        try:
            vec = (ctypes.c_ubyte * npages)()
            if libc.mincore(ctypes.c_void_p(addr), size, vec) != 0:
                return None
            return sum(1 for v in vec if v & 1) / npages
        finally:
            libc.munmap(ctypes.c_void_p(addr), size)
    finally:
        os.close(fd)


def evict(path):
    """Drops the file from the page cache; returns True when verified."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
        os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
    finally:
        os.close(fd)
    frac = resident_fraction(path)
    return frac is not None and frac < 0.02


def raw_read(path, block=8 << 20):
    buf = bytearray(block)
    view = memoryview(buf)
    total = 0
    t = time.perf_counter()
    with open(path, "rb", buffering=0) as f:
        while True:
            n = f.readinto(view)
            if not n:
                break
            total += n
    return time.perf_counter() - t, total


def run_measured(cmd, workdir):
    out = os.path.join(workdir, "bench-command.out")
    env = dict(os.environ, BENCH_STDOUT=out)
    r = subprocess.run([sys.executable, "-c", _WRAPPER] + cmd, capture_output=True,
                       text=True, env=env)
    if r.returncode != 0:
        raise RuntimeError("measurement wrapper failed: %s" % r.stderr.strip())
    res = json.loads(r.stdout)
    with open(out, "rb") as f:
        res["stdout"] = f.read(1 << 16).decode("utf-8", "replace")
    os.unlink(out)
    return res


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=50_000_000, help="points (default 50e6)")
    ap.add_argument("--workdir", default=os.path.join(tempfile.gettempdir(), "gdt-bench"),
                    help="folder for the generated file (default $TMPDIR/gdt-bench)")
    ap.add_argument("--keep", action="store_true",
                    help="keep the generated file for later runs (they reuse it)")
    ap.add_argument("--input", default=None, help="benchmark this LAS file instead")
    ap.add_argument("--gdt-tile", default=os.path.join(ROOT, "build", "tiler", "gdt-tile"),
                    help="program to measure (default build/tiler/gdt-tile)")
    ap.add_argument("--args", default="{file} --info",
                    help='its arguments, {file} = the LAS file (default "{file} --info")')
    ap.add_argument("--rss-limit-mb", type=float, default=100.0,
                    help="fail when the command's peak RSS reaches this (default 100)")
    ap.add_argument("--kind", default="lidar", help="gen_cloud.py --kind (default lidar)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--las-version", default="1.2")
    ap.add_argument("--point-format", type=int, default=None)
    ap.add_argument("--json", default=None, help="also write the figures as JSON")
    a = ap.parse_args(argv)

    exe = os.path.abspath(a.gdt_tile)
    if not os.access(exe, os.X_OK):
        print("bench_info: %s is not an executable (build it, or pass --gdt-tile)" % exe,
              file=sys.stderr)
        return 2
    os.makedirs(a.workdir, exist_ok=True)
    gen_info = None
    generated = False
    if a.input:
        path = os.path.abspath(a.input)
        points = las_point_count(path)
        if points is None:
            print("bench_info: %s is not a LAS file" % path, file=sys.stderr)
            return 2
        origin = "given"
    else:
        fmt = "" if a.point_format is None else "-f%d" % a.point_format
        path = os.path.join(a.workdir, "bench-%s-%d-s%d-v%s%s.las"
                            % (a.kind, a.points, a.seed, a.las_version, fmt))
        points = a.points
        if las_point_count(path) == a.points and os.path.getmtime(path) > generator_mtime():
            origin = "reused"
        else:
            cmd = [sys.executable, GEN, path, "--points", str(a.points), "--kind", a.kind,
                   "--seed", str(a.seed), "--las-version", a.las_version, "-q"]
            if a.point_format is not None:
                cmd += ["--point-format", str(a.point_format)]
            t = time.perf_counter()
            r = subprocess.run(cmd, capture_output=True, text=True)
            dt = time.perf_counter() - t
            if r.returncode != 0:
                print("bench_info: generation failed: %s" % r.stderr.strip(), file=sys.stderr)
                return 2
            generated = True
            origin = "generated"
            gen_info = {"seconds": dt, "mpts_per_s": a.points / dt / 1e6}
    size = os.path.getsize(path)
    mb = size / 1e6
    cmd = [exe] + [x.replace("{file}", path) for x in shlex.split(a.args)]
    shown = " ".join(shlex.quote(c) for c in cmd)

    rows = []
    results = {}
    try:
        for state in ("cold", "warm"):
            if state == "cold":
                ok = evict(path)
                label = "cold" if ok else "cached"
            else:
                label = "warm"
            t_raw, n = raw_read(path)
            if n != size:
                raise RuntimeError("read %d of %d bytes" % (n, size))
            if state == "cold":
                evict(path)
            res = run_measured(cmd, a.workdir)
            results[state] = {"raw_seconds": t_raw, "cache": label, **res}
            raw_mbs = mb / t_raw if t_raw > 0 else float("inf")
            cmd_mbs = mb / res["wall"] if res["wall"] > 0 else float("inf")
            rows.append(("raw read (%s)" % label, t_raw, raw_mbs, None, None))
            rows.append(("command (%s)" % label, res["wall"], cmd_mbs, res["maxrss_kb"] / 1024.0,
                         cmd_mbs / raw_mbs))
            if res["rc"] != 0:
                break
    finally:
        if generated and not a.keep:
            os.unlink(path)

    print("file: %s (%s, %d points, %.1f MB)" % (path, origin, points, mb))
    if gen_info:
        print("generation: %.2f s, %.2f Mpts/s" % (gen_info["seconds"], gen_info["mpts_per_s"]))
    print("command: %s" % shown)
    if "cold" in results and results["cold"]["cache"] == "cold":
        print("cold: evicted from this system's page cache (checked with mincore); "
              "the host of a virtual disk may still cache it")
    elif "cold" in results:
        print("cold runs not possible: the file could not be evicted from the page cache")
    print()
    print("%-20s %12s %9s %9s %9s %9s %12s %9s" % ("what", "points", "file MB", "time s", "MB/s",
                                                   "Mpts/s", "peak RSS MB", "vs raw"))
    for what, t, mbs, rss, ratio in rows:
        print("%-20s %12d %9.1f %9.3f %9.1f %9.2f %12s %9s"
              % (what, points, mb, t, mbs, points / t / 1e6 if t > 0 else float("inf"),
                 "-" if rss is None else "%.1f" % rss,
                 "-" if ratio is None else "%.2f" % ratio))
    last = results[list(results)[-1]]
    out = last["stdout"].strip().splitlines()
    if out:
        print()
        print("command output (%s run):" % list(results)[-1])
        for line in out[:40]:
            print("  " + line)
    status = 0
    peak = max(r["maxrss_kb"] for r in results.values()) / 1024.0
    if any(r["rc"] != 0 for r in results.values()):
        bad = [r for r in results.values() if r["rc"] != 0][0]
        print("\nbench_info: the command failed (exit %d): %s" % (bad["rc"], bad["stderr"].strip()),
              file=sys.stderr)
        status = 3
    elif peak >= a.rss_limit_mb:
        print("\nbench_info: peak RSS %.1f MB reaches the limit of %.0f MB"
              % (peak, a.rss_limit_mb), file=sys.stderr)
        status = 1
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"file": path, "origin": origin, "points": points, "bytes": size,
                       "command": cmd, "generation": gen_info, "runs": results,
                       "peak_rss_mb": peak, "status": status}, f, indent=1)
    return status


if __name__ == "__main__":
    sys.exit(main())
