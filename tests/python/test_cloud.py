"""Several inputs as one cloud, through the cloud_dump tool.

LAS inputs keep their record integers as lattice integers; a second LAS whose
offsets differ by whole steps maps exactly; PCD is snapped to the quantum
(round half to even); lon/lat input is projected to UTM and must agree with
an independent implementation (pyproj, else the `utm` package) to far below a
quantum; inputs in different CRSs are refused with exit 3.  The --dup
policies and the out-of-core duplicate counter are compared with numpy.
"""
import io
import math
import struct

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

POINT_DTYPE = [("x", "i8"), ("y", "i8"), ("z", "f8"), ("ord", "u8")]


@pytest.fixture(scope="session")
def cloud_dump(tool):
    return tool("cloud_dump")


class Dump:
    def __init__(self, text):
        self.header = {}
        self.maps = []
        body = []
        for line in text.splitlines():
            if line.startswith("# map "):
                self.maps.append(line.split()[3:])
            elif line.startswith("# "):
                key, _, rest = line[2:].partition(" ")
                self.header[key] = rest
            else:
                body.append(line)
        if body:
            self.pts = np.loadtxt(io.StringIO("\n".join(body)), dtype=POINT_DTYPE, ndmin=1)
        else:
            self.pts = np.zeros(0, dtype=POINT_DTYPE)

    @property
    def lattice(self):
        return [float(v) for v in self.header["lattice"].split()]


def run_dump(runner, exe, *args, expect=0):
    r = runner([exe, *args])
    assert r.returncode == expect, f"exit {r.returncode}: {r.stderr}"
    return Dump(r.stdout), r.stderr


def geokeys(epsg, geographic=False):
    """A GeoKeyDirectoryTag VLR: model type and the projected or geographic code."""
    words = [1, 1, 0, 2, 1024, 0, 1, 2 if geographic else 1,
             2048 if geographic else 3072, 0, 1, epsg]
    return laspy.VLR("LASF_Projection", 34735, "GeoKeyDirectoryTag",
                     struct.pack(f"<{len(words)}H", *words))


def write_las(path, X, Y, Z, scale, offset, epsg=None, geographic=False):
    header = laspy.LasHeader(version="1.2", point_format=0)
    header.scales = np.array(scale, dtype=np.float64)
    header.offsets = np.array(offset, dtype=np.float64)
    if epsg is not None:
        header.vlrs.append(geokeys(epsg, geographic))
    las = laspy.LasData(header)
    las.X = np.asarray(X, dtype=np.int32)
    las.Y = np.asarray(Y, dtype=np.int32)
    las.Z = np.asarray(Z, dtype=np.int32)
    las.write(str(path))
    return laspy.read(str(path))


def write_pcd_ascii(path, xyz):
    with open(path, "w") as f:
        f.write("VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
                f"WIDTH {len(xyz)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(xyz)}\n"
                "DATA ascii\n")
        for x, y, z in xyz:
            f.write(f"{x!r} {y!r} {z!r}\n")


def read_pcd_binary_xyz(path):
    """x, y, z columns of a binary PCD (any field order or case)."""
    raw = path.read_bytes()
    pos = 0
    header = {}
    while True:
        end = raw.index(b"\n", pos)
        line = raw[pos:end].decode().strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, *vals = line.split()
        header[key.upper()] = vals
        if key.upper() == "DATA":
            break
    assert header["DATA"] == ["binary"]
    kinds = {("F", "4"): "<f4", ("F", "8"): "<f8", ("U", "1"): "u1", ("U", "2"): "<u2",
             ("U", "4"): "<u4", ("I", "1"): "i1", ("I", "2"): "<i2", ("I", "4"): "<i4"}
    fields = []
    for i, (name, size, typ, count) in enumerate(zip(header["FIELDS"], header["SIZE"],
                                                     header["TYPE"], header["COUNT"])):
        fields.append((f"{name.lower()}_{i}" if name.lower() not in ("x", "y", "z")
                       else name.lower(), kinds[(typ, size)], (int(count),) if int(count) > 1 else ()))
    dt = np.dtype([(n, t, s) if s else (n, t) for n, t, s in fields])
    n = int(header["POINTS"][0])
    rec = np.frombuffer(raw, dtype=dt, count=n, offset=pos)
    return rec["x"].astype(np.float64), rec["y"].astype(np.float64), rec["z"].astype(np.float64)


# ---------------------------------------------------------------- LAS lattice


@pytest.mark.parametrize("name", ["autzen_trim.las", "100-points.las", "bad_vlr_count.las"])
def test_las_record_integers_are_the_lattice(cloud_dump, runner, data_dir, name):
    las = laspy.read(str(data_dir / name))
    d, _ = run_dump(runner, cloud_dump, "-q", data_dir / name)
    sx, sy, ox, oy = d.lattice
    assert (sx, sy) == tuple(las.header.scales[:2]) and (ox, oy) == tuple(las.header.offsets[:2])
    assert d.header["native"].split()[0] == "1"
    assert len(d.pts) == las.header.point_count
    np.testing.assert_array_equal(d.pts["x"], np.asarray(las.X, dtype=np.int64))
    np.testing.assert_array_equal(d.pts["y"], np.asarray(las.Y, dtype=np.int64))
    np.testing.assert_array_equal(d.pts["z"], np.asarray(las.z, dtype=np.float64))
    np.testing.assert_array_equal(d.pts["ord"], np.arange(len(d.pts), dtype=np.uint64))


@pytest.mark.sanitize
def test_shifted_offsets_map_exactly(cloud_dump, runner, tmp_path):
    rng = np.random.default_rng(20240611)
    n1, n2 = 3000, 2000
    a = write_las(tmp_path / "a.las", rng.integers(-2**31, 2**31, n1), rng.integers(-2**31, 2**31, n1),
                  rng.integers(0, 10**5, n1), (0.01, 0.01, 0.01), (636000.0, 848000.0, 0.0), 32610)
    b = write_las(tmp_path / "b.las", rng.integers(-2**30, 2**30, n2), rng.integers(-2**30, 2**30, n2),
                  rng.integers(0, 10**5, n2), (0.01, 0.01, 0.001), (637234.56, 847210.99, -5.0), 32610)
    d, err = run_dump(runner, cloud_dump, tmp_path / "a.las", tmp_path / "b.las")
    assert "GDT-3420" not in err
    assert d.maps[1][:5] == ["shift", "1", "123456", "1", "-78901"]
    kx, ky = 123456, -78901
    np.testing.assert_array_equal(d.pts["x"][:n1], np.asarray(a.X, dtype=np.int64))
    np.testing.assert_array_equal(d.pts["x"][n1:], np.asarray(b.X, dtype=np.int64) + kx)
    np.testing.assert_array_equal(d.pts["y"][n1:], np.asarray(b.Y, dtype=np.int64) + ky)
    # the CRS position of each b point is that of its lattice point, to far below a step
    pos = 636000.0 + 0.01 * d.pts["x"][n1:].astype(np.longdouble)
    assert np.max(np.abs(pos - np.asarray(b.x, dtype=np.longdouble))) < 1e-6
    np.testing.assert_array_equal(d.pts["z"][n1:], np.asarray(b.z))
    np.testing.assert_array_equal(d.pts["ord"], np.arange(n1 + n2, dtype=np.uint64))

    # the other way round, b's lattice is the cloud's
    r, _ = run_dump(runner, cloud_dump, tmp_path / "b.las", tmp_path / "a.las")
    assert r.lattice[2:] == [637234.56, 847210.99]
    np.testing.assert_array_equal(r.pts["x"][n2:], np.asarray(a.X, dtype=np.int64) - kx)

    # an offset half a step away cannot be mapped: snapped, with a warning
    c = write_las(tmp_path / "c.las", rng.integers(-10**6, 10**6, 50), rng.integers(-10**6, 10**6, 50),
                  rng.integers(0, 10, 50), (0.01, 0.01, 0.01), (636000.005, 848000.0, 0.0), 32610)
    s, err = run_dump(runner, cloud_dump, tmp_path / "a.las", tmp_path / "c.las")
    assert "GDT-3420" in err and "c.las" in err
    assert s.maps[1][0] == "snap"
    want = np.rint((np.asarray(c.x) - 636000.0) / 0.01).astype(np.int64)
    np.testing.assert_array_equal(s.pts["x"][n1:], want)


@pytest.mark.sanitize
def test_mixed_crs_refused(cloud_dump, runner, data_dir, tmp_path):
    r = runner([cloud_dump, data_dir / "autzen_trim.las", data_dir / "epsg_4326.las"])
    assert r.returncode == 3, r.stderr
    assert "GDT-3411" in r.stderr and "epsg_4326.las" in r.stderr and "autzen_trim.las" in r.stderr
    assert r.stdout == ""
    for epsg2, code in ((32611, "GDT-3410"), (4326, "GDT-3411")):
        write_las(tmp_path / "p.las", [0], [0], [0], (0.01, 0.01, 0.01), (0, 0, 0), 32610)
        write_las(tmp_path / "q.las", [0], [0], [0], (0.01, 0.01, 0.01), (0, 0, 0), epsg2,
                  geographic=epsg2 == 4326)
        r = runner([cloud_dump, tmp_path / "p.las", tmp_path / "q.las"])
        assert r.returncode == 3 and code in r.stderr, r.stderr
    # PCD has no CRS: it joins any cloud
    write_las(tmp_path / "q.las", [5], [7], [0], (0.01, 0.01, 0.01), (0, 0, 0), 32610)
    write_pcd_ascii(tmp_path / "p.pcd", [(1.004, 2.0, 3.0)])
    d, _ = run_dump(runner, cloud_dump, tmp_path / "q.las", tmp_path / "p.pcd")
    assert d.header["epsg"] == "32610"
    assert d.pts["x"].tolist() == [5, 100] and d.pts["y"].tolist() == [7, 200]


# ---------------------------------------------------------------- float input


def test_pcd_snapped_to_quantum(cloud_dump, runner, data_dir):
    x, y, z = read_pcd_binary_xyz(data_dir / "autzen-utm.pcd")
    for q in ("0.001", "0.01", "0.25"):
        d, _ = run_dump(runner, cloud_dump, "--quantum", q, data_dir / "autzen-utm.pcd")
        assert d.lattice == [float(q), float(q), 0.0, 0.0]
        np.testing.assert_array_equal(d.pts["x"], np.rint(x / float(q)).astype(np.int64))
        np.testing.assert_array_equal(d.pts["y"], np.rint(y / float(q)).astype(np.int64))
        np.testing.assert_array_equal(d.pts["z"], z)


@pytest.mark.sanitize
def test_half_way_rounds_to_even(cloud_dump, runner, tmp_path):
    vals = [0.125, 0.375, 0.625, 0.875, -0.125, -0.375, -0.625, -0.875, 1e9 + 0.125, -1e9 - 0.375]
    write_pcd_ascii(tmp_path / "h.pcd", [(v, -v, 0.0) for v in vals])
    d, _ = run_dump(runner, cloud_dump, "--quantum", "0.25", tmp_path / "h.pcd")
    want = [round(v / 0.25) for v in vals]  # Python's round is half to even
    assert d.pts["x"].tolist() == want
    assert d.pts["y"].tolist() == [round(-v / 0.25) for v in vals]
    assert [w % 2 for w in want] == [0] * len(want)


# ---------------------------------------------------------------- geographic input


def utm_forward(lon, lat, zone, north):
    """Independent UTM forward projection: pyproj if present, else `utm`."""
    try:
        from pyproj import Transformer
    except ImportError:
        Transformer = None
    epsg = (32600 if north else 32700) + zone
    if Transformer is not None:
        t = Transformer.from_crs("EPSG:4326", f"EPSG:{epsg}", always_xy=True)
        e, n = t.transform(np.asarray(lon), np.asarray(lat))
        return np.asarray(e, dtype=np.float64), np.asarray(n, dtype=np.float64), 1e-6
    utm = pytest.importorskip("utm", reason="neither pyproj nor utm is installed")
    e, n, _, _ = utm.from_latlon(np.asarray(lat), np.asarray(lon), force_zone_number=zone,
                                 force_northern=north)
    return np.asarray(e, dtype=np.float64), np.asarray(n, dtype=np.float64), 1e-3


@pytest.mark.sanitize
@pytest.mark.parametrize("name", ["epsg_4326.las", "test_epsg_4326.las"])
@pytest.mark.parametrize("quantum", ["0.001", "0.0001"])
def test_geographic_projection_matches_reference(cloud_dump, runner, data_dir, name, quantum):
    las = laspy.read(str(data_dir / name))
    lon, lat = np.asarray(las.x, dtype=np.float64), np.asarray(las.y, dtype=np.float64)
    mins, maxs = las.header.mins, las.header.maxs
    clon, clat = (mins[0] + maxs[0]) / 2, (mins[1] + maxs[1]) / 2
    zone = int(math.floor((clon + 180) / 6)) + 1
    north = clat >= 0
    d, _ = run_dump(runner, cloud_dump, "-q", "--quantum", quantum, data_dir / name)
    epsg = (32600 if north else 32700) + zone
    assert d.header["epsg"] == str(epsg)
    assert d.header["projected"].split() == ["1", str(zone), "1" if north else "0"]
    assert d.header["crs"] == (f"EPSG:{epsg} (WGS 84 / UTM zone {zone}{'N' if north else 'S'}, "
                               "projected from EPSG:4326)")
    q = float(quantum)
    assert d.lattice == [q, q, 0.0, 0.0]
    e, n, tol = utm_forward(lon, lat, zone, north)
    for got, ref in ((d.pts["x"], e), (d.pts["y"], n)):
        # the lattice point is the nearest to the reference position ...
        assert np.max(np.abs(got * q - ref)) <= q / 2 + tol
        if tol <= 1e-6:
            # ... and exactly the reference's rounding, except within a
            # micrometre of a half-way point, where the two may differ
            frac = np.abs(ref / q - np.floor(ref / q) - 0.5)
            mism = got != np.rint(ref / q).astype(np.int64)
            assert not np.any(mism & (frac > 1e-6 / q))
    np.testing.assert_array_equal(d.pts["z"], np.asarray(las.z))


# ---------------------------------------------------------------- duplicates


def reference_dedup(x, y, z, policy):
    order = np.lexsort((np.arange(len(x)), y, x))
    out = []
    i = 0
    while i < len(order):
        j = i
        while j < len(order) and x[order[j]] == x[order[i]] and y[order[j]] == y[order[i]]:
            j += 1
        grp = order[i:j]  # ordinals ascending
        if policy == "first":
            zz = z[grp[0]]
        elif policy == "min-z":
            zz = z[grp].min()
        else:
            zz = z[grp].max()
        out.append((x[grp[0]], y[grp[0]], zz, grp[0]))
        i = j
    return out


@pytest.mark.sanitize
@pytest.mark.parametrize("policy", ["first", "min-z", "max-z"])
def test_dup_policies(cloud_dump, runner, tmp_path, policy):
    rng = np.random.default_rng(7)
    n = 4000
    X, Y, Z = rng.integers(-40, 40, n), rng.integers(-40, 40, n), rng.integers(0, 30, n)
    write_las(tmp_path / "a.las", X[: n // 2], Y[: n // 2], Z[: n // 2], (0.5, 0.5, 0.25), (0, 0, 0))
    write_las(tmp_path / "b.las", X[n // 2:] - 4, Y[n // 2:] + 6, Z[n // 2:], (0.5, 0.5, 0.25),
              (2.0, -3.0, 0))
    d, _ = run_dump(runner, cloud_dump, "--dup", policy, tmp_path / "a.las", tmp_path / "b.las")
    ref = reference_dedup(X, Y, Z * 0.25, policy)
    got = [(int(p["x"]), int(p["y"]), float(p["z"]), int(p["ord"])) for p in d.pts]
    assert got == [(int(a), int(b), float(c), int(o)) for a, b, c, o in ref]


@pytest.mark.sanitize
def test_dupcount_matches_numpy(cloud_dump, runner, data_dir, tmp_path):
    for name in ("test_epsg_4326.las", "100-points.las", "autzen-utm.pcd"):
        d, _ = run_dump(runner, cloud_dump, "-q", data_dir / name)
        keys = np.stack([d.pts["x"], d.pts["y"]], axis=1)
        _, counts = np.unique(keys, axis=0, return_counts=True)
        for budget in ("4096", str(64 << 20)):
            c, _ = run_dump(runner, cloud_dump, "-q", "--dupcount", budget, tmp_path, data_dir / name)
            pts, distinct, dups, maxm, _levels = map(int, c.header["dupcount"].split())
            assert (pts, distinct, dups, maxm) == (len(keys), len(counts), len(keys) - len(counts),
                                                   int(counts.max()))
    assert list(tmp_path.iterdir()) == []


def test_dupcount_spills_on_real_data(cloud_dump, runner, data_dir, tmp_path):
    d, _ = run_dump(runner, cloud_dump, "-q", "--quantum", "1", data_dir / "autzen-utm.pcd",
                    data_dir / "autzen-utm.pcd")
    keys = np.stack([d.pts["x"], d.pts["y"]], axis=1)
    _, counts = np.unique(keys, axis=0, return_counts=True)
    c, _ = run_dump(runner, cloud_dump, "-q", "--quantum", "1", "--dupcount", "4096", tmp_path,
                    data_dir / "autzen-utm.pcd", data_dir / "autzen-utm.pcd")
    pts, distinct, dups, maxm, levels = map(int, c.header["dupcount"].split())
    assert levels >= 1
    assert (pts, distinct, maxm) == (len(keys), len(counts), int(counts.max()))
    assert dups == pts - distinct and maxm >= 2
    a, _ = run_dump(runner, cloud_dump, "-q", "--dupcount", "4096", tmp_path,
                    data_dir / "autzen_trim.las")
    pts, distinct, _, _, levels = map(int, a.header["dupcount"].split())
    las = laspy.read(str(data_dir / "autzen_trim.las"))
    want = len(np.unique(np.stack([np.asarray(las.X), np.asarray(las.Y)], axis=1), axis=0))
    assert pts == las.header.point_count and distinct == want and levels >= 2
