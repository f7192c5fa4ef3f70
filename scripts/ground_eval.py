#!/usr/bin/env python3
"""ground_eval.py — how well `--ground pmf` finds the ground of a classified cloud.

  ground_eval.py CLOUD.las [--gdt-tile PATH] [--tile N] [--dem-res R]
                 [--workdir DIR] [--json FILE] [-- extra gdt-tile options]

Runs gdt-tile twice on a LAS/LAZ file that carries ground classes (class 2):
with `--ground pmf` (the filter ignores the file's classes) and with
`--keep-class 2` (the file's own ground), both with `--dem` at the same cell
size, and prints

  - precision and recall of the filter's ground against class 2, over the
    distinct (x, y) locations the run sees (withheld records dropped, as the
    run does; a location takes the class of its first record, as --dup first);
  - the DTMs compared: the vertical difference of the two TINs at the centres
    of the DEM cells both cover (each DEM cell is the TIN's linear
    interpolation at its centre): mean, mean absolute, 95th percentile of the
    absolute difference, and the share of cells within 0.15 and 0.5 CRS units.

Extra options after `--` go to the --ground run (e.g. `-- --pmf-cell 3 --pmf-max-window 100`
for a cloud in feet with large buildings).  Needs numpy, laspy (lazrs for LAZ),
plyfile and GDAL's gdal_translate.
"""
import argparse
import json
import os
import pathlib
import subprocess
import sys
import tempfile

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]


def run(cmd):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit("ground_eval: %s -> exit %d\n%s" % (" ".join(map(str, cmd)), r.returncode,
                                                       r.stderr))
    return r


def lattice_of(ply):
    with open(ply, "rb") as f:
        head = f.read(1 << 16).split(b"end_header")[0].decode("ascii", "replace")
    for line in head.splitlines():
        if line.startswith("comment lattice "):
            return tuple(float(v) for v in line.split()[2:6])
    sys.exit("ground_eval: %s has no lattice comment" % ply)


def vertex_keys(ply):
    from plyfile import PlyData
    sx, sy, ox, oy = lattice_of(ply)
    v = PlyData.read(str(ply))["vertex"]
    ix = np.round((np.asarray(v["x"]) - ox) / sx).astype(np.int64)
    iy = np.round((np.asarray(v["y"]) - oy) / sy).astype(np.int64)
    return ix, iy, (sx, sy, ox, oy)


def truth(cloud, lattice):
    """Distinct (x, y) locations of the kept records and their class 2 flag
    (first record of each location)."""
    import laspy
    sx, sy, ox, oy = lattice
    las = laspy.read(str(cloud))
    keep = np.ones(len(las.points), bool)
    try:
        keep &= ~np.asarray(las.withheld, bool)
    except (AttributeError, ValueError):
        pass
    ix = np.round((np.asarray(las.x)[keep] - ox) / sx).astype(np.int64)
    iy = np.round((np.asarray(las.y)[keep] - oy) / sy).astype(np.int64)
    cls = np.asarray(las.classification)[keep]
    key = ix * (1 << 32) + (iy - iy.min())
    _, first = np.unique(key, return_index=True)  # first occurrence of each location
    return key[first], cls[first] == 2, iy.min()


def dem_cells(tif):
    """(x, y) -> z of the DEM's valid cells, via gdal_translate -of XYZ."""
    with tempfile.NamedTemporaryFile(suffix=".xyz") as t:
        run(["gdal_translate", "-q", "-of", "XYZ", tif, t.name])
        d = np.loadtxt(t.name, ndmin=2)
    info = json.loads(run(["gdalinfo", "-json", tif]).stdout)
    nodata = info["bands"][0].get("noDataValue")
    if nodata is not None:
        d = d[d[:, 2] != nodata]
    return d


def split_extra(argv):
    """(own arguments, arguments after `--` for gdt-tile)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--" not in argv:
        return argv, []
    i = argv.index("--")
    return argv[:i], argv[i + 1:]


def main(argv=None):
    argv, extra = split_extra(argv)
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cloud")
    ap.add_argument("--gdt-tile", default=None, help="gdt-tile binary (default: build/tiler)")
    ap.add_argument("--tile", type=int, default=1024)
    ap.add_argument("--dem-res", type=float, default=1.0, help="DEM cell size (default 1)")
    ap.add_argument("--workdir", default=None, help="keep the runs' files here")
    ap.add_argument("--json", default=None, help="write the figures as JSON")
    a = ap.parse_args(argv)
    gdt = a.gdt_tile or os.environ.get("GDT_TILE") or ROOT / "build" / "tiler" / "gdt-tile"
    work = pathlib.Path(a.workdir or tempfile.mkdtemp(prefix="ground_eval."))
    work.mkdir(parents=True, exist_ok=True)
    common = ["--tile", a.tile, "--dem-res", a.dem_res, "-q", *extra]
    pmf, own = work / "pmf.ply", work / "class2.ply"
    run([gdt, a.cloud, "-o", pmf, "--ground", "pmf", "--dem", work / "pmf.tif",
         "--json", work / "pmf.json", *common])
    run([gdt, a.cloud, "-o", own, "--keep-class", 2, "--dem", work / "class2.tif",
         "--tile", a.tile, "--dem-res", a.dem_res, "-q"])
    ix, iy, lattice = vertex_keys(pmf)
    keys, is_ground, ybase = truth(a.cloud, lattice)
    pred = np.isin(keys, ix * (1 << 32) + (iy - ybase))
    tp = int((pred & is_ground).sum())
    fp = int((pred & ~is_ground).sum())
    fn = int((~pred & is_ground).sum())
    res = {"cloud": str(a.cloud), "locations": int(keys.size), "class2": int(is_ground.sum()),
           "pmf_ground": int(pred.sum()), "true_positive": tp, "false_positive": fp,
           "false_negative": fn,
           "precision": tp / (tp + fp) if tp + fp else 1.0,
           "recall": tp / (tp + fn) if tp + fn else 1.0}
    s = json.loads((work / "pmf.json").read_text())
    res["filter_seconds"] = s["ground"]["seconds"]
    a_dem, b_dem = dem_cells(work / "pmf.tif"), dem_cells(work / "class2.tif")
    ka = {(round(x, 6), round(y, 6)): z for x, y, z in a_dem}
    d = np.array([ka[(round(x, 6), round(y, 6))] - z for x, y, z in b_dem
                  if (round(x, 6), round(y, 6)) in ka])
    if d.size:
        ad = np.abs(d)
        res.update({"dtm_cells": int(d.size), "dtm_mean": float(d.mean()),
                    "dtm_mean_abs": float(ad.mean()), "dtm_p95_abs": float(np.percentile(ad, 95)),
                    "dtm_within_0.15": float((ad <= 0.15).mean()),
                    "dtm_within_0.5": float((ad <= 0.5).mean())})
    print("ground_eval: %s: %d locations, class 2: %d, --ground pmf: %d" %
          (a.cloud, res["locations"], res["class2"], res["pmf_ground"]))
    print("  precision %.4f  recall %.4f  (true %d, false %d, missed %d); filter %.2f s" %
          (res["precision"], res["recall"], tp, fp, fn, res["filter_seconds"]))
    if d.size:
        print("  DTM (pmf - class 2) at %d cell centres of %g: mean %+.3f, mean |d| %.3f, "
              "95th percentile |d| %.3f, within 0.15: %.1f%%, within 0.5: %.1f%%" %
              (res["dtm_cells"], a.dem_res, res["dtm_mean"], res["dtm_mean_abs"],
               res["dtm_p95_abs"], 100 * res["dtm_within_0.15"], 100 * res["dtm_within_0.5"]))
    if a.json:
        pathlib.Path(a.json).write_text(json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
