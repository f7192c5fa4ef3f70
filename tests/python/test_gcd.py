"""The per-tile OpenCL core end to end, through the single-tile command.

The single-tile output must be byte-identical to the CPU reference's
(gdt-tile --reference): same unique triangulation, same vertex and face
order.  Checked on the real LiDAR samples, on generated LiDAR-like tiles
and on the degenerate kinds of the generator, for several tile sizes,
repeated runs, a permuted input, and the integer-only predicate path.  Device errors exit 5 naming the OpenCL error.
Everything is skipped (not failed) where no OpenCL device exists.
"""
import json
import os
import pathlib
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def single_tile(tools_dir):
    exe = tools_dir / "gcd_single_tile"
    if not exe.exists():
        pytest.fail(f"gcd_single_tile not built at {exe}")
    return exe


@pytest.fixture(scope="session")
def gcd_run(tools_dir):
    exe = tools_dir / "gcd_run"
    if not exe.exists():
        pytest.fail(f"gcd_run not built at {exe}")
    return exe


@pytest.fixture(scope="session")
def device_ok(tools_dir):
    r = subprocess.run([str(tools_dir / "gcd_kcompile")], capture_output=True, text=True)
    if r.returncode == 77:
        pytest.skip("no OpenCL device")
    assert r.returncode == 0, r.stderr
    return True


def reference_ply(gdt_bin, runner, inputs, out, extra=()):
    r = runner([gdt_bin, *inputs, "--reference", "-o", out, "-q", *extra])
    assert r.returncode == 0, r.stderr
    return out.read_bytes()


def core_ply(single_tile, runner, inputs, out, tile, extra=(), env=None):
    r = runner([single_tile, *inputs, "-o", out, "--tile", str(tile), "-q", *extra], env=env)
    assert r.returncode == 0, r.stderr
    return out.read_bytes()


def generate(tmp_path, kind, points, seed, name=None):
    out = tmp_path / (name or f"{kind}-{points}-{seed}.las")
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "gen_cloud.py"), str(out),
                        "--points", str(points), "--kind", kind, "--seed", str(seed)],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return out


REAL = ["autzen_trim.las", "100-points.las", "epsg_4326.las", "test_epsg_4326.las",
        "autzen-utm.pcd"]


@pytest.mark.parametrize("name", REAL)
@pytest.mark.parametrize("tile", [256, 4096])
def test_real_data_equals_reference(device_ok, gdt_bin, single_tile, runner, data_dir,
                                    tmp_path, name, tile):
    src = data_dir / name
    ref = reference_ply(gdt_bin, runner, [src], tmp_path / "ref.ply")
    got = core_ply(single_tile, runner, [src], tmp_path / "core.ply", tile, ["--check"])
    assert got == ref


@pytest.mark.parametrize("kind,points,seed", [
    ("lidar", 60000, 1), ("lidar", 150000, 2), ("uniform", 80000, 3), ("grid", 50000, 4),
    ("dem", 60000, 5), ("mixed", 100000, 6)])
def test_generated_equals_reference(device_ok, gdt_bin, single_tile, runner, tmp_path,
                                    kind, points, seed):
    las = generate(tmp_path, kind, points, seed)
    ref = reference_ply(gdt_bin, runner, [las], tmp_path / "ref.ply")
    for tile in (256, 1024):
        got = core_ply(single_tile, runner, [las], tmp_path / f"core{tile}.ply", tile)
        assert got == ref, f"tile {tile}"


def test_repeatable_and_json(device_ok, single_tile, runner, tmp_path):
    las = generate(tmp_path, "lidar", 80000, 11)
    outs = []
    for k in range(2):
        js = tmp_path / f"run{k}.json"
        outs.append(core_ply(single_tile, runner, [las], tmp_path / f"o{k}.ply", 512,
                             ["--json", js]))
        summary = json.loads(js.read_text())
        assert summary["mode"] == "single-tile"
        assert summary["device"]
        tile = summary["tiles"][0]
        assert tile["path"] in ("gcd", "insert") and tile["path_reason"]
        for key in ("phase1_voronoi", "phase2_dual", "phase3_shift", "phase4_insert",
                    "phase5_flip", "total"):
            assert tile["phase_times_s"][key] >= 0
        assert tile["phase5"]["flips"] > 0
        assert tile["phase1"]["kept"] + tile["phase1"]["missing_points"] == summary["vertices"]
        assert summary["faces"] > summary["vertices"]
    assert outs[0] == outs[1]


def read_faces_as_coordinates(path):
    plyfile = pytest.importorskip("plyfile")
    ply = plyfile.PlyData.read(str(path))
    v = ply["vertex"]
    xy = list(zip(v["x"].tolist(), v["y"].tolist()))
    faces = set()
    for f in ply["face"]["vertex_indices"]:
        tri = [xy[i] for i in f]
        k = tri.index(min(tri))
        faces.add(tuple(tri[k:] + tri[:k]))
    return faces


def test_permuted_input_same_triangles(device_ok, single_tile, runner, tmp_path):
    laspy = pytest.importorskip("laspy")
    np = pytest.importorskip("numpy")
    las = generate(tmp_path, "lidar", 60000, 21)
    data = laspy.read(str(las))
    perm = np.random.default_rng(5).permutation(len(data.points))
    shuffled = laspy.LasData(data.header)
    shuffled.points = data.points[perm]
    shuffled_path = tmp_path / "shuffled.las"
    shuffled.write(str(shuffled_path))
    a = core_ply(single_tile, runner, [las], tmp_path / "a.ply", 512)
    b = core_ply(single_tile, runner, [shuffled_path], tmp_path / "b.ply", 512)
    assert a != b  # vertex order follows the input order
    assert read_faces_as_coordinates(tmp_path / "a.ply") == \
        read_faces_as_coordinates(tmp_path / "b.ply")


@pytest.mark.parametrize("kind", ["lidar", "grid", "uniform"])
def test_core_runner_against_reference(device_ok, gcd_run, runner, kind):
    """Both paths, the integer-only predicates and a GPU's launch sizes and column
    layout, compared inside gcd_run."""
    for extra in (["--path", "gcd"], ["--path", "insert"], ["--no-fp64"],
                  ["--path", "gcd", "--gpu-layout"]):
        r = runner([gcd_run, "--gen", kind, "40000", "3", "--grid", "512", "--reference",
                    "--check", "--json", *extra])
        assert r.returncode == 0, r.stderr
        rep = json.loads(r.stdout)
        assert rep["reference_equal"] and rep["checked"]


@pytest.mark.parametrize("kind", ["lidar", "grid", "uniform"])
@pytest.mark.parametrize("grid,per_point", [(512, 2), (1024, 4), (1024, 2)])
def test_the_tile_memory_bound_holds(device_ok, gcd_run, runner, kind, grid, per_point):
    """gdt_core_tile_bytes, which the automatic --tile of a GPU trusts, bounds what
    the core's buffers hold at once with the GPU's layout and the result read back
    from device buffers (as on a GPU), and is not far above it."""
    n = grid * grid // per_point
    r = runner([gcd_run, "--gen", kind, str(n), "5", "--grid", str(grid), "--gpu-layout",
                "--copy-out", "--json"])
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    peak, bound = rep["device_peak_bytes"], rep["tile_bytes_bound"]
    assert 0 < peak <= bound <= 1.5 * peak + (16 << 20), (peak, bound)


@pytest.mark.parametrize("spec,name", [("99", "CL_DEVICE_NOT_FOUND"),
                                       ("7:3", "CL_DEVICE_NOT_FOUND")])
def test_device_errors_exit_5(device_ok, single_tile, runner, data_dir, tmp_path, spec, name):
    r = runner([single_tile, data_dir / "100-points.las", "-o", tmp_path / "o.ply",
                "--device", spec])
    assert r.returncode == 5, r.stderr
    assert name in r.stderr and "GDT-51" in r.stderr
    assert not (tmp_path / "o.ply").exists()


def test_malformed_device_spec_exit_2(single_tile, runner, data_dir, tmp_path):
    """A spec that is no device spec at all is a usage error, found when the
    options are parsed, before any OpenCL call."""
    r = runner([single_tile, data_dir / "100-points.las", "-o", tmp_path / "o.ply",
                "--device", "x"])
    assert r.returncode == 2, r.stderr
    assert "GDT-2110" in r.stderr
    assert not (tmp_path / "o.ply").exists()


def test_missing_device_type_exit_5(device_ok, single_tile, runner, data_dir, tmp_path):
    listing = subprocess.run(["clinfo", "-l"], capture_output=True, text=True)
    if listing.returncode == 0 and "gpu" in listing.stdout.lower():
        pytest.skip("this machine has a GPU")
    r = runner([single_tile, data_dir / "100-points.las", "-o", tmp_path / "o.ply",
                "--device", "gpu"])
    assert r.returncode == 5, r.stderr
    assert "CL_DEVICE_NOT_FOUND" in r.stderr


def test_cpu_device_spec(device_ok, single_tile, runner, data_dir, tmp_path):
    for spec in ("cpu", "0", "0:0"):
        js = tmp_path / f"{spec.replace(':', '_')}.json"
        r = runner([single_tile, data_dir / "100-points.las", "-o", tmp_path / "o.ply",
                    "--device", spec, "--json", js, "-q"])
        assert r.returncode == 0, r.stderr
        assert json.loads(js.read_text())["device"]


DX = [5, 4, 3, 0, -3, -4, -5, -4, -3, 0, 3, 4]
DY = [0, 3, 4, 5, 4, 3, 0, -3, -4, -5, -4, -3]


def _exact_sign(op, pts, cx, cy, big_r):
    xy = [(cx + big_r * DX[p[1]], cy + big_r * DY[p[1]]) if p[0] == "f" else (p[1], p[2])
          for p in pts]
    if op == "o":
        (ax, ay), (bx, by), (qx, qy) = xy
        v = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
    else:
        dx, dy = xy[3]
        m = [(x - dx, y - dy) for x, y in xy[:3]]
        lift = [x * x + y * y for x, y in m]
        v = (lift[0] * (m[1][0] * m[2][1] - m[2][0] * m[1][1])
             + lift[1] * (m[2][0] * m[0][1] - m[0][0] * m[2][1])
             + lift[2] * (m[0][0] * m[1][1] - m[1][0] * m[0][1]))
    return (v > 0) - (v < 0)


@pytest.mark.sanitize
def test_symbolic_predicates_big_integers(tools_dir):
    """The fake boundary's predicates equal the geometry at one huge R."""
    import random
    rng = random.Random(17)
    cases, lines = [], []
    for it in range(12000):
        span = rng.choice([50, 10 ** 6, 2 ** 31 - 1])
        cx, cy = span // 2, span // 2 + rng.randint(-1, 1) * (span > 50)
        op = "i" if it % 3 else "o"
        used, pts = set(), []
        while len(pts) < (4 if op == "i" else 3):
            if rng.random() < 0.45:
                p = ("f", rng.randrange(12))
            elif rng.random() < 0.3:
                # points symmetric about the centre: degenerate leading terms
                d = rng.choice([-2, -1, 0, 1, 2]) * max(1, span // 1000)
                e = rng.choice([-2, -1, 0, 1, 2]) * max(1, span // 1000)
                p = ("r", min(max(cx + d, 0), span), min(max(cy + e, 0), span))
            else:
                p = ("r", rng.randint(0, span), rng.randint(0, span))
            if p not in used:
                used.add(p)
                pts.append(p)
        cases.append(_exact_sign(op, pts, cx, cy, 10 ** 60))
        lines.append(f"{op} {cx} {cy} " + " ".join(
            f"f {p[1]}" if p[0] == "f" else f"r {p[1]} {p[2]}" for p in pts))
    r = subprocess.run([str(tools_dir / "gcd_geom_eval")], input="\n".join(lines) + "\n",
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    got = [int(v) for v in r.stdout.split()]
    bad = [(l, e, g) for l, e, g in zip(lines, cases, got) if e != g]
    assert len(got) == len(cases) and not bad, bad[:5]
