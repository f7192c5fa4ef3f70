#!/usr/bin/env python3
"""bench_laz.py — gdt-tile's LAZ decoder against lazrs, and gdt-tile end to end on LAZ
against the same cloud as LAS.

  bench_laz.py [--build-dir DIR] [--points 10M] [--formats 1,3,6,7,8] [--threads N]
               [--tile N] [--repeat K] [--seed S] [--workdir DIR] [--keep] [--no-e2e]
               [--target-decode-pw 1.0] [--target-decode-layered 1.5]
               [--target-e2e 1.3] [--json FILE]

For every point format, one LiDAR-like cloud (scripts/gen_cloud.py for X Y Z,
then pulses of 1-4 returns with consistent return numbers, ASPRS classes,
intensity, GPS time, scan angle, flight lines, RGB and NIR where the format
has them) is written twice with laspy: as LAS and as LAZ (lazrs, chunks of
50,000 points, the LASzip default).  Not timed; reused from --workdir.

Decode throughput (million points per second, best of --repeat, file in the
page cache):
  gdt 1t / gdt Nt   tests/src_read FILE --threads 1 / N: gdt_source streams
                    every point as a run's passes do (X Y Z, class, return
                    numbers and flags: the layers a run with filters needs);
  lazrs 1t / par    lazrs.LasZipDecompressor / ParLasZipDecompressor on the
                    file's bytes in memory (every field), with
                    RAYON_NUM_THREADS=N, one process per mode.
The ratio is gdt Nt / lazrs par.  src_read's checksum must be the same at 1
and N threads.

End to end (--no-e2e skips it): gdt-tile FILE --tile T --threads N -o OUT.ply
on the LAZ and on the LAS (wall time of the process, best of --repeat); the
ratio is LAZ / LAS, and the two PLY files must be identical.

Targets, each PASS or MISS: decode ratio >= --target-decode-pw (formats 0-5)
or --target-decode-layered (6-10); end-to-end ratio <= --target-e2e.

Exit status: 0 all targets met; 1 a target missed or outputs differ; 2 usage
or a missing program; 3 a program failed.
"""
import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_e2e as be  # noqa: E402  (shared process measuring and size parsing)

ROOT = pathlib.Path(__file__).resolve().parents[1]
GEN = ROOT / "scripts" / "gen_cloud.py"
CHUNK = 50_000

# The lazrs timing runs in a child process so RAYON_NUM_THREADS takes effect.
LAZRS_CHILD = r"""
import io, sys, time, laspy, lazrs
path, parallel, repeat = sys.argv[1], sys.argv[2] == "1", int(sys.argv[3])
with open(path, "rb") as f:
    data = f.read()
with laspy.open(path) as r:
    h = r.header
    vlr = next(v for v in h.vlrs if v.record_id == 22204)
    start, n, rec = h.offset_to_point_data, h.point_count, h.point_format.size
out = bytearray(n * rec)
kind = lazrs.ParLasZipDecompressor if parallel else lazrs.LasZipDecompressor
best = None
for _ in range(repeat):
    src = io.BytesIO(data)
    src.seek(start)
    t0 = time.perf_counter()
    kind(src, vlr.record_data).decompress_many(out)
    t = time.perf_counter() - t0
    best = t if best is None else min(best, t)
print(best)
"""


def synth_fields(las, rng, np):
    """Fills every non-XYZ field a LiDAR survey would: pulses of 1-4 returns in
    order, classes correlated with the return, GPS time along the scan,
    flight lines, colour varying smoothly in space."""
    n = len(las.points)
    pf = las.header.point_format.id
    nret = rng.choice([1, 1, 1, 2, 2, 3, 4], size=n).astype(np.uint8)
    # return number: walk pulses so each pulse's returns are 1..k in order
    ret = np.ones(n, dtype=np.uint8)
    i = 0
    k = nret.copy()
    while i < n:
        m = int(k[i])
        j = min(n, i + m)
        ret[i:j] = np.arange(1, j - i + 1, dtype=np.uint8)
        k[i:j] = m
        i = j
    las.return_number = ret
    las.number_of_returns = k
    last = ret == k
    cls = np.where(last, 2, rng.choice([1, 3, 4, 5, 6], size=n)).astype(np.uint8)
    cls[rng.random(n) < 0.002] = 7
    if pf >= 6:
        cls[rng.random(n) < 0.01] = 40
    las.classification = cls
    las.intensity = (200 + 30 * k + rng.integers(0, 200, size=n)).astype(np.uint16)
    x = np.asarray(las.X, dtype=np.int64)
    line = ((x - x.min()) // max(1, (x.max() - x.min()) // 7 + 1)).astype(np.uint16)
    las.point_source_id = line + 1
    if pf >= 6:
        las.scan_angle = rng.integers(-3000, 3000, size=n).astype(np.int16)
    else:
        las.scan_angle_rank = rng.integers(-30, 30, size=n).astype(np.int8)
    las.gps_time = 300000.0 + np.cumsum(np.where(ret == 1, 1e-5, 0.0))
    if "red" in las.point_format.dimension_names:
        y = np.asarray(las.Y, dtype=np.int64)
        las.red = ((x * 7) % 65536).astype(np.uint16)
        las.green = ((y * 5) % 65536).astype(np.uint16)
        las.blue = ((x + y) % 65536).astype(np.uint16)
    if "nir" in las.point_format.dimension_names:
        las.nir = (las.intensity * 40).astype(np.uint16)


def ensure_clouds(work, n, fmt, seed):
    """(las, laz) paths of the n-point cloud of point format fmt."""
    import laspy
    import numpy as np

    work.mkdir(parents=True, exist_ok=True)
    las_p = work / f"laz-bench-{n}-f{fmt}-s{seed}.las"
    laz_p = las_p.with_suffix(".laz")
    if be.las_points(las_p) == n and laz_p.is_file():
        return las_p, laz_p
    base = work / f"laz-bench-{n}-base-s{seed}.las"
    if be.las_points(base) != n:
        print(f"bench_laz: generating {be.size_label(n)} points ...", file=sys.stderr,
              flush=True)
        part = base.with_name(base.name + ".part")
        cmd = [sys.executable, GEN, part, "--points", n, "--seed", seed, "-q"]
        rc, _, _, _ = be.run_measured(cmd, str(part))
        be.check_run(rc, cmd, str(part), "gen_cloud.py")
        os.replace(part, base)
    print(f"bench_laz: writing format {fmt} as LAS and LAZ ...", file=sys.stderr, flush=True)
    src = laspy.read(base)
    version = "1.4" if fmt >= 6 else "1.2"
    hdr = laspy.LasHeader(point_format=fmt, version=version)
    hdr.scales = src.header.scales
    hdr.offsets = src.header.offsets
    for v in src.header.vlrs:
        hdr.vlrs.append(v)
    las = laspy.LasData(hdr)
    las.X, las.Y, las.Z = src.X, src.Y, src.Z
    synth_fields(las, np.random.default_rng(seed + fmt), np)
    las.update_header()
    las.write(las_p)
    las.write(laz_p, do_compress=True, laz_backend=laspy.LazBackend.Lazrs)
    return las_p, laz_p


def src_read(exe, path, threads, repeat, log):
    cmd = [exe, "--threads", threads, "--repeat", repeat, path]
    rc, _, _, _ = be.run_measured(cmd, log)
    be.check_run(rc, cmd, log, "src_read")
    best, sums = None, set()
    for line in pathlib.Path(f"{log}.out").read_text().split():
        k, _, v = line.partition("=")
        if k == "seconds":
            best = float(v) if best is None else min(best, float(v))
        elif k == "checksum":
            sums.add(v)
    if best is None or len(sums) != 1:
        raise be.BenchError(3, f"src_read printed no consistent result ({log}.out)")
    return best, sums.pop()


def lazrs_time(path, parallel, threads, repeat, log):
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads))
    cmd = [sys.executable, "-c", LAZRS_CHILD, str(path), "1" if parallel else "0", str(repeat)]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True)
    pathlib.Path(f"{log}.err").write_text(p.stderr)
    if p.returncode != 0:
        raise be.BenchError(3, f"lazrs failed on {path}:\n{p.stderr[-2000:]}")
    return float(p.stdout.strip())


def e2e_time(gdt, path, a, run_dir, tag):
    best = None
    out = run_dir / f"{tag}.ply"
    for r in range(a.repeat):
        job = run_dir / f"{tag}-job{r}"
        cmd = [gdt, path, "--tile", a.tile, "--threads", a.threads, "-o", out, "--job", job]
        log = str(run_dir / f"{tag}-{r}")
        rc, wall, _, _ = be.run_measured(cmd, log)
        be.check_run(rc, cmd, log, "gdt-tile")
        best = wall if best is None else min(best, wall)
    return best, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--build-dir", default=str(ROOT / "build"))
    ap.add_argument("--points", type=be.parse_size, default=10_000_000)
    ap.add_argument("--formats", default="1,3,6,7,8")
    ap.add_argument("--threads", type=be.positive_int, default=os.cpu_count() or 2)
    ap.add_argument("--tile", default="4096")
    ap.add_argument("--repeat", type=be.positive_int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workdir")
    ap.add_argument("--keep", action="store_true")
    ap.add_argument("--no-e2e", action="store_true")
    ap.add_argument("--target-decode-pw", type=float, default=1.0)
    ap.add_argument("--target-decode-layered", type=float, default=1.5)
    ap.add_argument("--target-e2e", type=float, default=1.3)
    ap.add_argument("--json")
    a = ap.parse_args()
    try:
        formats = [int(f) for f in a.formats.split(",")]
        if any(f < 0 or f > 10 for f in formats):
            raise ValueError
    except ValueError:
        ap.error("--formats: a comma list of LAS point formats 0-10")
    build = pathlib.Path(a.build_dir)
    rows, ok = [], True
    try:
        gdt = be.need_exe(build / "tiler" / "gdt-tile", "gdt-tile")
        rd = be.need_exe(build / "tests" / "src_read", "src_read")
        tmp = None
        if a.workdir:
            work = pathlib.Path(a.workdir)
            work.mkdir(parents=True, exist_ok=True)
        else:
            tmp = tempfile.TemporaryDirectory(prefix="bench_laz-")
            work = pathlib.Path(tmp.name)
        n = a.points
        print(f"bench_laz: {be.size_label(n)} points, {a.threads} threads, best of {a.repeat}")
        print(f"{'fmt':>3} {'LAS MB':>7} {'LAZ MB':>7} {'gdt 1t':>7} {'gdt Nt':>7} "
              f"{'lazrs 1t':>8} {'lazrs par':>9} {'ratio':>6} {'target':>6}  "
              f"{'e2e LAS s':>9} {'e2e LAZ s':>9} {'ratio':>6}")
        for fmt in formats:
            las_p, laz_p = ensure_clouds(work, n, fmt, a.seed)
            log = str(work / f"f{fmt}")
            # warm the page cache
            for p in (las_p, laz_p):
                with open(p, "rb") as f:
                    while f.read(1 << 24):
                        pass
            g1, c1 = src_read(rd, laz_p, 1, a.repeat, log + "-g1")
            gn, cn = src_read(rd, laz_p, a.threads, a.repeat, log + "-gn")
            _, cl = src_read(rd, las_p, 1, 1, log + "-gl")
            if not (c1 == cn == cl):
                print(f"bench_laz: format {fmt}: checksums differ (LAZ 1t {c1}, LAZ "
                      f"{a.threads}t {cn}, LAS {cl})", file=sys.stderr)
                ok = False
            l1 = lazrs_time(laz_p, False, 1, a.repeat, log + "-l1")
            lp = lazrs_time(laz_p, True, a.threads, a.repeat, log + "-lp")
            ratio = lp / gn
            target = a.target_decode_layered if fmt >= 6 else a.target_decode_pw
            row = {"format": fmt, "points": n, "las_bytes": las_p.stat().st_size,
                   "laz_bytes": laz_p.stat().st_size, "gdt_1t_mpts": n / g1 / 1e6,
                   "gdt_nt_mpts": n / gn / 1e6, "lazrs_1t_mpts": n / l1 / 1e6,
                   "lazrs_par_mpts": n / lp / 1e6, "decode_ratio": ratio,
                   "decode_target": target, "decode_pass": ratio >= target}
            ok = ok and row["decode_pass"]
            e2e = ""
            if not a.no_e2e:
                run_dir = work / f"e2e-f{fmt}"
                run_dir.mkdir(exist_ok=True)
                t_las, out_las = e2e_time(gdt, las_p, a, run_dir, "las")
                t_laz, out_laz = e2e_time(gdt, laz_p, a, run_dir, "laz")
                same = out_las.read_bytes() == out_laz.read_bytes()
                row.update(e2e_las_s=t_las, e2e_laz_s=t_laz, e2e_ratio=t_laz / t_las,
                           e2e_target=a.target_e2e, e2e_same_ply=same,
                           e2e_pass=t_laz / t_las <= a.target_e2e)
                ok = ok and same and row["e2e_pass"]
                e2e = (f"{t_las:9.2f} {t_laz:9.2f} {t_laz / t_las:6.2f} "
                       f"{'PASS' if row['e2e_pass'] else 'MISS'}"
                       f"{'' if same else ' PLY DIFFERS'}")
                if not a.keep:
                    for p in sorted(run_dir.rglob("*"), reverse=True):
                        p.rmdir() if p.is_dir() else p.unlink()
                    run_dir.rmdir()
            rows.append(row)
            print(f"{fmt:>3} {row['las_bytes'] / 1e6:7.0f} {row['laz_bytes'] / 1e6:7.0f} "
                  f"{row['gdt_1t_mpts']:7.2f} {row['gdt_nt_mpts']:7.2f} "
                  f"{row['lazrs_1t_mpts']:8.2f} {row['lazrs_par_mpts']:9.2f} {ratio:6.2f} "
                  f"{'PASS' if row['decode_pass'] else 'MISS':>6}  {e2e}", flush=True)
        print("decode columns: million points per second; ratio = gdt Nt / lazrs par")
        if a.json:
            pathlib.Path(a.json).write_text(json.dumps({"threads": a.threads, "rows": rows},
                                                       indent=2))
        if tmp is not None and not a.keep:
            tmp.cleanup()
    except be.BenchError as e:
        print(f"bench_laz: {e}", file=sys.stderr)
        return e.status
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
