"""Tests of scripts/gen_cloud.py, the synthetic LAS generator.

Files are read back with laspy (an independent LAS implementation); the
layout the generator reports with --describe says where lakes and DEM patches
are, and every such claim is checked against the points themselves.
"""
import json
import pathlib
import struct
import subprocess
import sys

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

ROOT = pathlib.Path(__file__).resolve().parents[2]
GEN = ROOT / "scripts" / "gen_cloud.py"


def gen(out, points, *args, describe=False, check=True):
    cmd = [sys.executable, str(GEN), str(out), "--points", str(points), "-q"]
    cmd += [str(a) for a in args]
    desc = None
    if describe:
        desc = out.with_suffix(".json")
        cmd += ["--describe", str(desc)]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    if check:
        assert r.returncode == 0, r.stderr
    if describe:
        return json.loads(desc.read_text())
    return r


def ints(las):
    p = las.points.array
    return (p["X"].astype(np.int64), p["Y"].astype(np.int64), p["Z"].astype(np.int64))


@pytest.fixture(scope="module")
def lidar(tmp_path_factory):
    """A lidar cloud large enough to hold every feature (lakes, DEM patches)."""
    d = tmp_path_factory.mktemp("lidar")
    path = d / "lidar.las"
    desc = gen(path, 60000, "--seed", 7, describe=True)
    return path, desc, laspy.read(path)


# ------------------------------------------------------------ counts, bounds

@pytest.mark.parametrize("kind,n", [("lidar", 30000), ("grid", 5000), ("uniform", 5000),
                                    ("dem", 5001), ("mixed", 40000),
                                    ("lidar", 0), ("lidar", 1), ("grid", 7), ("dem", 3),
                                    ("mixed", 11)])
def test_counts_and_header_bounds_exact(tmp_path, kind, n):
    path = tmp_path / "c.las"
    gen(path, n, "--kind", kind, "--seed", 3)
    las = laspy.read(path)
    h = las.header
    assert h.point_count == n
    assert len(las.points) == n
    assert path.stat().st_size == h.offset_to_point_data + n * h.point_format.size
    assert not (tmp_path / "c.las.part").exists()
    if n == 0:
        return
    X, Y, Z = ints(las)
    for i, a in enumerate((X, Y, Z)):
        # Header bounds are exactly those of the records (same formula as laspy).
        assert h.mins[i] == a.min() * h.scales[i] + h.offsets[i]
        assert h.maxs[i] == a.max() * h.scales[i] + h.offsets[i]
    rn = np.asarray(las.return_number)
    by_ret = np.bincount(rn, minlength=6)[1:6]
    assert list(h.number_of_points_by_return[:5]) == list(by_ret)
    assert rn.min() >= 1
    assert (rn <= np.asarray(las.number_of_returns)).all()


def test_extent_offset_and_scale_respected(tmp_path):
    path = tmp_path / "e.las"
    gen(path, 20000, "--extent", 300, 120, "--offset", 500000, 4100000, "--scale", 0.001)
    las = laspy.read(path)
    h = las.header
    assert list(h.scales) == [0.001] * 3
    assert list(h.offsets[:2]) == [500000.0, 4100000.0]
    assert h.mins[0] >= 500000.0 and h.maxs[0] <= 500300.0
    assert h.mins[1] >= 4100000.0 and h.maxs[1] <= 4100120.0
    # The survey covers its extent (no strip ends short of it).
    assert h.maxs[0] - h.mins[0] > 290 and h.maxs[1] - h.mins[1] > 110


# ------------------------------------------------------------ determinism

@pytest.mark.parametrize("kind,n", [("lidar", 40000), ("mixed", 30000), ("uniform", 3000)])
def test_bytes_independent_of_chunk_size(tmp_path, kind, n):
    outs = []
    for chunk in (97, 4096, 1 << 16):
        p = tmp_path / ("c%d.las" % chunk)
        gen(p, n, "--kind", kind, "--seed", 11, "--chunk", chunk)
        outs.append(p.read_bytes())
    assert outs[0] == outs[1] == outs[2]


def test_seed_determinism_and_sensitivity(tmp_path):
    a, b, c = (tmp_path / "a.las", tmp_path / "b.las", tmp_path / "c.las")
    gen(a, 20000, "--seed", 5)
    gen(b, 20000, "--seed", 5)
    gen(c, 20000, "--seed", 6)
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes() != c.read_bytes()
    la, lc = laspy.read(a), laspy.read(c)
    sa = set(zip(*ints(la)[:2]))
    sc = set(zip(*ints(lc)[:2]))
    # Different seeds give different clouds, not a reshuffle of the same one.
    assert len(sa & sc) < 0.2 * len(sa)


# ------------------------------------------------------------ lidar features

def test_multiple_returns_share_xy_with_distinct_z(lidar):
    _, _, las = lidar
    X, Y, Z = ints(las)
    rn = np.asarray(las.return_number)
    later = np.flatnonzero(rn > 1)
    assert len(later) > 0.03 * len(X)
    # A later return directly follows the earlier returns of its pulse.
    prev = later - 1
    assert (X[later] == X[prev]).all() and (Y[later] == Y[prev]).all()
    # Pure duplicates repeat a record; all other later returns lie below.
    same = (Z[later] == Z[prev]) & (rn[later] == rn[prev])
    assert (Z[later][~same] < Z[prev][~same]).all()
    # Grouped by exact (X, Y): many locations carry several distinct heights.
    xy = X * (1 << 32) + Y
    order = np.lexsort((Z, xy))
    xs, zs = xy[order], Z[order]
    step = (xs[1:] == xs[:-1]) & (zs[1:] != zs[:-1])
    assert step.sum() > 0.02 * len(X)


def test_pure_duplicate_records_present(lidar):
    path, desc, las = lidar
    rec = las.points.array
    dup = np.flatnonzero(rec[1:] == rec[:-1])
    assert len(dup) == desc["sections"][0]["stats"]["duplicate_points"]
    # 0.2 % of pulses by default: a small but non-zero share.
    assert 0.0005 * len(rec) < len(dup) < 0.01 * len(rec)


def test_lakes_are_empty_disks_of_the_stated_size(lidar):
    _, desc, las = lidar
    lakes = desc["sections"][0]["lakes"]
    assert lakes, "the lidar kind places at least one lake"
    x = np.asarray(las.x)
    y = np.asarray(las.y)
    for lake in lakes:
        d = np.hypot(x - lake["x"], y - lake["y"])
        r = lake["r"]
        assert r > 1.0
        assert d.min() >= r - 1e-6, "a point falls inside a lake"
        # Returns resume right at the shore all around: the void is no larger.
        ring = (d >= r) & (d < 1.25 * r)
        ang = np.arctan2(y[ring] - lake["y"], x[ring] - lake["x"])
        sectors = np.unique(np.floor((ang + np.pi) / (np.pi / 8)).astype(int))
        assert len(sectors) >= 16


def _patch_nodes(X, Y, p):
    """Indices of points on patch p's lattice nodes, and its exclusion mask."""
    ox, oy = p["origin"]
    a, b = p["e1"]
    g2 = a * a + b * b
    dx = X - ox
    dy = Y - oy
    u = dx * a + dy * b          # = g2 * column
    v = dy * a - dx * b          # = g2 * row
    # Within half a step of the node set (exact: compare 2u with odd multiples of g2).
    inside = (2 * u >= -g2) & (2 * u <= (2 * p["cols"] - 1) * g2) & \
             (2 * v >= -g2) & (2 * v <= (2 * p["rows"] - 1) * g2)
    node = inside & (u % g2 == 0) & (v % g2 == 0)
    return node, inside


def test_dem_patches_are_exact_lattice_grids(lidar):
    _, desc, las = lidar
    X, Y, Z = ints(las)
    patches = desc["sections"][0]["dem_patches"]
    assert len(patches) >= 2
    assert any(p["e1"][1] != 0 for p in patches), "one patch is rotated"
    assert any(p["e1"][1] == 0 for p in patches), "one patch is axis-aligned"
    for p in patches:
        node, inside = _patch_nodes(X, Y, p)
        # Every node once, and nothing else inside the patch.
        assert node.sum() == p["cols"] * p["rows"] == p["count"]
        assert (node == inside).all()
        keys = set(zip(X[node].tolist(), Y[node].tolist()))
        assert len(keys) == p["count"]


def test_dem_patch_cells_are_cocircular(lidar):
    _, desc, las = lidar
    rot = [p for p in desc["sections"][0]["dem_patches"] if p["e1"][1] != 0][0]
    ox, oy = rot["origin"]
    a, b = rot["e1"]
    X, Y, _ = ints(las)
    present = set(zip(X.tolist(), Y.tolist()))

    def incircle(pa, pb, pc, pd):
        m = [[pa[0] - pd[0], pa[1] - pd[1]], [pb[0] - pd[0], pb[1] - pd[1]],
             [pc[0] - pd[0], pc[1] - pd[1]]]
        w = [r[0] * r[0] + r[1] * r[1] for r in m]
        return (m[0][0] * (m[1][1] * w[2] - w[1] * m[2][1])
                - m[0][1] * (m[1][0] * w[2] - w[1] * m[2][0])
                + w[0] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))

    rng = np.random.default_rng(0)
    for _ in range(50):
        i = int(rng.integers(0, rot["cols"] - 1))
        j = int(rng.integers(0, rot["rows"] - 1))
        corner = [(ox + (i + di) * a - (j + dj) * b, oy + (i + di) * b + (j + dj) * a)
                  for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1))]
        assert all(c in present for c in corner)
        assert incircle(*corner) == 0


def test_overlapping_strips_and_scan_lines(lidar):
    _, desc, las = lidar
    strips = desc["sections"][0]["strips"]
    main = [s for s in strips if not s["cross"]]
    assert len(main) >= 3
    assert 0.15 < desc["sections"][0]["overlap"] < 0.5
    psid = np.asarray(las.point_source_id)
    x = np.asarray(las.x)
    y = np.asarray(las.y)
    cell = 4.0
    ij = np.floor((x - x.min()) / cell).astype(np.int64) * 100003 + \
        np.floor((y - y.min()) / cell).astype(np.int64)
    cells = {}
    for s in main:
        cells[s["point_source_id"]] = set(np.unique(ij[psid == s["point_source_id"]]).tolist())
    for s1, s2 in zip(main[:-1], main[1:]):
        a, b = cells[s1["point_source_id"]], cells[s2["point_source_id"]]
        # Adjacent strips overlap in a band, without one covering the other.
        assert 0.1 * len(a) < len(a & b) < 0.6 * len(a)
    # Within a strip, GPS time runs forward and scan lines alternate direction.
    one = psid == main[0]["point_source_id"]
    t = np.asarray(las.gps_time)[one]
    assert (np.diff(t) >= 0).all()
    sd = np.asarray(las.scan_direction_flag)[one]
    assert 0.3 < sd.mean() < 0.7
    assert np.asarray(las.edge_of_flight_line)[one].any()


# ------------------------------------------------------------ formats

def test_las14_format6_valid(tmp_path):
    path = tmp_path / "f6.las"
    gen(path, 25000, "--las-version", "1.4", "--point-format", 6, "--seed", 2)
    las = laspy.read(path)
    h = las.header
    assert (h.version.major, h.version.minor) == (1, 4)
    assert h.point_format.id == 6
    assert h.point_count == len(las.points) == 25000
    raw = path.read_bytes()[:375]
    assert struct.unpack_from("<H", raw, 94)[0] == 375              # header size
    assert struct.unpack_from("<I", raw, 107)[0] == 0               # legacy count
    assert struct.unpack_from("<Q", raw, 247)[0] == 25000           # 64-bit count
    by_ret = struct.unpack_from("<15Q", raw, 255)
    rn = np.asarray(las.return_number)
    assert list(by_ret) == list(np.bincount(rn, minlength=16)[1:16])
    assert struct.unpack_from("<H", raw, 6)[0] & 16, "WKT bit set for format 6"
    wkt = [v for v in h.vlrs if v.record_id == 2112]
    assert len(wkt) == 1 and "UTM zone 10N" in wkt[0].string
    assert 'AUTHORITY["EPSG","26910"]' in wkt[0].string
    assert not any(v.record_id == 34735 for v in h.vlrs)


@pytest.mark.parametrize("version,fmt", [("1.1", 1), ("1.2", 0), ("1.2", 2), ("1.3", 5),
                                         ("1.4", 1), ("1.4", 7), ("1.4", 8), ("1.4", 10)])
def test_versions_and_formats_readable(tmp_path, version, fmt):
    path = tmp_path / "f.las"
    gen(path, 3000, "--las-version", version, "--point-format", fmt)
    las = laspy.read(path)
    assert las.header.point_format.id == fmt
    assert str(las.header.version) == version
    assert len(las.points) == 3000
    if fmt in (2, 3, 5, 7, 8, 10):
        assert np.asarray(las.red).max() > 0


def test_geokeys_carry_the_epsg_code(tmp_path):
    path = tmp_path / "g.las"
    gen(path, 1000, "--epsg", 32633)
    raw = path.read_bytes()
    hsize, = struct.unpack_from("<H", raw, 94)
    user, rid, length = struct.unpack_from("<16sHH", raw, hsize + 2)
    assert user.rstrip(b"\0") == b"LASF_Projection" and rid == 34735
    words = struct.unpack_from("<%dH" % (length // 2), raw, hsize + 54)
    keys = {words[i]: words[i + 3] for i in range(4, len(words), 4)}
    assert keys[3072] == 32633 and keys[1024] == 1


@pytest.mark.parametrize("args,msg", [
    (["--las-version", "1.2", "--point-format", "6"], "point format 6"),
    (["--epsg", "4326"], "geographic"),
    (["--las-version", "1.2", "--crs", "wkt"], "WKT"),
    (["--chunk", "0"], "chunk"),
])
def test_bad_arguments_fail_cleanly(tmp_path, args, msg):
    path = tmp_path / "bad.las"
    r = gen(path, 100, *args, check=False)
    assert r.returncode == 2
    assert msg in r.stderr
    assert not path.exists() and not (tmp_path / "bad.las.part").exists()


def test_grid_kind_is_a_lattice_grid(tmp_path):
    path = tmp_path / "g.las"
    desc = gen(path, 4900, "--kind", "grid", describe=True)
    s = desc["sections"][0]
    X, Y, _ = ints(laspy.read(path))
    step = s["step"]
    assert ((X - s["origin"][0]) % step == 0).all() and ((Y - s["origin"][1]) % step == 0).all()
    assert len(set(zip(X.tolist(), Y.tolist()))) == 4900
    assert s["cols"] * s["rows"] >= 4900


def test_dem_kind_has_rotated_and_axis_aligned_grids(tmp_path):
    path = tmp_path / "d.las"
    desc = gen(path, 8000, "--kind", "dem", describe=True)
    X, Y, _ = ints(laspy.read(path))
    patches = desc["sections"][0]["dem_patches"]
    assert sum(p["count"] for p in patches) == 8000
    assert sum(1 for p in patches if p["e1"][1] != 0) >= 2
    found = np.zeros(len(X), dtype=int)
    for p in patches:
        node, _ = _patch_nodes(X, Y, p)
        assert node.sum() == p["count"]
        found += node
    # Every point is a node of exactly one grid.
    assert (found == 1).all()


def test_cross_strips_are_reflown_when_main_strips_fall_short():
    """The exact count holds even when the main strips give far fewer points
    than planned: the cross strips are flown again (new point source ids),
    and the result still does not depend on the chunk size."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from lasgen import cloud

    def run(chunk):
        sec = cloud.build_sections("lidar", 20000, 4, (50.0, 50.0), (0.01,) * 3)[0]
        sec.thr = np.uint64(int(0.05 * 2 ** 32))    # main strips keep 5 % of pulses
        parts = list(sec.batches(chunk))
        cols = {k: np.concatenate([getattr(b, k) for b in parts])
                for k in ("X", "Y", "Z", "psid", "gps")}
        return sec, cols

    sec, a = run(1000)
    _, b = run(7777)
    assert len(a["X"]) == sec.count
    for k in a:
        assert np.array_equal(a[k], b[k])
    n_strips = len(sec.plan["strips"])
    assert a["psid"].max() > n_strips
    assert np.all(np.diff(a["gps"][:sec.n_scan]) >= 0)


def test_bench_info_table_and_rss_limit(tmp_path):
    """bench_info.py measures any command; md5sum stands in for gdt-tile."""
    bench = ROOT / "scripts" / "bench_info.py"
    base = [sys.executable, str(bench), "--points", "20000", "--workdir", str(tmp_path),
            "--gdt-tile", "/usr/bin/md5sum", "--args", "{file}"]
    r = subprocess.run(base + ["--json", str(tmp_path / "b.json")], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    rows = [ln.split() for ln in r.stdout.splitlines() if ln.startswith(("raw read", "command ("))]
    assert len(rows) == 4
    res = json.loads((tmp_path / "b.json").read_text())
    assert res["points"] == 20000 and res["origin"] == "generated"
    assert all(run["rc"] == 0 and run["maxrss_kb"] > 0 for run in res["runs"].values())
    # Without --keep the generated file is removed; with it, a later run reuses it.
    assert not list(tmp_path.glob("*.las"))
    r = subprocess.run(base + ["--keep", "--rss-limit-mb", "0.01"], capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 1 and "limit" in r.stderr
    r = subprocess.run(base + ["--keep"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and "reused" in r.stdout
    r = subprocess.run(base[:-4] + ["--gdt-tile", str(tmp_path / "missing")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2
    r = subprocess.run(base[:-4] + ["--gdt-tile", "/usr/bin/false", "--keep"],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 3 and "failed" in r.stderr
