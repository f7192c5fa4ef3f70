"""Tests of scripts/gen_degenerate.py: every kind is readable by laspy, is a
pure function of its seed, and has the property it promises, checked on the
stored integers with exact Python-integer geometry."""
import math
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from conftest import build_dir

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
KINDS = ["grid", "rotgrid", "circle", "thincircle", "collinear", "duplicates", "clusters",
         "one", "two", "three", "extreme", "sparse", "uniform", "mixed"]
N = 500


def gen(kind, out, *args):
    r = subprocess.run([sys.executable, str(SCRIPTS / "gen_degenerate.py"), kind, str(out)]
                       + [str(a) for a in args], capture_output=True, text=True, timeout=120)
    return r


def read_las(path):
    import laspy
    las = laspy.read(str(path))
    return las, [int(v) for v in las.X], [int(v) for v in las.Y], [int(v) for v in las.Z]


def orient(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def incircle(a, b, c, d):
    rows = [(p[0] - d[0], p[1] - d[1]) for p in (a, b, c)]
    (ax, ay), (bx, by), (cx, cy) = rows
    return ((ax * ax + ay * ay) * (bx * cy - cx * by) + (bx * bx + by * by) * (cx * ay - ax * cy)
            + (cx * cx + cy * cy) * (ax * by - bx * ay))


def non_collinear_triple(P):
    a, b = P[0], next(p for p in P if p != P[0])
    c = next(p for p in P if orient(a, b, p) != 0)
    if orient(a, b, c) < 0:
        b, c = c, b
    return a, b, c


def is_grid_prefix(rel, n):
    """rel: integer (i, j) pairs; True when they are exactly the first n cells,
    row by row, of a k x k grid with k = ceil(sqrt(n))."""
    k = math.isqrt(n - 1) + 1
    i0 = min(i for i, _ in rel)
    j0 = min(j for _, j in rel)
    cells = sorted((j - j0) * k + (i - i0) for i, j in rel)
    return all(0 <= i - i0 < k for i, _ in rel) and cells == list(range(n))


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    d = tmp_path_factory.mktemp("degenerate")
    out = {}
    for kind in KINDS:
        path = d / (kind + ".las")
        r = gen(kind, path, "--n", N, "--seed", 4)
        assert r.returncode == 0, r.stderr
        assert r.stdout.startswith("wrote ")
        out[kind] = path
    return out


@pytest.mark.parametrize("kind", KINDS)
def test_readable_and_deterministic(clouds, kind, tmp_path):
    las, X, Y, Z = read_las(clouds[kind])
    assert las.header.version.major == 1 and las.header.version.minor == 2
    assert list(las.header.scales) == [0.001, 0.001, 0.001]
    expect = {"one": 1, "two": 2, "three": 3}.get(kind, N)
    assert las.header.point_count == len(X) == expect
    np.testing.assert_array_equal(las.x, 0.001 * np.array(X, dtype=np.float64))
    again = tmp_path / "again.las"
    assert gen(kind, again, "--n", N, "--seed", 4).returncode == 0
    assert again.read_bytes() == clouds[kind].read_bytes()
    if kind != "duplicates":
        other = tmp_path / "other.las"
        assert gen(kind, other, "--n", N, "--seed", 5).returncode == 0
        assert other.read_bytes() != clouds[kind].read_bytes()


def test_grids(clouds):
    _, X, Y, _ = read_las(clouds["grid"])
    assert len(set(zip(X, Y))) == N
    x0, y0 = min(X), min(Y)
    assert all((x - x0) % 1000 == 0 and (y - y0) % 1000 == 0 for x, y in zip(X, Y))
    assert is_grid_prefix([((x - x0) // 1000, (y - y0) // 1000) for x, y in zip(X, Y)], N)
    _, X, Y, _ = read_las(clouds["rotgrid"])
    # Coordinates in the basis u = (600, 800), v = (-800, 600) (|u|^2 = 10^6).
    rel = []
    for x, y in zip(X, Y):
        dx, dy = x - X[0], y - Y[0]
        i, ri = divmod(600 * dx + 800 * dy, 10 ** 6)
        j, rj = divmod(-800 * dx + 600 * dy, 10 ** 6)
        assert ri == 0 and rj == 0
        rel.append((i, j))
    assert is_grid_prefix(rel, N)
    # Cells are squares, so every cell's corners are co-circular.
    a, b, c, d = (0, 0), (600, 800), (-200, 1400), (-800, 600)
    assert incircle(a, b, c, d) == 0


@pytest.mark.parametrize("n", [N, 7000])
def test_circle(tmp_path, n):
    path = tmp_path / "c.las"
    assert gen("circle", path, "--n", n, "--seed", 2).returncode == 0
    _, X, Y, _ = read_las(path)
    P = list(zip(X, Y))
    assert len(P) == min(n, 6804) and len(set(P)) == len(P)
    a, b, c = non_collinear_triple(P)
    assert all(incircle(a, b, c, p) == 0 for p in P)


def test_thin_circle(clouds):
    _, X, Y, _ = read_las(clouds["thincircle"])
    P = list(zip(X, Y))
    cx2, cy2 = min(X) + max(X), min(Y) + max(Y)          # twice the centre
    R = max(10_000, 4 * N)
    dist = [math.hypot(2 * x - cx2, 2 * y - cy2) / 2 for x, y in P]
    assert max(abs(d - R) for d in dist) <= 1.5
    a, b, c = non_collinear_triple(P)
    assert sum(1 for p in P if incircle(a, b, c, p) != 0) > len(P) // 2


def test_collinear_duplicates_clusters(clouds):
    _, X, Y, _ = read_las(clouds["collinear"])
    P = list(zip(X, Y))
    assert len(set(P)) == N
    assert all(orient(P[0], P[1], p) == 0 for p in P)
    _, X, Y, Z = read_las(clouds["duplicates"])
    assert len(set(zip(X, Y))) == 1 and len(set(Z)) == N
    _, X, Y, _ = read_las(clouds["clusters"])
    distinct = len(set(zip(X, Y)))
    assert N - distinct >= N // 100


def test_small_sets(clouds):
    _, X, Y, _ = read_las(clouds["one"])
    assert len(X) == 1
    _, X, Y, _ = read_las(clouds["two"])
    assert len(set(zip(X, Y))) == 2
    _, X, Y, _ = read_las(clouds["three"])
    P = list(zip(X, Y))
    assert len(P) == 3 and orient(*P) != 0


def test_extreme_and_sparse(clouds, tmp_path):
    _, X, Y, _ = read_las(clouds["extreme"])
    lo, hi = -(1 << 31), (1 << 31) - 1
    assert (min(X), max(X), min(Y), max(Y)) == (lo, hi, lo, hi)
    w = max(64, 8 * math.isqrt(N - 4))
    assert all(min(x - lo, hi - x) < w and min(y - lo, hi - y) < w for x, y in zip(X, Y))
    # A chosen scale and offset are stored as given; the integers do not move.
    path = tmp_path / "x.las"
    assert gen("extreme", path, "--n", N, "--seed", 4, "--scale", 0.01,
               "--offset", 500000, 4000000).returncode == 0
    las, X2, Y2, _ = read_las(path)
    assert list(las.header.offsets[:2]) == [500000.0, 4000000.0]
    assert list(las.header.scales) == [0.01, 0.01, 0.01]
    assert (X2, Y2) == (X, Y)
    assert las.header.maxs[0] == pytest.approx(500000 + 0.01 * hi)
    _, X, Y, _ = read_las(clouds["sparse"])
    assert max(X) - min(X) > 1 << 29 and max(Y) - min(Y) > 1 << 29
    _, X, Y, _ = read_las(clouds["uniform"])
    assert 0 <= min(X) and max(X) < 10 ** 7 and len(set(zip(X, Y))) > N * 0.99


def test_mixed(clouds):
    _, X, Y, _ = read_las(clouds["mixed"])
    P = list(zip(X, Y))
    assert len(P) == N
    assert len(set(P)) < N                            # duplicates part
    # Co-circular structure: some four points share a circle (grid cells).
    S = set(P)
    assert any((x + 1000, y) in S and (x, y + 1000) in S and (x + 1000, y + 1000) in S for x, y in P)


@pytest.mark.parametrize("fmt", ["pcd", "xyz"])
def test_other_formats_hold_the_same_points(clouds, tmp_path, fmt):
    _, X, Y, Z = read_las(clouds["mixed"])
    path = tmp_path / ("m." + fmt)
    assert gen("mixed", path, "--n", N, "--seed", 4).returncode == 0
    if fmt == "xyz":
        arr = np.loadtxt(path)
    else:
        data = path.read_bytes()
        k = data.index(b"DATA binary\n") + len(b"DATA binary\n")
        assert b"FIELDS x y z" in data[:k] and b"POINTS %d" % N in data[:k]
        arr = np.frombuffer(data[k:], dtype="<f8").reshape(-1, 3)
    assert arr.shape == (N, 3)
    np.testing.assert_array_equal(np.rint(arr[:, 0] / 0.001).astype(np.int64), X)
    np.testing.assert_array_equal(np.rint(arr[:, 1] / 0.001).astype(np.int64), Y)
    np.testing.assert_array_equal(np.rint(arr[:, 2] / 0.001).astype(np.int64), Z)


def test_validator_reads_every_format(tmp_path):
    """The triangle of the 'three' kind, written as a mesh here, validates
    against the generated LAS, PCD and XYZ files."""
    from plyfile import PlyData, PlyElement
    las = tmp_path / "t.las"
    assert gen("three", las, "--seed", 9).returncode == 0
    _, X, Y, _ = read_las(las)
    P = list(zip(X, Y))
    tri = (0, 1, 2) if orient(*P) > 0 else (0, 2, 1)
    v = np.zeros(3, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    v["x"] = 0.001 * np.array(X, dtype=np.float64)
    v["y"] = 0.001 * np.array(Y, dtype=np.float64)
    f = np.zeros(1, dtype=[("vertex_indices", "<i4", (3,))])
    f["vertex_indices"][0] = tri
    mesh = tmp_path / "t.ply"
    PlyData([PlyElement.describe(v, "vertex"),
             PlyElement.describe(f, "face", len_types={"vertex_indices": "u1"},
                                 val_types={"vertex_indices": "i4"})],
            text=False, byte_order="<", comments=["lattice 0.001 0.001 0 0"]).write(str(mesh))
    for fmt in ("las", "pcd", "xyz"):
        cloud = tmp_path / ("t." + fmt)
        assert gen("three", cloud, "--seed", 9).returncode == 0
        r = subprocess.run([sys.executable, str(SCRIPTS / "validate_mesh.py"), str(mesh),
                            "--input", str(cloud)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and r.stdout.startswith("OK: 3 vertices, 1 faces"), r.stdout + r.stderr
    other = tmp_path / "o.las"
    assert gen("three", other, "--seed", 10).returncode == 0
    r = subprocess.run([sys.executable, str(SCRIPTS / "validate_mesh.py"), str(mesh),
                        "--input", str(other)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 1 and "input points missing" in r.stdout


def test_usage_errors(tmp_path):
    assert gen("nonsense", tmp_path / "a.las").returncode == 2
    assert gen("grid", tmp_path / "a.las", "--n", 0).returncode == 2
    assert gen("grid", tmp_path / "a.las", "--scale", -1).returncode == 2
    r = gen("grid", tmp_path / "nodir" / "a.las")
    assert r.returncode == 4


@pytest.mark.sanitize
def test_gdt_tile_reads_generated_las(clouds):
    exe = build_dir() / "tiler" / "gdt-tile"
    if not exe.exists():
        pytest.skip("gdt-tile not built at %s" % exe)
    for kind in KINDS:
        r = subprocess.run([str(exe), str(clouds[kind]), "--info"], capture_output=True,
                           text=True, timeout=60)
        assert r.returncode == 0, (kind, r.stderr)
        assert str({"one": 1, "two": 2, "three": 3}.get(kind, N)) in r.stdout
