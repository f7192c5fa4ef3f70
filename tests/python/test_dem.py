"""gdt-tile --dem: the GeoTIFF of the TIN, end to end.

The oracle is independent of the C code: from the written PLY alone (its
lattice comment gives back the exact integers), it rebuilds the grid by the
documented rule (core/gdt_raster.h), locates every cell centre in the
triangles with Python integers (the half-open ownership rule: strictly
inside, or on a west or south edge), interpolates by the documented double
formula and rounds to float32; every cell of our GeoTIFF must have the same
bits, nodata elsewhere.  gdal_grid's linear interpolation (its own qhull
triangulation) must agree within 1e-6 relative wherever the triangulation is
unique.  The file must be a Cloud Optimized GeoTIFF with the input's CRS and
the nodata value, the same bytes run after run, whatever the memory budget,
and the same from --reference and --single-tile.
"""
import json
import math
import os
import pathlib
import shutil
import signal
import struct
import subprocess
import sys

import numpy as np
import pytest
from ply_util import read_ply_triangles as read_ply

ROOT = pathlib.Path(__file__).resolve().parents[2]
GEN = ROOT / "scripts" / "gen_cloud.py"
COG_VALIDATOR = pathlib.Path(
    "/usr/lib/python3/dist-packages/osgeo_utils/samples/validate_cloud_optimized_geotiff.py")

pytestmark = pytest.mark.skipif(shutil.which("gdalinfo") is None,
                                reason="GDAL's tools (Debian gdal-bin) are not installed")


# ---- helpers --------------------------------------------------------------

def gen(runner, path, points, seed, kind="uniform", extra=()):
    r = runner([sys.executable, GEN, path, "--points", str(points), "--seed", str(seed),
                "--kind", kind, "-q", *extra])
    assert r.returncode == 0, r.stderr
    return path


def ply_lattice(header):
    for line in header.splitlines():
        if line.startswith("comment lattice "):
            return [float(t) for t in line.split()[2:6]]
    raise AssertionError("no lattice comment")


def gdalinfo(path):
    r = subprocess.run(["gdalinfo", "-json", "-mdd", "all", str(path)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def raster(path, tmp, dtype="<f4"):
    """Every cell of band 1, exactly (GDAL's raw ENVI copy)."""
    info = gdalinfo(path)
    nc, nr = info["size"]
    raw = tmp / (pathlib.Path(path).name + ".raw")
    r = subprocess.run(["gdal_translate", "-q", "-of", "ENVI", str(path), str(raw)],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return np.fromfile(raw, dtype=dtype).reshape(nr, nc), info


def f32(x):
    return struct.unpack("<f", struct.pack("<f", x))[0]


def owns(u, v, p):
    """The half-open rule on the directed edge u -> v (interior on its left)."""
    d = (v[0] - u[0]) * (p[1] - u[1]) - (v[1] - u[1]) * (p[0] - u[0])
    return d > 0 or (d == 0 and (v[1] < u[1] or (v[1] == u[1] and v[0] > u[0])))


def cross(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


class Oracle:
    """The DEM of a PLY by the documented rules, in Python integers."""

    def __init__(self, ply, res, nodata=-9999.0):
        header, verts, faces = read_ply(ply)
        sx, sy, ox, oy = ply_lattice(header)
        ix = [round((x - ox) / sx) for x in verts[:, 0]]
        iy = [round((y - oy) / sy) for y in verts[:, 1]]
        for k in range(len(verts)):  # the PLY holds ox + sx * i exactly
            assert ox + sx * ix[k] == verts[k, 0] and oy + sy * iy[k] == verts[k, 1]
        self.verts, self.faces, self.ix, self.iy = verts, faces, ix, iy
        if res is None:  # the default: twice the mean spacing of the bounding box
            w = (max(ix) - min(ix)) * sx
            h = (max(iy) - min(iy)) * sy
            assert sx == sy
            res = max(1, round(2 * math.sqrt(w * h / len(verts)) / sx)) * sx
        self.res = res
        mx, my = round(res / sx), round(res / sy)
        ax, ay = round(-ox / sx), round(-oy / sy)
        aligned_x = abs(-ox / sx - ax) <= 1e-9
        aligned_y = abs(-oy / sy - ay) <= 1e-9
        k0 = (min(ix) - ax) // mx
        k1 = (max(ix) - ax) // mx
        ks = (min(iy) - ay) // my
        kn = (max(iy) - ay) // my + 1
        self.ncols, self.nrows = k1 - k0 + 1, kn - ks
        self.x0, self.y0 = ax + k0 * mx, ay + kn * my
        self.mx, self.my = mx, my
        self.west = k0 * res if aligned_x else ox + sx * self.x0
        self.north = kn * res if aligned_y else oy + sy * self.y0
        self.grid = np.full((self.nrows, self.ncols), nodata, dtype="<f4")
        self.owner = np.full((self.nrows, self.ncols), -1, dtype=np.int64)
        for f, tri in enumerate(faces):
            self._triangle(f, [int(t) for t in tri])

    def centre(self, r, c):
        return (2 * self.x0 + self.mx * (2 * c + 1), 2 * self.y0 - self.my * (2 * r + 1))

    def _triangle(self, f, tri):
        p = [(2 * self.ix[k], 2 * self.iy[k]) for k in tri]
        z = [float(self.verts[k, 2]) for k in tri]
        d = cross(p[0], p[1], p[2])
        assert d > 0, "PLY faces are counter-clockwise"
        first = min(range(3), key=lambda i: p[i])
        a, b, c = (p[(first + i) % 3] for i in range(3))
        za, zb, zc = (z[(first + i) % 3] for i in range(3))
        xs, ys = [q[0] for q in p], [q[1] for q in p]
        dx = 2 * self.mx
        c_lo = max(0, -((2 * self.x0 + self.mx - min(xs)) // dx))
        c_hi = min(self.ncols - 1, (max(xs) - 2 * self.x0 - self.mx) // dx)
        r_lo = max(0, -((max(ys) - 2 * self.y0 + self.my) // (2 * self.my)))
        r_hi = min(self.nrows - 1, (2 * self.y0 - self.my - min(ys)) // (2 * self.my))
        for r in range(r_lo, r_hi + 1):
            for col in range(c_lo, c_hi + 1):
                q = self.centre(r, col)
                if not (owns(a, b, q) and owns(b, c, q) and owns(c, a, q)):
                    continue
                wa, wb, wc = cross(b, c, q), cross(c, a, q), cross(a, b, q)
                assert wa + wb + wc == d
                val = ((float(wa) * za + float(wb) * zb) + float(wc) * zc) / float(d)
                assert self.owner[r, col] == -1, f"cell ({r}, {col}) owned twice"
                self.owner[r, col] = f
                self.grid[r, col] = f32(val)


def run_dem(runner, gdt_bin, cloud, out_dir, mode=("--reference",), extra=(), name="d"):
    ply = out_dir / f"{name}.ply"
    tif = out_dir / f"{name}.tif"
    js = out_dir / f"{name}.json"
    r = runner([gdt_bin, cloud, *mode, "-q", "-o", ply, "--dem", tif, "--json", js, *extra])
    assert r.returncode == 0, r.stderr
    return ply, tif, json.loads(js.read_text())


def assert_same_cells(ours, oracle):
    assert ours.shape == oracle.grid.shape
    bad = np.argwhere(ours.view("<u4") != oracle.grid.view("<u4"))
    assert len(bad) == 0, (f"{len(bad)} cells differ, first {bad[:5].tolist()}: ours "
                           f"{[float(ours[tuple(b)]) for b in bad[:5]]}, oracle "
                           f"{[float(oracle.grid[tuple(b)]) for b in bad[:5]]}")


# ---- the oracle -----------------------------------------------------------

@pytest.mark.parametrize("kind,res", [("uniform", "0.37"), ("grid", "0.5"), ("lidar", None),
                                      ("dem", "0.25")])
def test_every_cell_equals_the_oracle(gdt_bin, runner, tmp_path, kind, res):
    cloud = gen(runner, tmp_path / "c.las", 4000, 11, kind)
    extra = ("--dem-res", res) if res is not None else ()
    ply, tif, summary = run_dem(runner, gdt_bin, cloud, tmp_path, extra=extra)
    oracle = Oracle(ply, float(res) if res is not None else None)
    ours, info = raster(tif, tmp_path)
    gt = info["geoTransform"]
    assert gt == [oracle.west, oracle.res, 0.0, oracle.north, 0.0, -oracle.res]
    assert_same_cells(ours, oracle)
    assert summary["dem"]["cells_with_value"] == int((oracle.owner >= 0).sum()) > 0
    # a grid cloud puts centres on vertices and edges (res 0.5 = 50 steps: centres on the
    # lattice); the oracle asserted that none is owned twice
    if res is None:
        assert summary["dem"]["res"] == oracle.res


def write_pcd(path, pts):
    lines = ["# .PCD v0.7", "VERSION 0.7", "FIELDS x y z", "SIZE 8 8 8", "TYPE F F F",
             "COUNT 1 1 1", f"WIDTH {len(pts)}", "HEIGHT 1", "VIEWPOINT 0 0 0 1 0 0 0",
             f"POINTS {len(pts)}", "DATA ascii"]
    lines += [f"{x!r} {y!r} {z!r}" for x, y, z in pts]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.sanitize
def test_centres_on_vertices_edges_and_the_hull(gdt_bin, runner, tmp_path):
    """A square grid of unit spacing and cells of 2: every centre is a vertex or lies on
    edges, the hull's east and north sides included (nodata by the rule: only west and
    south edges own their points), plus a slanted hull side through centres."""
    rng = np.random.default_rng(4)
    pts = [(float(x), float(y), float(rng.integers(0, 1000)) / 8.0)
           for x in range(22) for y in range(14) if x + y <= 30]
    cloud = write_pcd(tmp_path / "g.pcd", pts)
    ply, tif, summary = run_dem(runner, gdt_bin, cloud, tmp_path,
                                extra=("--quantum", "1", "--dem-res", "2"))
    oracle = Oracle(ply, 2.0)
    ours, info = raster(tif, tmp_path)
    assert_same_cells(ours, oracle)
    # centres at odd lattice coordinates 1..21 (x) and 1..13 (y): the column x = 21 and
    # the row y = 13 lie on the hull's east and north sides, the line x + y = 30 too
    xs = [(2 * oracle.x0 + oracle.mx * (2 * c + 1)) // 2 for c in range(oracle.ncols)]
    ys = [(2 * oracle.y0 - oracle.my * (2 * r + 1)) // 2 for r in range(oracle.nrows)]
    for r, y in enumerate(ys):
        for c, x in enumerate(xs):
            inside = 0 < x < 21 and 0 < y < 13 and x + y < 30
            on_ws = (x == 0 or y == 0) and x <= 21 and y <= 13
            assert (oracle.owner[r, c] >= 0) == (inside or on_ws), (x, y)
    assert info.get("coordinateSystem", {}).get("wkt", "") == ""


def test_lattice_with_an_origin_off_the_step(gdt_bin, runner, tmp_path):
    """A LAS offset that is not a multiple of the scale: grid lines are the lattice lines
    nearest to multiples of R."""
    cloud = gen(runner, tmp_path / "c.las", 3000, 5, "uniform",
                ("--offset", "480000.005", "4860000.003"))
    ply, tif, _ = run_dem(runner, gdt_bin, cloud, tmp_path, extra=("--dem-res", "0.3"))
    oracle = Oracle(ply, 0.3)
    ours, info = raster(tif, tmp_path)
    assert info["geoTransform"][0] == oracle.west and info["geoTransform"][3] == oracle.north
    assert_same_cells(ours, oracle)


def test_real_samples_equal_the_oracle(gdt_bin, runner, tmp_path, data_dir):
    for name in ["100-points.las", "autzen-utm.pcd", "autzen_trim.las"]:
        out = tmp_path / name
        out.mkdir()
        ply, tif, summary = run_dem(runner, gdt_bin, data_dir / name, out)
        oracle = Oracle(ply, None)
        ours, info = raster(tif, out)
        assert_same_cells(ours, oracle)
        header = read_ply(ply)[0]
        crs = [ln for ln in header.splitlines() if ln.startswith("comment crs ")]
        wkt = info.get("coordinateSystem", {}).get("wkt", "").replace("\n", "")
        if crs and crs[0].startswith("comment crs EPSG:"):
            code = crs[0].split("EPSG:")[1].split()[0]
            assert wkt.endswith(f'ID["EPSG",{code}]]')
        elif crs and crs[0].startswith("comment crs PROJCS["):
            name = crs[0].split('PROJCS["')[1].split('"')[0]
            assert wkt.startswith(f'PROJCRS["{name}"')
        else:
            assert wkt == ""


# ---- gdal_grid ------------------------------------------------------------

def test_agrees_with_gdal_grid(gdt_bin, runner, tmp_path):
    """gdal_grid -a linear:radius=0 triangulates with qhull and interpolates linearly: the
    same values within 1e-6 relative in every cell whose triangle is unique (not one of a
    co-circular pair, where qhull may take the other diagonal), the same nodata cells
    apart from centres on the hull."""
    cloud = gen(runner, tmp_path / "c.las", 6000, 23, "uniform")
    ply, tif, _ = run_dem(runner, gdt_bin, cloud, tmp_path, extra=("--dem-res", "0.29"))
    oracle = Oracle(ply, 0.29)
    ours, info = raster(tif, tmp_path)
    verts, faces = oracle.verts, oracle.faces
    # triangles of co-circular quads (exact in-circle on every interior edge)
    ix, iy = oracle.ix, oracle.iy
    edge = {}
    for f, t in enumerate(faces):
        for k in range(3):
            edge[(int(t[(k + 1) % 3]), int(t[(k + 2) % 3]))] = (f, int(t[k]))
    ambiguous = set()
    for (u, v), (f, w) in edge.items():
        other = edge.get((v, u))
        if other is None:
            continue
        rows = []
        for p in (u, v, w):
            dx, dy = ix[p] - ix[other[1]], iy[p] - iy[other[1]]
            rows.append((dx, dy, dx * dx + dy * dy))
        (a1, a2, a3), (b1, b2, b3), (c1, c2, c3) = rows
        if a1 * (b2 * c3 - b3 * c2) - a2 * (b1 * c3 - b3 * c1) + a3 * (b1 * c2 - b2 * c1) == 0:
            ambiguous |= {f, other[0]}
    # centres on a hull edge
    on_hull = np.zeros(ours.shape, dtype=bool)
    for (u, v) in edge:
        if (v, u) in edge:
            continue
        a, b = (2 * ix[u], 2 * iy[u]), (2 * ix[v], 2 * iy[v])
        for r in range(oracle.nrows):
            for c in range(oracle.ncols):
                q = oracle.centre(r, c)
                if cross(a, b, q) == 0 and min(a[0], b[0]) <= q[0] <= max(a[0], b[0]) and \
                        min(a[1], b[1]) <= q[1] <= max(a[1], b[1]):
                    on_hull[r, c] = True

    x0, y0 = float(verts[:, 0].min()), float(verts[:, 1].min())
    csv = tmp_path / "p.csv"
    with open(csv, "w") as fh:
        fh.write("x,y,z\n")
        for x, y, z in verts:
            fh.write(f"{x - x0!r},{y - y0!r},{z!r}\n")
    vrt = tmp_path / "p.vrt"
    vrt.write_text('<OGRVRTDataSource><OGRVRTLayer name="p"><SrcDataSource>'
                   f'{csv}</SrcDataSource><GeometryType>wkbPoint</GeometryType>'
                   '<GeometryField encoding="PointFromColumns" x="x" y="y" z="z"/>'
                   '</OGRVRTLayer></OGRVRTDataSource>')
    gt = info["geoTransform"]
    nc, nr = info["size"]
    west, north = gt[0] - x0, gt[3] - y0
    east, south = west + nc * gt[1], north + nr * gt[5]
    grid_tif = tmp_path / "g.tif"
    r = runner(["gdal_grid", "-q", "-a", "linear:radius=0:nodata=-9999", "-ot", "Float64",
                "-txe", repr(west), repr(east), "-tye", repr(north), repr(south),
                "-outsize", nc, nr, "-zfield", "z", "-l", "p", vrt, grid_tif])
    assert r.returncode == 0, r.stderr
    theirs, _ = raster(grid_tif, tmp_path, "<f8")
    mine = ours.astype(np.float64)
    unique = ~np.isin(oracle.owner, list(ambiguous)) if ambiguous else np.ones(ours.shape, bool)
    have_ours, have_theirs = mine != -9999.0, theirs != -9999.0
    assert np.array_equal(have_ours[~on_hull], have_theirs[~on_hull])
    both = have_ours & have_theirs & unique
    assert both.sum() > 0.9 * have_ours.sum() > 1000
    rel = np.abs(mine - theirs) / np.maximum(1.0, np.abs(theirs))
    assert rel[both].max() <= 1e-6, f"largest difference {rel[both].max()}"


# ---- the half-lattice predicates at extreme coordinates ----------------------

def test_half_lattice_predicates_equal_big_integers(tool):
    """gdt_orient2d_half_det, gdt_edge_owns_half and gdt_edge_owned_range against Python's
    integers, up to |coordinate| = 2^60 (products of 2^122) and on lines."""
    import random
    rnd = random.Random(8)
    lim = 1 << 60
    lines, want = [], []
    for t in range(3000):
        big = t % 3 != 0
        span = (lim if t % 5 else lim // 8) if big else 50

        def c():
            return rnd.randint(-span, span)
        a, b = (c(), c()), (c(), c())
        if t % 7 == 0:  # a horizontal edge
            b = (b[0], a[1])
        if t % 5 == 0:  # p on the line a-b: a + k (b - a)
            k = rnd.randint(-2, 2)
            p = (a[0] + k * (b[0] - a[0]), a[1] + k * (b[1] - a[1]))
        else:
            p = (c(), c())
        lines.append(f"0 {a[0]} {a[1]} {b[0]} {b[1]} {p[0]} {p[1]}")
        want.append(str(cross(a, b, p)))
        if a != b:
            lines.append(f"1 {a[0]} {a[1]} {b[0]} {b[1]} {p[0]} {p[1]}")
            want.append("1" if owns(a, b, p) else "0")
            dx = rnd.randint(1, (1 << 53) if big else 4)
            x0 = rnd.randint(-(1 << 59), 1 << 59) if big else rnd.randint(-60, 0)
            y = p[1] if t % 4 == 0 else c()
            lo, hi = rnd.randint(0, 10), rnd.randint(10, 50)
            lines.append(f"2 {a[0]} {a[1]} {b[0]} {b[1]} {x0} {dx} {y} {lo} {hi}")
            ks = [k for k in range(lo, hi + 1) if owns(a, b, (x0 + k * dx, y))]
            assert ks == list(range(ks[0], ks[-1] + 1)) if ks else True
            want.append(f"{ks[0]} {ks[-1]}" if ks else None)
    r = subprocess.run([str(tool("half_eval"))], input="\n".join(lines) + "\n",
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    got = r.stdout.split("\n")
    for line, w, g in zip(lines, want, got):
        if w is None:  # empty: lo > hi
            lo, hi = map(int, g.split())
            assert lo > hi, line
        else:
            assert g == w, f"{line}: {g}, want {w}"
    assert len(got) == len(lines) + 1
    assert sum(1 for ln, w in zip(lines, want) if ln[0] == "0" and w == "0") > 300


# ---- the file --------------------------------------------------------------

def test_cog_layout_crs_nodata_and_preview(gdt_bin, runner, tmp_path):
    cloud = gen(runner, tmp_path / "c.las", 20000, 3, "lidar", ("--epsg", "32633"))
    png = tmp_path / "p.png"
    ply, tif, summary = run_dem(runner, gdt_bin, cloud, tmp_path,
                                extra=("--dem-res", "0.05", "--dem-nodata", "-32768",
                                       "--preview", png))
    info = gdalinfo(tif)
    assert info["driverShortName"] == "GTiff"
    assert '"EPSG",32633' in info["coordinateSystem"]["wkt"].replace("\n", "").replace(" ", "")
    band = info["bands"][0]
    assert band["type"] == "Float32" and band["noDataValue"] == -32768.0
    assert band["block"] == [512, 512]
    assert band.get("overviews"), "a raster larger than a block has overviews"
    st = info["metadata"]["IMAGE_STRUCTURE"]
    assert st["LAYOUT"] == "COG" and st["COMPRESSION"] == "DEFLATE" and st["PREDICTOR"] == "3"
    if COG_VALIDATOR.exists() and pathlib.Path("/usr/bin/python3").exists():
        v = runner(["/usr/bin/python3", COG_VALIDATOR, tif])
        if "No module named" not in v.stderr:
            assert v.returncode == 0 and "is a valid cloud optimized GeoTIFF" in v.stdout, \
                v.stdout + v.stderr
    # preview: a PNG, long side min(2048, DEM's), aspect kept
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    w, h = struct.unpack(">II", data[16:24])
    nc, nr = info["size"]
    longest = max(nc, nr)
    assert max(w, h) == min(2048, longest)
    if longest > 2048:
        assert (w, h) == (round(nc * 2048 / longest), round(nr * 2048 / longest))
    pinfo = gdalinfo(png)
    assert pinfo["driverShortName"] == "PNG" and pinfo["bands"][0]["type"] == "Byte"
    assert not (tmp_path / "p.png.aux.xml").exists() and not (tmp_path / "d.tif.aux.xml").exists()
    # nothing else beside the outputs: no temporary or scratch file left
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        ["c.las", "d.ply", "d.tif", "d.json", "p.png"])


def overview(path, tmp, level, nodata):
    """Every cell of overview level (1-based) of band 1, exactly."""
    raw = tmp / f"ovr{level}.raw"
    r = subprocess.run(["gdal_translate", "-q", "-ovr", str(level - 1), "-of", "ENVI", str(path),
                        str(raw)], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    hdr = {k.strip(): v.strip() for k, v in
           (line.split("=", 1) for line in (tmp / f"ovr{level}.hdr").read_text().splitlines()
            if "=" in line)}
    nc, nr = int(hdr["samples"]), int(hdr["lines"])
    return np.fromfile(raw, dtype="<f4").reshape(nr, nc)


@pytest.mark.parametrize("mode", [("--reference",), ("--tile", "64")])
def test_overviews_are_footprint_means(gdt_bin, runner, tmp_path, mode):
    """Each overview level k has ceil(n / 2^k) cells a side, each the mean of
    the cells with a value in its 2^k x 2^k footprint of the full-resolution
    DEM, nodata where the footprint has none (computed here with numpy from
    the full-resolution cells)."""
    cloud = gen(runner, tmp_path / "c.las", 12000, 5, "lidar")
    nd = -9999.0
    _, tif, _ = run_dem(runner, gdt_bin, cloud, tmp_path, mode=mode,
                        extra=("--dem-res", "0.03", "--dem-nodata", str(nd)))
    full, info = raster(tif, tmp_path)
    ovrs = info["bands"][0].get("overviews", [])
    nr, nc = full.shape
    assert max(nr, nc) > 1024 and len(ovrs) >= 2, (full.shape, ovrs)
    valid = full != np.float32(nd)
    for k in range(1, len(ovrs) + 1):
        f = 2 ** k
        want_r, want_c = -(-nr // f), -(-nc // f)
        assert ovrs[k - 1]["size"] == [want_c, want_r]
        pr, pc = want_r * f - nr, want_c * f - nc
        v = np.pad(np.where(valid, full.astype(np.float64), 0.0), ((0, pr), (0, pc)))
        cnt = np.pad(valid.astype(np.int64), ((0, pr), (0, pc)))
        sums = v.reshape(want_r, f, want_c, f).sum(axis=(1, 3))
        cnts = cnt.reshape(want_r, f, want_c, f).sum(axis=(1, 3))
        ours = overview(tif, tmp_path, k, nd)
        assert ours.shape == (want_r, want_c)
        has = cnts > 0
        assert np.array_equal(ours != np.float32(nd), has), f"level {k}: nodata pattern"
        mean = (sums[has] / cnts[has]).astype(np.float32)
        assert np.allclose(ours[has], mean, rtol=1e-6, atol=0), \
            f"level {k}: max diff {np.max(np.abs(ours[has] - mean))}"


def test_same_bytes_twice_any_budget_and_both_modes(gdt_bin, runner, tmp_path):
    """Run twice, with a budget that forces the block cache to spill (the raster has
    more blocks than 16 MiB holds) and one that holds it all, and from --single-tile:
    the same GeoTIFF and PNG bytes."""
    cloud = gen(runner, tmp_path / "c.las", 20000, 9, "uniform")
    outs = []
    for i, (mode, budget) in enumerate([(("--reference",), "16M"), (("--reference",), "16M"),
                                        (("--reference",), "4G"),
                                        (("--tile", "256", "--single-tile"), "4G")]):
        d = tmp_path / f"run{i}"
        d.mkdir()
        ply, tif, summary = run_dem(runner, gdt_bin, cloud, d, mode,
                                    ("--dem-res", "0.02", "--mem-budget", budget,
                                     "--preview", d / "p.png"))
        outs.append((tif.read_bytes(), (d / "p.png").read_bytes(), summary["dem"]))
    assert outs[0][2]["spills"] > 0 and outs[2][2]["spills"] == 0
    assert outs[0][2]["blocks"] > outs[0][2]["cache_blocks"]
    for o in outs[1:]:
        assert o[0] == outs[0][0] and o[1] == outs[0][1]


def test_empty_blocks_read_nodata_from_either_intermediate(gdt_bin, runner, tmp_path):
    """Two clusters at opposite corners of a 3000 x 3000-cell raster with its
    long edges trimmed: most 512 x 512 blocks hold no value.  The intermediate
    the COG is copied from is a sparse GeoTIFF when the cache cannot hold every
    block (16M) and an in-memory raster when it can (4G), where empty blocks and
    overview cells must be filled with nodata: the same GeoTIFF bytes, every
    empty block nodata, and overview level 1 nodata exactly where its
    footprint has no value."""
    rng = np.random.default_rng(5)
    pts = []
    for cx, cy in ((3.0, 3.0), (57.0, 57.0)):
        for x, y in rng.uniform(-2.0, 2.0, size=(300, 2)):
            pts.append((round(cx + x, 2), round(cy + y, 2), round(float(rng.uniform(0, 9)), 2)))
    pts += [(0.0, 0.0, 1.0), (60.0, 60.0, 2.0)]  # the raster spans 60 m
    cloud = write_pcd(tmp_path / "c.pcd", pts)
    outs = []
    for budget in ("16M", "4G"):
        d = tmp_path / budget
        d.mkdir()
        _, tif, summary = run_dem(runner, gdt_bin, cloud, d,
                                  extra=("--quantum", "0.01", "--dem-res", "0.02",
                                         "--max-edge", "3", "--mem-budget", budget))
        outs.append((tif, summary["dem"]))
    (tif16, s16), (tif4g, s4g) = outs
    # the intermediate is in memory exactly when the cache can hold every block
    assert s16["blocks"] == 36 and s16["cache_blocks"] < 36 and s4g["cache_blocks"] >= 36
    assert tif16.read_bytes() == tif4g.read_bytes()
    nd = np.float32(-9999.0)
    cells, _ = raster(tif4g, tmp_path)
    valid = cells != nd
    assert 0 < valid.sum() < cells.size
    blocks_with_values = {(r // 512, c // 512) for r, c in np.argwhere(valid)}
    assert 2 <= len(blocks_with_values) <= 8, blocks_with_values  # the two corners
    ovr = overview(tif4g, tmp_path, 1, nd)
    h, w = (cells.shape[0] + 1) // 2, (cells.shape[1] + 1) // 2
    pad = np.zeros((2 * h, 2 * w), dtype=bool)
    pad[:cells.shape[0], :cells.shape[1]] = valid
    any_valid = pad.reshape(h, 2, w, 2).any(axis=(1, 3))
    assert ovr.shape == (h, w)
    assert np.array_equal(ovr != nd, any_valid)


# ---- the tiled run ------------------------------------------------------------

@pytest.mark.parametrize("kind,tile_args", [
    pytest.param("lidar", ["--tile", "64", "--halo", "0"], marks=pytest.mark.sanitize),
    ("lidar", ["--tile", "64", "--halo", "3", "--threads", "1"]),
    ("grid", ["--tile", "64"]),
    ("uniform", ["--tile", "128", "--mem-budget", "16M"]),
])
def test_tiled_run_writes_the_reference_dem(gdt_bin, runner, tmp_path, kind, tile_args):
    """Certified faces rasterised by the mesh writer thread as it copies them, the merge's
    faces as it copies those: every cell once, the same bytes as --reference (and the
    oracle)."""
    cloud = gen(runner, tmp_path / "c.las", 12000, 17, kind)
    ref = tmp_path / "ref"
    ref.mkdir()
    rply, rtif, _ = run_dem(runner, gdt_bin, cloud, ref, extra=("--preview", ref / "p.png"))
    til = tmp_path / "tiled"
    til.mkdir()
    tply, ttif, summary = run_dem(runner, gdt_bin, cloud, til, tile_args,
                                  ("--preview", til / "p.png", "--job", til / "job"))
    assert summary["tiles"] >= 4 and summary["seam_vertices"] > 0
    assert ttif.read_bytes() == rtif.read_bytes()
    assert (til / "p.png").read_bytes() == (ref / "p.png").read_bytes()
    oracle = Oracle(tply, summary["dem"]["res"])
    ours, _ = raster(ttif, til)
    assert_same_cells(ours, oracle)
    assert not (til / "job").exists()


@pytest.mark.parametrize("trim", [("--concavity", "0.6"), ("--max-edge", "0.5"),
                                  ("--concavity", "0.4", "--max-edge", "0.9")])
def test_trimmed_triangles_are_nodata_whatever_the_tiling(gdt_bin, runner, tmp_path, trim):
    """The DEM takes the faces the mesh keeps: cells in trimmed triangles are
    nodata, the tiled run writes --reference's bytes, and the oracle built from
    the trimmed PLY's faces agrees on every cell."""
    cloud = gen(runner, tmp_path / "c.las", 12000, 23, "lidar")
    ref = tmp_path / "ref"
    ref.mkdir()
    full_ply, full_tif, _ = run_dem(runner, gdt_bin, cloud, ref, name="full")
    rply, rtif, rs = run_dem(runner, gdt_bin, cloud, ref, extra=trim)
    assert rs["trim"]["dropped"] > 0
    full, _ = raster(full_tif, ref)
    ours_ref, _ = raster(rtif, ref)
    assert (ours_ref == -9999).sum() > (full == -9999).sum(), "no cell was trimmed"
    for tile in ("64", "256"):
        til = tmp_path / f"t{tile}"
        til.mkdir()
        tply, ttif, ts = run_dem(runner, gdt_bin, cloud, til, ("--tile", tile), trim)
        assert ts["trim"] == rs["trim"]
        assert ttif.read_bytes() == rtif.read_bytes(), f"--tile {tile}"
        oracle = Oracle(tply, ts["dem"]["res"])
        ours, _ = raster(ttif, til)
        assert_same_cells(ours, oracle)


def test_tiled_dem_of_a_real_sample(gdt_bin, runner, tmp_path, data_dir):
    cloud = data_dir / "autzen_trim.las"
    outs = []
    for name, mode in [("ref", ("--reference",)), ("tiled", ("--tile", "128", "--halo", "1"))]:
        d = tmp_path / name
        d.mkdir()
        _, tif, _ = run_dem(runner, gdt_bin, cloud, d, mode,
                            ("--dem-res", "2", "--preview", d / "p.png"))
        outs.append((tif.read_bytes(), (d / "p.png").read_bytes()))
    assert outs[0] == outs[1]


def test_tiled_dem_spills_and_resumes(gdt_bin, runner, tmp_path):
    """A raster larger than the DEM's share of the budget, and a rerun that reuses every
    tile: the same bytes as --reference."""
    cloud = gen(runner, tmp_path / "c.las", 20000, 9, "uniform")
    ref = tmp_path / "ref"
    ref.mkdir()
    _, rtif, _ = run_dem(runner, gdt_bin, cloud, ref, extra=("--dem-res", "0.02"))
    til = tmp_path / "tiled"
    til.mkdir()
    args = ("--dem-res", "0.02", "--mem-budget", "16M", "--job", til / "job", "--keep-job")
    _, ttif, s1 = run_dem(runner, gdt_bin, cloud, til, ("--tile", "128"), args)
    assert s1["dem"]["spills"] > 0
    assert ttif.read_bytes() == rtif.read_bytes()
    ttif.unlink()
    _, ttif, s2 = run_dem(runner, gdt_bin, cloud, til, ("--tile", "128"), args)
    assert s2["resumed"] and s2["reused"]["tiles"] == s2["tiles"]
    assert ttif.read_bytes() == rtif.read_bytes()
    assert not [p for p in (til / "job").iterdir() if p.name.startswith("gdt-dem")]


# ---- options ----------------------------------------------------------------

@pytest.mark.sanitize
@pytest.mark.parametrize("args,code,word", [
    (["--dem-res", "0"], "2002", "--dem-res"),
    (["--dem-res", "-1"], "2002", "--dem-res"),
    (["--dem-res", "nan"], "2001", "--dem-res"),
    (["--dem-res", "inf"], "2001", "--dem-res"),
    (["--dem-res", "abc"], "2001", "--dem-res"),
    (["--dem-res", "0.015"], "2601", "--dem-res"),
    (["--dem-nodata", "0.1"], "2604", "--dem-nodata"),
    (["--dem-nodata", "nan"], "2001", "--dem-nodata"),
])
def test_bad_dem_values_exit_2(gdt_bin, runner, tmp_path, args, code, word):
    cloud = gen(runner, tmp_path / "c.las", 500, 1)
    tif = tmp_path / "d.tif"
    r = runner([gdt_bin, cloud, "--reference", "-q", "-o", tmp_path / "m.ply", "--dem", tif,
                *args])
    assert r.returncode == 2, r.stderr
    assert f"GDT-{code}" in r.stderr and word in r.stderr
    assert not tif.exists() and not (tmp_path / "m.ply").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(("d.tif", "gdt-dem"))]


def test_tiled_run_refuses_a_bad_cell_size_before_the_work(gdt_bin, runner, tmp_path):
    cloud = gen(runner, tmp_path / "c.las", 2000, 1)
    r = runner([gdt_bin, cloud, "--tile", "64", "-q", "-o", tmp_path / "m.ply", "--dem",
                tmp_path / "d.tif", "--dem-res", "0.015"])
    assert r.returncode == 2 and "GDT-2601" in r.stderr, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.las"]


@pytest.mark.sanitize
@pytest.mark.parametrize("args,code", [
    (["--reference", "--preview", "{t}/p.png"], "2605"),
    (["--reference", "--dem-res", "1"], "2605"),
    (["--info", "--dem", "{t}/d.tif"], "2606"),
    (["--reference", "--dem", "{t}/m.ply"], "2208"),
    (["--reference", "--dem", "{t}/d.tif", "--preview", "{t}/d.tif"], "2208"),
    (["--reference", "--dem", "{t}/c.las"], "2202"),
    (["--reference", "--dem", "{t}/nodir/d.tif"], "2206"),
    (["--reference", "--dem", "{t}/d.tif", "--preview", "{t}/nodir/p.png"], "2206"),
])
def test_dem_usage_errors(gdt_bin, runner, tmp_path, args, code):
    cloud = gen(runner, tmp_path / "c.las", 500, 1)
    before = (tmp_path / "c.las").read_bytes()
    r = runner([gdt_bin, cloud, "-q", "-o", tmp_path / "m.ply",
                *[a.format(t=tmp_path) for a in args]])
    assert r.returncode == 2, r.stderr
    assert f"GDT-{code}" in r.stderr
    assert (tmp_path / "c.las").read_bytes() == before
    assert not (tmp_path / "d.tif").exists() and not (tmp_path / "m.ply").exists()


def test_help_lists_the_dem_options(gdt_bin, runner):
    r = runner([gdt_bin, "--help"])
    assert r.returncode == 0
    for opt in ["--dem OUT.tif", "--dem-res R", "--dem-nodata V", "--preview OUT.png"]:
        assert opt in r.stdout


# ---- invariance: tiling, threads, input order, a killed run ------------------

def _dem_bytes(runner, gdt_bin, inputs, out_dir, args):
    """The DEM bytes and --json summary of one run of gdt-tile on inputs (one or more)."""
    out_dir.mkdir()
    inputs = [inputs] if isinstance(inputs, pathlib.Path) else list(inputs)
    tif, js = out_dir / "d.tif", out_dir / "d.json"
    r = runner([gdt_bin, *inputs, "-q", "-o", out_dir / "d.ply", "--dem", tif, "--json", js,
                *args])
    assert r.returncode == 0, r.stderr
    return tif.read_bytes(), json.loads(js.read_text())


@pytest.mark.parametrize("trim", [(), ("--concavity", "0.8")])
def test_same_dem_bytes_any_tiling_threads_and_input_order(gdt_bin, runner, tmp_path, trim):
    """--tile 64 to 4096 (one tile), --threads 1 and 2, the records shuffled, the cloud
    split into two files given in either order: the same GeoTIFF bytes as --reference
    (the PLY's vertex order follows the input order; the raster does not).  The lidar
    cloud has duplicate (x, y) with other z: --dup min-z makes the kept z independent of
    the input order (the default, first, is not)."""
    from tiled_util import permute_las
    cloud = gen(runner, tmp_path / "c.las", 15000, 31, "lidar")
    shuffled = permute_las(cloud, tmp_path / "s.las", 7)
    halves = permute_las(cloud, tmp_path / "h.las", 8, parts=2)
    trim = ("--dup", "min-z", *trim)
    want, ws = _dem_bytes(runner, gdt_bin, cloud, tmp_path / "ref", ("--reference", *trim))
    assert ws["duplicates_merged"] > 0
    if len(trim) > 2:
        assert ws["trim"]["dropped"] > 0
    cases = [(cloud, ("--tile", t)) for t in ("64", "256", "1024", "4096")]
    cases += [(cloud, ("--tile", "64", "--threads", k)) for k in ("1", "2")]
    cases += [(shuffled, ("--tile", "64")), (shuffled, ("--tile", "256", "--threads", "1")),
              (halves, ("--tile", "64")), (halves[::-1], ("--tile", "64", "--threads", "2"))]
    tiles = {}
    for i, (inputs, args) in enumerate(cases):
        got, s = _dem_bytes(runner, gdt_bin, inputs, tmp_path / f"run{i}", (*args, *trim))
        tiles[args[1]] = s["tiles"]
        assert got == want, f"DEM differs: {inputs} {args}"
        if "trim" in ws:
            assert s["trim"] == ws["trim"], args
    assert tiles["4096"] == 1 and tiles["64"] >= 4


@pytest.mark.parametrize("stage,offset,trim", [("tiles", 0.05, ()),
                                               ("merge", 0.0, ()),
                                               ("merge", 0.0, ("--concavity", "0.8"))])
def test_killed_run_resumes_to_the_same_dem_bytes(gdt_bin, runner, tmp_path, stage, offset,
                                                  trim):
    """SIGKILL during the tile stage or at the merge, then the same command again: the
    GeoTIFF (and the PLY) of an uninterrupted run.  A kill before the output is
    written leaves neither file; the seam merge may finish beside the tile stage,
    so a kill "at the merge" can land in the writing, where the mesh is put in
    place before the DEM: then there is never a DEM without its mesh."""
    import resume_util as ru
    cloud = gen(runner, tmp_path / "c.las", 20000, 37, "lidar")
    want, _ = _dem_bytes(runner, gdt_bin, cloud, tmp_path / "want",
                         ("--tile", "64", "--dem-res", "0.25", *trim))
    out, tif = tmp_path / "o.ply", tmp_path / "o.tif"
    cmd = [gdt_bin, cloud, "-o", out, "--dem", tif, "--dem-res", "0.25", "--tile", 64,
           "--threads", 1, "--job", tmp_path / "job", *trim]
    p = ru.Run(cmd)
    p.stop_in(stage, offset)
    rc = p.finish()
    assert rc in (0, -signal.SIGKILL), p.stderr
    if rc != 0:
        if p.died_in in ("tiles", "merge", "after tiles", "after merge"):
            assert not tif.exists() and not out.exists(), p.died_in
        else:
            assert out.exists() or not tif.exists(), p.died_in
    r = runner([*cmd, "-q"])
    assert r.returncode == 0, r.stderr
    assert tif.read_bytes() == want
    assert out.read_bytes() == (tmp_path / "want" / "d.ply").read_bytes()


@pytest.mark.parametrize("fails", ["mesh", "dem", "preview"])
def test_a_failed_sync_publishes_neither_a_new_dem_nor_a_new_mesh(gdt_bin, runner, tools_dir,
                                                                  tmp_path, fails):
    """The DEM is built beside the mesh's sync and put in place only after the
    mesh: when the mesh's fsync fails (an LD_PRELOAD shim), the run exits 4
    and the DEM already at the path is not replaced; when the DEM's fails,
    the run exits 4 too, the complete mesh is in place and the old DEM
    stays; when only the preview's fails, the mesh and the new DEM are in
    place and the old preview stays.  No temporary is left, and a rerun
    resumes to the bytes of an undisturbed run."""
    shim = tools_dir / "libgdt_fail_write.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_write.so not built at {shim}")
    cloud = gen(runner, tmp_path / "c.las", 20000, 23, "lidar")
    out, tif, job, log = tmp_path / "o.ply", tmp_path / "x.tif", tmp_path / "job", tmp_path / "log"
    png = tmp_path / "p.png"
    tif.write_bytes(b"an older DEM")
    png.write_bytes(b"an older preview")
    args = [gdt_bin, cloud, "--tile", "64", "-q", "-o", out, "--dem", tif, "--preview", png,
            "--job", job]
    match = {"mesh": "o.ply.tmp-", "dem": "x.tif.tmp-", "preview": "p.png.tmp-"}[fails]
    env = dict(os.environ, LD_PRELOAD=str(shim), GDT_TEST_FAIL_WRITE_LOG=str(log),
               GDT_TEST_FAIL_FSYNC_MATCH=match)
    r = subprocess.run([str(a) for a in args], capture_output=True, text=True, env=env,
                       timeout=300)
    assert log.exists(), r.stderr  # the shim refused an fsync
    assert r.returncode == 4, r.stderr
    assert "fsync" in r.stderr and "Input/output error" in r.stderr, r.stderr
    assert png.read_bytes() == b"an older preview"
    assert (tif.read_bytes() == b"an older DEM") == (fails != "preview")
    assert out.exists() == (fails != "mesh")
    assert [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name] == []
    ref = tmp_path / "ref"
    ref.mkdir()
    _, rtif, _ = run_dem(runner, gdt_bin, cloud, ref, ("--tile", "64"),
                         ("--preview", ref / "p.png"))
    if fails == "preview":  # the DEM in place is already the complete one
        assert tif.read_bytes() == rtif.read_bytes()
    r = runner([*args, "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stderr
    assert tif.read_bytes() == rtif.read_bytes()
    assert png.read_bytes() == (ref / "p.png").read_bytes()
    assert out.read_bytes() == (ref / "d.ply").read_bytes()
