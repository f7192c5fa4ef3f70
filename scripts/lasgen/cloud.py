"""Assembles the sections of a cloud and streams them into a LAS file."""
import json
import math
import time

from .las import LasWriter
from .lidar import LidarSection
from .simple import DemSection, GridSection, UniformSection
from .terrain import Terrain

KINDS = ("lidar", "grid", "uniform", "dem", "mixed")
_SIMPLE = {"grid": GridSection, "uniform": UniformSection, "dem": DemSection}


def default_extent(points: int, density: float):
    side = max(10.0, math.sqrt(max(points, 1) / density))
    return side, side


def build_sections(kind, points, seed, extent, scale, dem_fraction=0.04, dup_fraction=0.002):
    """Sections (in output order) of a cloud of exactly `points` points over
    the local rectangle [0, W] x [0, H]."""
    w, h = extent
    terrain = Terrain(seed, w, h)
    if kind == "lidar":
        return [LidarSection(seed, 0, (0.0, 0.0, w, h), points, scale, terrain,
                             dem_fraction=dem_fraction, dup_fraction=dup_fraction)]
    if kind in _SIMPLE:
        return [_SIMPLE[kind](seed, 0, (0.0, 0.0, w, h), points, scale, terrain)]
    if kind != "mixed":
        raise ValueError("unknown kind %r" % kind)
    # Survey over the western 60 %, three bands of synthetic data in the east.
    n_lidar = int(round(points * 0.6))
    rest = points - n_lidar
    n_band = [rest // 3, rest // 3, rest - 2 * (rest // 3)]
    wl = 0.6 * w
    wb = w - wl
    sections = [LidarSection(seed, 0, (0.0, 0.0, wl, h), n_lidar, scale, terrain,
                             dem_fraction=dem_fraction, dup_fraction=dup_fraction)]
    for k, cls in enumerate((GridSection, UniformSection, DemSection)):
        region = (wl, k * h / 3.0, wb, h / 3.0)
        sections.append(cls(seed, k + 1, region, n_band[k], scale, terrain))
    return sections


def generate(path, points, seed=1, kind="lidar", version="1.2", fmt=None,
             scale=0.01, offset=(480000.0, 4860000.0), epsg=26910, crs="auto",
             extent=None, density=8.0, chunk=1 << 16, dem_fraction=0.04,
             dup_fraction=0.002, describe=None):
    """Writes the cloud; returns a summary dict (also written to `describe`)."""
    if points < 0:
        raise ValueError("--points must be >= 0")
    if chunk < 1:
        raise ValueError("--chunk must be >= 1")
    if not 0.0 <= dem_fraction <= 0.5:
        raise ValueError("--dem-fraction must be in [0, 0.5]")
    if not 0.0 <= dup_fraction <= 0.5:
        raise ValueError("--dup-fraction must be in [0, 0.5]")
    if not density > 0:
        raise ValueError("--density must be positive")
    if fmt is None:
        fmt = {"1.1": 1, "1.2": 3, "1.3": 3, "1.4": 6}.get(version, 3)
    if extent is None:
        extent = default_extent(points, density)
    w, h = float(extent[0]), float(extent[1])
    if not (w > 0 and h > 0):
        raise ValueError("--extent must be positive")
    sc = (float(scale),) * 3
    if max(w, h) / sc[0] >= 2 ** 31 - 1:
        raise ValueError("extent / scale exceeds the int32 lattice")
    off = (float(offset[0]), float(offset[1]), 0.0)
    t0 = time.perf_counter()
    sections = build_sections(kind, points, seed, (w, h), sc, dem_fraction, dup_fraction)
    assert sum(s.count for s in sections) == points
    t_plan = time.perf_counter() - t0
    writer = LasWriter(path, version=version, fmt=fmt, scale=sc, offset=off, epsg=epsg,
                       crs=crs, seed=seed)
    try:
        for s in sections:
            for batch in s.batches(chunk):
                writer.write(batch)
        summary = writer.close()
    except BaseException:
        writer.abort()
        raise
    elapsed = time.perf_counter() - t0
    if summary["points"] != points:
        raise RuntimeError("internal error: wrote %d points, planned %d"
                           % (summary["points"], points))
    summary.update({
        "file": str(path), "kind": kind, "seed": seed, "las_version": version,
        "point_format": fmt, "scale": list(sc), "offset": list(off), "epsg": epsg,
        "extent": [w, h], "chunk": chunk, "seconds": elapsed, "plan_seconds": t_plan,
        "sections": [s.describe(off) for s in sections],
    })
    if describe:
        with open(describe, "w") as f:
            json.dump(summary, f, indent=1)
    return summary
