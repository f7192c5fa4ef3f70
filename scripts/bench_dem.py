#!/usr/bin/env python3
"""bench_dem.py — what --dem costs a tiled gdt-tile run, and gdal_grid beside it.

  bench_dem.py [--build-dir DIR] [--points 10M] [--subset 1M] [--tile N] [--threads N]
               [--repeat K] [--kind lidar] [--seed S] [--workdir DIR] [--keep]
               [--target-time 1.15] [--target-rss 1.10] [--json FILE]

One LiDAR-like LAS cloud of --points records (scripts/gen_cloud.py; not timed,
reused from --workdir) goes through
    gdt-tile CLOUD.las --tile T --threads N -o OUT.ply -q
three ways: without --dem, with --dem OUT.tif --dem-res 1, and with --dem at the
point spacing (the mean spacing sqrt(W*H/n) of the cloud's bounding box,
rounded to a whole number of lattice steps, at least one).  Each runs once
untimed first (the first run on a machine compiles the OpenCL kernels).  The
three configurations run in turn, --repeat rounds, round k starting with the k-th
(so each runs first, second and third equally often over three rounds: a
machine slower after a run does not always weigh on the same one); each
reports its best wall time
(the whole process) and its lowest peak RSS (the child's ru_maxrss), with the
CPU time (user + system, all threads) of the best run.  The ratios with --dem /
without are the targets, each PASS or MISS:
  time ratio  <= --target-time (1.15)
  RSS ratio   <= --target-rss (1.10)
Beside them, not targets: each DEM run's time over the no-DEM run of its own
round, and their median (the machine's speed drifts between rounds).

For scale, a --subset of the cloud (default 1M points, the whole cloud when
smaller), the records nearest its centre (a window of the cloud's aspect, in
file order), is written as LAS and as a CSV of x, y, z relative to the
cloud's south-west corner (one point per (x, y), the first z, as gdt-tile
keeps them); gdt-tile --dem
--dem-res 1 runs on the LAS, then gdal_grid -a linear:radius=0 (qhull and
linear interpolation) on the CSV, on the same grid as gdt-tile's GeoTIFF (its
extent and size, R = 1).  Both once untimed, then best of --repeat, wall time
and peak RSS; the share of cells where both have a value and agree within 1e-6 relative is
printed as a check, not a target.

Outputs are deleted after each run; without --workdir everything lives in a
temporary folder removed at the end (--keep keeps it).  Needs the build target
gdt-tile, numpy and laspy, and GDAL's command line tools (gdal_grid,
gdalinfo, gdal_translate).  Memory figures are MiB (2^20 bytes).

Exit status: 0 every target met; 1 a target missed; 2 usage or a missing
program; 3 a program failed (its exit status and the tail of its stderr are
printed).
"""
import argparse
import json
import math
import os
import pathlib
import shutil
import statistics
import subprocess
import sys
import tempfile

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import bench_e2e as be  # noqa: E402  (cloud generation, process measuring, size parsing)

ROOT = pathlib.Path(__file__).resolve().parents[1]
NODATA = -9999.0


def lattice_res(r, step):
    """r rounded to a whole number of lattice steps (at least one), as gdt-tile reads it."""
    k = max(1, round(r / step))
    return float(f"{k * step:.12g}"), k


def cloud_geometry(las):
    """(points, (minx, miny, maxx, maxy), scale x, scale y) from the LAS header."""
    import laspy
    with laspy.open(str(las)) as f:
        h = f.header
        return (int(h.point_count), (float(h.mins[0]), float(h.mins[1]), float(h.maxs[0]),
                                     float(h.maxs[1])), float(h.scales[0]), float(h.scales[1]))


def run_fresh(cmd, outputs, run_dir, tag):
    """One run of cmd after deleting its outputs and the job folder: (wall s,
    peak RSS bytes, CPU s); its log is run_dir/tag."""
    for p in outputs:
        p.unlink(missing_ok=True)
    shutil.rmtree(run_dir / "job", ignore_errors=True)
    log = str(run_dir / tag)
    rc, wall, rss, cpu = be.run_measured(cmd, log)
    be.check_run(rc, cmd, log, cmd[0].rsplit("/", 1)[-1])
    return wall, rss, cpu


def time_runs(cmds, a, run_dir):
    """Runs every (name, cmd, its outputs) of cmds once untimed, then in turn,
    --repeat rounds, each after deleting its outputs and the job folder;
    round k starts at the k-th command (mod their number), so that each takes
    every place in a round equally often over a multiple of that many rounds;
    returns name -> figures (walls_s in round order)."""
    res = {name: {"walls": [], "rss": [], "cpu": []} for name, _, _ in cmds}
    # the first run on a machine compiles the OpenCL kernels into the cache
    # and loads the input and the libraries into memory, which no later run
    # pays
    for name, cmd, outputs in cmds:
        wall, _, _ = run_fresh(cmd, outputs, run_dir, f"{name}-warm")
        print(f"  {name} warm-up run (not counted): {wall:8.2f} s", file=sys.stderr, flush=True)
    for k in range(a.repeat):
        for name, cmd, outputs in cmds[k % len(cmds):] + cmds[:k % len(cmds)]:
            wall, rss, cpu = run_fresh(cmd, outputs, run_dir, f"{name}-{k}")
            r = res[name]
            r["walls"].append(wall)
            r["rss"].append(rss)
            r["cpu"].append(cpu)
            print(f"  {name} run {k + 1}/{a.repeat}: {wall:8.2f} s, CPU {cpu:8.2f} s, "
                  f"peak RSS {rss / 2**20:8.1f} MiB", file=sys.stderr, flush=True)
    out = {}
    for name, r in res.items():
        best = min(range(len(r["walls"])), key=lambda i: r["walls"][i])
        out[name] = {"wall_s": r["walls"][best], "cpu_s": r["cpu"][best],
                     "peak_rss_bytes": min(r["rss"]), "peak_rss_mb": min(r["rss"]) / 2**20,
                     "walls_s": r["walls"], "peak_rss_all_bytes": r["rss"]}
    return out


def gdt_cmd(gdt, las, out, a, dem=None, res=None):
    cmd = [gdt, las, "--tile", a.tile, "--threads", a.threads, "-q", "-o", out,
           "--job", out.parent / "job"]
    if dem is not None:
        cmd += ["--dem", dem, "--dem-res", repr(res)]
    return [str(c) for c in cmd]


def write_subset(las, m, corner, work):
    """The m records nearest the cloud's centre (Chebyshev distance scaled by the
    bounding box, so the window has the cloud's aspect), in file order: a LAS
    file and a CSV (x, y, z relative to corner) with the OGR VRT that reads it."""
    import laspy
    import numpy as np
    sub = work / f"{las.stem}-sub{m}.las"
    csv, vrt = sub.with_suffix(".csv"), sub.with_suffix(".vrt")
    if be.las_points(sub) == m and csv.is_file() and vrt.is_file() and \
            sub.stat().st_mtime >= las.stat().st_mtime:
        return sub, vrt
    print(f"bench_dem: writing the {be.size_label(m)}-point subset ...", file=sys.stderr,
          flush=True)
    src = laspy.read(str(las))
    x, y = np.asarray(src.x), np.asarray(src.y)
    w = max(float(x.max() - x.min()), 1e-300)
    h = max(float(y.max() - y.min()), 1e-300)
    cx, cy = (x.max() + x.min()) / 2, (y.max() + y.min()) / 2
    d = np.maximum(np.abs(x - cx) / w, np.abs(y - cy) / h)
    keep = np.sort(np.argpartition(d, m - 1)[:m]) if m < len(d) else np.arange(len(d))
    out = laspy.LasData(src.header)
    out.points = src.points[keep]
    part = sub.with_name(sub.name + ".part")
    out.write(str(part))
    # gdal_grid gets the TIN's vertex set: one point per (x, y), the first z in file
    # order (gdt-tile's default --dup first)
    X, Y = np.asarray(src.X, dtype=np.int64)[keep], np.asarray(src.Y, dtype=np.int64)[keep]
    _, first = np.unique(np.column_stack([X, Y]), axis=0, return_index=True)
    first = keep[np.sort(first)]
    with open(csv, "w") as f:
        f.write("x,y,z\n")
        np.savetxt(f, np.column_stack([x[first] - corner[0], y[first] - corner[1],
                                       np.asarray(src.z)[first]]),
                   fmt="%.17g", delimiter=",")
    vrt.write_text('<OGRVRTDataSource><OGRVRTLayer name="p"><SrcDataSource>'
                   f'{csv}</SrcDataSource><SrcLayer>{csv.stem}</SrcLayer>'
                   '<GeometryType>wkbPoint</GeometryType>'
                   '<GeometryField encoding="PointFromColumns" x="x" y="y" z="z"/>'
                   '</OGRVRTLayer></OGRVRTDataSource>')
    os.replace(part, sub)
    return sub, vrt


def gdalinfo(path):
    r = subprocess.run(["gdalinfo", "-json", str(path)], capture_output=True, text=True)
    if r.returncode != 0:
        raise be.BenchError(3, f"gdalinfo failed on {path}:\n{r.stderr[-2000:]}")
    return json.loads(r.stdout)


def cells(path, dtype, run_dir):
    """Every cell of band 1 (GDAL's raw ENVI copy)."""
    import numpy as np
    info = gdalinfo(path)
    nc, nr = info["size"]
    raw = run_dir / (pathlib.Path(path).name + ".raw")
    r = subprocess.run(["gdal_translate", "-q", "-of", "ENVI", str(path), str(raw)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        raise be.BenchError(3, f"gdal_translate failed on {path}:\n{r.stderr[-2000:]}")
    return np.fromfile(raw, dtype=dtype).reshape(nr, nc)


def bench_subset(gdt, las, m, corner, work, run_dir, a):
    import numpy as np
    sub, vrt = write_subset(las, m, corner, work)
    ply, tif, grid = run_dir / "sub.ply", run_dir / "sub.tif", run_dir / "grid.tif"
    # gdt-tile first: its GeoTIFF gives gdal_grid the grid
    cmd = gdt_cmd(gdt, sub, ply, a, tif, 1.0)
    log = str(run_dir / "sub-probe")
    rc, _, _, _ = be.run_measured(cmd, log)
    be.check_run(rc, cmd, log, "gdt-tile")
    info = gdalinfo(tif)
    gt, (nc, nr) = info["geoTransform"], info["size"]
    west, north = gt[0] - corner[0], gt[3] - corner[1]
    east, south = west + nc * gt[1], north + nr * gt[5]
    gcmd = ["gdal_grid", "-q", "-a", f"linear:radius=0:nodata={NODATA:g}", "-ot", "Float32",
            "-txe", repr(west), repr(east), "-tye", repr(north), repr(south),
            "-outsize", str(nc), str(nr), "-zfield", "z", "-l", "p", str(vrt), str(grid)]
    t = time_runs([("subset gdt-tile", cmd, [ply, tif]), ("subset gdal_grid", gcmd, [grid])],
                  a, run_dir)
    ours, theirs = cells(tif, "<f4", run_dir), cells(grid, "<f4", run_dir)
    both = (ours != NODATA) & (theirs != NODATA)
    o, g = ours.astype(np.float64), theirs.astype(np.float64)
    agree = both & (np.abs(o - g) <= 1e-6 * np.maximum(1.0, np.abs(g)))
    nb = int(both.sum())
    return {"points": m, "cols": nc, "rows": nr, "cells": nc * nr,
            "gdt": t["subset gdt-tile"], "gdal_grid": t["subset gdal_grid"],
            "cells_ours": int((ours != NODATA).sum()), "cells_gdal": int((theirs != NODATA).sum()),
            "cells_both": nb, "agree_fraction": (int(agree.sum()) / nb) if nb else None}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--build-dir", default=os.environ.get("GDT_BUILD_DIR", str(ROOT / "build")),
                    help="build folder (default $GDT_BUILD_DIR, else build/)")
    ap.add_argument("--points", type=be.parse_size, default=10_000_000,
                    help="cloud size in records (default 10M)")
    ap.add_argument("--subset", type=be.parse_size, default=None,
                    help="points of the gdal_grid comparison (default 1M, at most --points)")
    ap.add_argument("--tile", type=be.positive_int, default=4096, help="gdt-tile --tile (4096)")
    ap.add_argument("--threads", type=be.positive_int, default=os.cpu_count() or 2,
                    help="gdt-tile --threads (default all cores)")
    ap.add_argument("--repeat", type=be.positive_int, default=2, help="rounds, best counts (2)")
    ap.add_argument("--kind", default="lidar", help="gen_cloud.py --kind (lidar)")
    ap.add_argument("--seed", type=int, default=1, help="gen_cloud.py --seed (1)")
    ap.add_argument("--workdir", default=None, help="keep and reuse the generated clouds here")
    ap.add_argument("--tmpdir", default=None, help="parent of the temporary folder")
    ap.add_argument("--keep", action="store_true", help="keep outputs and temporary files")
    ap.add_argument("--target-time", type=float, default=1.15)
    ap.add_argument("--target-rss", type=float, default=1.10)
    ap.add_argument("--json", default=None, help="write every figure to this JSON file")
    a = ap.parse_args(argv)
    if a.subset is None:
        a.subset = min(1_000_000, a.points)
    if a.subset > a.points:
        ap.error("--subset is larger than --points")

    tmp = None
    try:
        build = pathlib.Path(a.build_dir)
        gdt = be.need_exe(build / "tiler" / "gdt-tile", "gdt-tile")
        for tool in ("gdal_grid", "gdalinfo", "gdal_translate"):
            if shutil.which(tool) is None:
                raise be.BenchError(2, f"{tool} not found (GDAL's tools, Debian gdal-bin)")
        tmp = pathlib.Path(tempfile.mkdtemp(prefix="gdt-dem-", dir=a.tmpdir))
        work = pathlib.Path(a.workdir) if a.workdir else tmp
        work.mkdir(parents=True, exist_ok=True)

        las = be.ensure_cloud(work, a.points, a)
        n, (x0, y0, x1, y1), sx, sy = cloud_geometry(las)
        if abs(sx - sy) > 1e-12 * max(sx, sy):
            raise be.BenchError(2, f"{las}: x and y scales differ ({sx}, {sy})")
        spacing = math.sqrt((x1 - x0) * (y1 - y0) / n)
        res_sp, steps = lattice_res(spacing, sx)
        with open(las, "rb") as f:  # the LAS in the page cache
            while f.read(1 << 24):
                pass

        run_dir = tmp / "run"
        run_dir.mkdir()
        ply, tif = run_dir / "out.ply", run_dir / "out.tif"
        cmds = [("no DEM", gdt_cmd(gdt, las, ply, a), [ply, tif]),
                ("DEM 1 m", gdt_cmd(gdt, las, ply, a, tif, 1.0), [ply, tif]),
                (f"DEM {res_sp:g} m", gdt_cmd(gdt, las, ply, a, tif, res_sp), [ply, tif])]
        print(f"bench_dem: {be.size_label(n)} points, --tile {a.tile}, {a.threads} threads, "
              f"best of {a.repeat}", file=sys.stderr, flush=True)
        t = time_runs(cmds, a, run_dir)
        base = t["no DEM"]
        runs, targets = [], []
        for (name, cmd, _), res in zip(cmds, (None, 1.0, res_sp)):
            r = dict(t[name], name=name, dem_res=res, command=cmd)
            if res is not None:
                # each round's run against the no-DEM run of the same round: not a
                # target, a view of the machine's noise beside the best-of figures
                r["round_ratios"] = [w / b for w, b in zip(r["walls_s"], base["walls_s"])]
                r["median_round_ratio"] = statistics.median(r["round_ratios"])
                r["time_ratio"] = r["wall_s"] / base["wall_s"]
                r["rss_ratio"] = r["peak_rss_bytes"] / base["peak_rss_bytes"]
                for what, v, target in (("time ratio", r["time_ratio"], a.target_time),
                                        ("RSS ratio", r["rss_ratio"], a.target_rss)):
                    targets.append({"name": f"{name} {what}", "value": v, "target": target,
                                    "op": "<=", "pass": v <= target})
                r["time_pass"], r["rss_pass"] = (targets[-2]["pass"], targets[-1]["pass"])
            runs.append(r)
        if not a.keep:
            shutil.rmtree(run_dir, ignore_errors=True)

        sub_dir = tmp / "subset"
        sub_dir.mkdir()
        subset = bench_subset(gdt, las, a.subset, (x0, y0), work, sub_dir, a)
        if not a.keep:
            shutil.rmtree(sub_dir, ignore_errors=True)
            if not a.workdir:
                las.unlink(missing_ok=True)

        print(f"\ngdt-tile --dem: {be.size_label(n)} points ({a.kind}, seed {a.seed}), --tile "
              f"{a.tile}, --threads {a.threads}, best of {a.repeat}; mean spacing "
              f"{spacing:.4f} m -> --dem-res {res_sp:g} ({steps} lattice steps of {sx:g})")
        hdr = (f"{'run':<16} {'res m':>6} {'wall s':>8} {'CPU s':>8} {'RSS MiB':>8} "
               f"{'time x':>7} {'target':>6} {'RSS x':>6} {'target':>6}")
        print(hdr)
        print("-" * len(hdr))
        for r in runs:
            res = "-" if r["dem_res"] is None else f"{r['dem_res']:g}"
            line = (f"{r['name']:<16} {res:>6} "
                    f"{r['wall_s']:8.2f} {r['cpu_s']:8.2f} {r['peak_rss_mb']:8.1f}")
            if r["dem_res"] is not None:
                line += (f" {r['time_ratio']:7.3f} {'PASS' if r['time_pass'] else 'MISS':>6}"
                         f" {r['rss_ratio']:6.3f} {'PASS' if r['rss_pass'] else 'MISS':>6}")
            print(line)
        print(f"targets: time ratio <= {a.target_time}, peak RSS ratio <= {a.target_rss} "
              f"(with --dem / without)")
        for r in runs[1:]:
            print(f"{r['name']}: time ratio of each round to that round's run without "
                  f"--dem: {' '.join(f'{x:.3f}' for x in r['round_ratios'])} "
                  f"(median {r['median_round_ratio']:.3f})")
        s = subset
        print(f"\n{be.size_label(s['points'])}-point subset, R = 1 m, {s['cols']} x {s['rows']} "
              f"cells:")
        print(f"{'program':<24} {'wall s':>8} {'CPU s':>8} {'RSS MiB':>8}")
        for label, key in (("gdt-tile --dem (+ PLY)", "gdt"),
                           ("gdal_grid linear", "gdal_grid")):
            print(f"{label:<24} {s[key]['wall_s']:8.2f} {s[key]['cpu_s']:8.2f} "
                  f"{s[key]['peak_rss_mb']:8.1f}")
        agree = "-" if s["agree_fraction"] is None else f"{100 * s['agree_fraction']:.3f}%"
        print(f"cells with a value: gdt-tile {s['cells_ours']}, gdal_grid {s['cells_gdal']}; "
              f"agreeing within 1e-6 relative where both have one: {agree}")
        ok = all(x["pass"] for x in targets)
        if a.json:
            config = {k: v for k, v in vars(a).items() if k != "json"}
            pathlib.Path(a.json).write_text(json.dumps(
                {"config": config, "cloud": {"path": str(las), "points": n,
                                             "bbox": [x0, y0, x1, y1], "scale": sx,
                                             "spacing": spacing, "spacing_res": res_sp},
                 "runs": runs, "targets": targets, "subset": subset, "pass": ok},
                indent=1) + "\n")
        if a.keep:
            print(f"bench_dem: kept {tmp}", file=sys.stderr)
        return 0 if ok else 1
    except KeyboardInterrupt:
        print("bench_dem: interrupted", file=sys.stderr)
        return 130
    except be.BenchError as e:
        print(f"bench_dem: {e}", file=sys.stderr)
        if tmp is not None and a.keep:
            print(f"bench_dem: kept {tmp}", file=sys.stderr)
        return e.status
    finally:
        if tmp is not None and not a.keep:
            shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
