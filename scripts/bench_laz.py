#!/usr/bin/env python3
"""bench_laz.py — LAZ decoding benchmark: gdt-tile's LASzip decoder against lazrs and LASzip.

  bench_laz.py [--points 5000000] [--point-format 3] [--kind lidar] [--seed 1]
               [--input FILE.laz ...] [--build DIR] [--repeat 3] [--workdir DIR]
               [--json FILE]

Decodes every point of each LAZ file (generated with gen_cloud.py and
compressed by laspy with lazrs, chunks of 50000 points, unless --input
names files) with:

  gdt        BUILD/tests/laz_decode (the decoder of io/private/laz_*.c), one
             thread, records written to /dev/null; CPU time of the child
  lazrs      lazrs.LasZipDecompressor, one thread, into memory; CPU time
  lazrs-par  lazrs.ParLasZipDecompressor (all cores), into memory; wall time
  laszip     laspy with the laszip back-end (LASzip's C++), one thread; CPU
             time including laspy's parsing

and prints the best of --repeat runs as seconds and million points per
second.  Figures only, never pass/fail.  Exit status: 0, 2 usage (missing
binary or module), 3 a decoder failed.
"""
import argparse
import json
import os
import resource
import struct
import subprocess
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
GEN = os.path.join(ROOT, "scripts", "gen_cloud.py")


def laszip_vlr(b):
    """The LASzip VLR's payload in the file bytes b."""
    i = b.find(b"laszip encoded") - 2
    (n,) = struct.unpack_from("<H", b, i + 20)
    return b[i + 54:i + 54 + n]


def make_laz(workdir, a):
    import laspy

    las_path = os.path.join(workdir, f"bench_{a.kind}_{a.points}_pf{a.point_format}.las")
    laz_path = las_path[:-4] + ".laz"
    if not os.path.exists(laz_path):
        subprocess.run([sys.executable, GEN, "--points", str(a.points), "--kind", a.kind,
                        "--seed", str(a.seed), "--point-format", str(a.point_format), "-q",
                        las_path], check=True)
        laspy.read(las_path).write(laz_path, laz_backend=laspy.LazBackend.Lazrs)
        os.unlink(las_path)
    return laz_path


def best(fn, repeat):
    return min(fn() for _ in range(repeat))


def time_gdt(exe, path):
    r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    with open(os.devnull, "wb") as null:
        p = subprocess.run([exe, path], stdout=null, stderr=subprocess.PIPE)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        sys.stderr.write(p.stderr.decode())
        sys.exit(3)
    return (r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime)


def time_lazrs(path, parallel):
    import lazrs

    with open(path, "rb") as f:
        b = f.read()
    (offset,) = struct.unpack_from("<I", b, 96)
    (count,) = struct.unpack_from("<I", b, 107)
    (rl,) = struct.unpack_from("<H", b, 105)
    vlr = laszip_vlr(b)
    with open(path, "rb") as f:
        f.seek(offset)
        out = bytearray(count * rl)
        clock = time.perf_counter if parallel else time.process_time
        t = clock()
        cls = lazrs.ParLasZipDecompressor if parallel else lazrs.LasZipDecompressor
        cls(f, vlr).decompress_many(out)
        return clock() - t


def time_laszip(path):
    import laspy

    t = time.process_time()
    laspy.read(path, laz_backend=laspy.LazBackend.Laszip)
    return time.process_time() - t


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--points", type=int, default=5_000_000)
    ap.add_argument("--point-format", type=int, default=3)
    ap.add_argument("--kind", default="lidar")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--input", nargs="+")
    ap.add_argument("--build", default=os.path.join(ROOT, "build"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--workdir")
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    exe = os.path.join(a.build, "tests", "laz_decode")
    if not os.access(exe, os.X_OK):
        print(f"bench_laz: {exe} not built", file=sys.stderr)
        return 2
    try:
        import laspy  # noqa: F401
        import lazrs  # noqa: F401
    except ImportError as e:
        print(f"bench_laz: {e} (run it with the project's .venv)", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="gdt-bench-laz-") as tmp:
        workdir = a.workdir or tmp
        paths = a.input or [make_laz(workdir, a)]
        rows = []
        for path in paths:
            with open(path, "rb") as f:
                head = f.read(111)
            (count,) = struct.unpack_from("<I", head, 107)
            times = {
                "gdt": best(lambda: time_gdt(exe, path), a.repeat),
                "lazrs": best(lambda: time_lazrs(path, False), a.repeat),
                "lazrs-par": best(lambda: time_lazrs(path, True), a.repeat),
                "laszip": best(lambda: time_laszip(path), a.repeat),
            }
            rows.append({"file": os.path.basename(path), "points": count,
                         "seconds": times,
                         "mpts_per_s": {k: count / v / 1e6 for k, v in times.items() if v > 0}})
    print(f"{'file':32s} {'points':>10s} " + " ".join(f"{k:>16s}" for k in rows[0]["seconds"]))
    for r in rows:
        cells = " ".join(f"{r['seconds'][k]:7.3f}s {r['mpts_per_s'].get(k, 0):6.2f}M"
                         for k in r["seconds"])
        print(f"{r['file']:32s} {r['points']:10d} {cells}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
