"""--ground pmf: PCL's progressive morphological filter, tile by tile with a
halo, gives every point the class of a whole-cloud run of the same filter
(tests/tools/pmf_whole), whatever the tiling, thread count or resume; the
mesh is the exact Delaunay triangulation of the ground points; bad options
are usage errors naming the option."""
import json
import pathlib
import signal
import sys

import numpy as np
import pytest

import resume_util as ru
from tiled_util import (SCALE, assert_equal_meshes, command, gen_cloud, run, shell,
                        write_las)

ROOT = pathlib.Path(__file__).resolve().parents[2]


def roof_cloud(path, n, seed):
    """A tilted plane with a 28 m square flat roof 12 m above it and a few
    low outliers: the roof is wider than small tiles, so some tiles keep no
    ground point at all."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 120, n)
    y = rng.uniform(0, 120, n)
    z = 100 + 0.02 * x + rng.normal(0, 0.02, n)
    roof = (np.abs(x - 60) < 14) & (np.abs(y - 60) < 14)
    z[roof] += 12.0
    z[:5] -= 3.0
    write_las(path, np.round(x / SCALE), np.round(y / SCALE), np.round(z / SCALE))
    return path, roof


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    d = tmp_path_factory.mktemp("ground")
    roof, _ = roof_cloud(d / "roof.las", 40_000, 4)
    return {
        "lidar": gen_cloud(d / "lidar.las", 120_000, 7),
        "roof": roof,
    }


def whole(tool, las, *args):
    """The whole-cloud oracle: {(ix, iy): class} and the lattice."""
    r = run([tool("pmf_whole"), *args, las])
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    sx, sy, ox, oy = (float(v) for v in lines[0].split()[2:])
    d = np.loadtxt(lines[2:], dtype=np.float64, ndmin=2)
    ground = d[d[:, 3] == 2]
    keys = set(zip(ground[:, 0].astype(np.int64).tolist(), ground[:, 1].astype(np.int64).tolist()))
    return keys, len(d), (sx, sy, ox, oy)


def vertex_keys(ply, lattice):
    from plyfile import PlyData
    sx, sy, ox, oy = lattice
    v = PlyData.read(str(ply))["vertex"]
    ix = np.round((np.asarray(v["x"]) - ox) / sx).astype(np.int64)
    iy = np.round((np.asarray(v["y"]) - oy) / sy).astype(np.int64)
    keys = set(zip(ix.tolist(), iy.tolist()))
    assert len(keys) == len(ix)
    return keys


def ground_run(gdt_bin, las, out, *args):
    js = pathlib.Path(str(out) + ".json")
    cmd = command(gdt_bin, las, out, "--ground", "pmf", *args, "--json", js)
    r = run(cmd)
    assert r.returncode == 0, f"exit {r.returncode}: {shell(cmd)}\n{r.stderr}"
    return json.loads(js.read_text())


@pytest.mark.parametrize("name", ["lidar", "roof"])
def test_every_tiling_keeps_the_whole_cloud_ground(gdt_bin, tool, clouds, tmp_path, name):
    las = clouds[name]
    want, distinct, lattice = whole(tool, las)
    assert 0 < len(want) < distinct
    first = None
    for tile in (64, 256, 1024, 4096):
        out = tmp_path / f"g{tile}.ply"
        s = ground_run(gdt_bin, las, out, "--tile", tile, *(["--check"] if tile == 256 else []))
        got = vertex_keys(out, lattice)
        assert got == want, f"--tile {tile}: {len(got - want)} extra, {len(want - got)} missing"
        g = s["ground"]
        assert g["ground_points"] == len(want) == s["vertices"]
        assert g["ground_points"] + g["nonground_points"] == distinct
        assert g["classified"] and g["method"] == "pmf"
        if first is None:
            first = out
        else:
            assert_equal_meshes(first, out, f"{name} --tile {tile}")


@pytest.mark.sanitize
def test_roof_is_removed_and_empty_tiles_are_fine(gdt_bin, clouds, tmp_path):
    """The roof's points are all non-ground, the terrain's (but the low
    outliers' neighbours) ground; at --tile 64 tiles inside the roof keep
    no point, and the mesh is still exact (--check)."""
    las = clouds["roof"]
    out = tmp_path / "r.ply"
    s = ground_run(gdt_bin, las, out, "--tile", 64, "--check")
    _, roof = roof_cloud(tmp_path / "again.las", 40_000, 4)
    assert s["ground"]["nonground_points"] >= roof.sum()
    assert s["ground"]["nonground_points"] < roof.sum() + 200
    assert s["tiles"] > 16


def test_in_memory_modes_give_the_tiled_mesh_and_dem(gdt_bin, clouds, tmp_path):
    """--reference and --single-tile classify the whole cloud in one call:
    the same mesh as the tiled run, and the same DEM bytes (its grid from
    the cloud's box and the ground points' count in every mode)."""
    las = clouds["roof"]
    tiled = tmp_path / "t.ply"
    ground_run(gdt_bin, las, tiled, "--tile", 64, "--dem", tmp_path / "t.tif")
    for mode in (["--reference"], ["--single-tile", "--tile", 4096]):
        out = tmp_path / f"m{len(mode)}.ply"
        tif = tmp_path / f"m{len(mode)}.tif"
        s = ground_run(gdt_bin, las, out, *mode, "--dem", tif)
        assert_equal_meshes(tiled, out, " ".join(map(str, mode)))
        assert tif.read_bytes() == (tmp_path / "t.tif").read_bytes()
        assert s["ground"]["classified"] and s["ground"]["ground_points"] == s["vertices"]


def test_parameters_change_the_classes_as_the_oracle_does(gdt_bin, tool, clouds, tmp_path):
    las = clouds["lidar"]
    args = ["--pmf-max-window", "12", "--pmf-slope", "0.4", "--pmf-initial-distance", "0.3",
            "--pmf-max-distance", "1.5", "--pmf-cell", "1.5", "--pmf-exponential", "false"]
    want, _, lattice = whole(tool, las, *args)
    default, _, _ = whole(tool, las)
    assert want != default
    out = tmp_path / "p.ply"
    ground_run(gdt_bin, las, out, "--tile", 256, *args)
    assert vertex_keys(out, lattice) == want


@pytest.mark.parametrize("name", ["autzen_trim.las", "epsg_4326.las"])
def test_real_sample_matches_the_oracle(gdt_bin, tool, data_dir, tmp_path, name):
    """Real LiDAR: a State Plane cloud in feet, and lon/lat points projected
    to UTM on the quantum lattice."""
    las = data_dir / name
    if not las.exists():
        pytest.skip(f"{las} absent (../shared/data is not beside the checkout)")
    want, _, lattice = whole(tool, las)
    assert want
    # autzen at 64 holds tiles near its sides with empty cells inside its box;
    # the lon/lat sample is sparse over a wide box: one tiling (its grid costs)
    for tile in ((64, 1024) if name.startswith("autzen") else (256,)):
        out = tmp_path / f"a{tile}.ply"
        ground_run(gdt_bin, las, out, "--tile", tile)
        assert vertex_keys(out, lattice) == want, f"--tile {tile}"


def test_same_bytes_for_any_threads_and_a_reused_job(gdt_bin, clouds, tmp_path):
    las = clouds["lidar"]
    a = tmp_path / "a.ply"
    b = tmp_path / "b.ply"
    ground_run(gdt_bin, las, a, "--tile", 256, "--threads", 1, "--keep-job")
    s = ground_run(gdt_bin, las, b, "--tile", 256, "--threads", 2, "--job", str(a) + ".gdt-job")
    assert a.read_bytes() == b.read_bytes()
    # the reused pass 2 classifies nothing, and reports the recorded counts
    assert not s["ground"]["classified"] and s["ground"]["ground_points"] == s["vertices"]
    header = a.read_bytes()[:2048].split(b"end_header")[0].decode()
    assert "comment ground pmf max-window 33 slope 1 initial-distance 0.15" in header


@pytest.fixture(scope="module")
def lidar_64(gdt_bin, clouds, tmp_path_factory):
    """The lidar cloud's ground mesh at --tile 64, made once."""
    want = tmp_path_factory.mktemp("want") / "want.ply"
    ground_run(gdt_bin, clouds["lidar"], want, "--tile", 64)
    return want


@pytest.mark.parametrize("stage,offset", [("ground", 1.0), ("tiles", 0.0)])
def test_killed_run_resumes_to_the_same_bytes(gdt_bin, clouds, lidar_64, tmp_path, stage,
                                              offset):
    """A run killed in the filter takes the tiles it classified (recorded
    one by one) and classifies the others; killed later it classifies none."""
    import sqlite3
    las = clouds["lidar"]
    want = lidar_64
    out = tmp_path / "o.ply"
    job = tmp_path / "job"
    cmd = [gdt_bin, las, "-o", out, "--tile", 64, "--job", job, "--ground", "pmf"]
    p = ru.Run(cmd)
    p.stop_in(stage, offset)
    rc = p.finish()
    assert rc in (0, -signal.SIGKILL), p.stderr
    recorded = 0
    if rc != 0 and (job / "job.db").exists():
        with sqlite3.connect(str(job / "job.db")) as db:
            recorded = db.execute("SELECT COUNT(*) FROM pfile WHERE kind = 5").fetchone()[0]
            pass2 = db.execute("SELECT COUNT(*) FROM stage WHERE name = 'pass2' AND done = 1"
                               ).fetchone()[0]
    js = tmp_path / "o.json"
    r = run(cmd + ["-q", "--json", js])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == want.read_bytes()
    if rc != 0:
        g = json.loads(js.read_text())["ground"]
        if pass2:
            assert not g["classified"]
        else:
            assert g["classified"] and g["tiles_reused"] == recorded


@pytest.mark.parametrize("args,name", [
    (["--pmf-max-window", "0"], "--pmf-max-window"),
    (["--pmf-max-window", "-5"], "--pmf-max-window"),
    (["--pmf-slope", "nan"], "--pmf-slope"),
    (["--pmf-slope", "-1"], "--pmf-slope"),
    (["--pmf-cell", "0"], "--pmf-cell"),
    (["--pmf-initial-distance", "inf"], "--pmf-initial-distance"),
    (["--pmf-max-distance", "-0.5"], "--pmf-max-distance"),
    (["--pmf-exponential", "maybe"], "--pmf-exponential"),
    (["--pmf-max-window", "0.5", "--pmf-cell", "1"], "--pmf-max-window"),
])
def test_bad_parameters_exit_2_naming_the_option(gdt_bin, clouds, tmp_path, args, name):
    out = tmp_path / "bad.ply"
    r = run(command(gdt_bin, clouds["roof"], out, "--ground", "pmf", *args))
    assert r.returncode == 2, r.stderr
    assert name in r.stderr
    assert not out.exists()


@pytest.mark.parametrize("args,what", [
    (["--ground", "pmf", "--keep-class", "2"], "--keep-class"),
    (["--pmf-slope", "0.5"], "--ground"),
    (["--ground", "csf"], "--ground"),
    (["--ground", "pmf", "--info"], "--info"),
    (["--ground", "pmf", "--reference", "--ground-out", "x.las"], "tiled run"),
])
def test_usage_errors(gdt_bin, clouds, tmp_path, args, what):
    out = tmp_path / "u.ply"
    r = run(command(gdt_bin, clouds["roof"], out, *args))
    assert r.returncode == 2, r.stderr
    assert what in r.stderr
    assert not out.exists()


def test_ground_eval_script(gdt_bin, clouds, tmp_path):
    """scripts/ground_eval.py against the generator's classes: buildings and
    trees are never taken for ground; the DTMs agree where both exist."""
    js = tmp_path / "eval.json"
    cmd = [sys.executable, ROOT / "scripts" / "ground_eval.py", clouds["lidar"], "--gdt-tile",
           gdt_bin, "--tile", 256, "--workdir", tmp_path / "w", "--json", js]
    r = run(cmd)
    assert r.returncode == 0, f"{shell(cmd)}\n{r.stderr}"
    assert "precision" in r.stdout and "DTM" in r.stdout
    res = json.loads(js.read_text())
    assert res["precision"] > 0.99
    assert 0.5 < res["recall"] <= 1.0
    assert res["true_positive"] + res["false_positive"] == res["pmf_ground"]
    assert res["dtm_cells"] > 1000 and res["dtm_p95_abs"] < 1.0


def las_records(path):
    import laspy
    las = laspy.read(str(path))
    raw = np.frombuffer(las.points.array.tobytes(), np.uint8).reshape(len(las.points), -1)
    return las, raw.copy()


def check_ground_out(src, out, ply, dropped=None):
    """Every record of src is in out, in order, byte for byte but the class
    of the records the run kept: 2 where its (x, y) is a vertex of the
    ground mesh (duplicates too), else 1; dropped (a mask) records as read."""
    a, ra = las_records(src)
    b, rb = las_records(out)
    assert rb.shape == ra.shape
    ci, mask = (16, 0xFF) if a.header.point_format.id >= 6 else (15, 0x1F)
    other = ra != rb
    other[:, ci] = False
    assert not other.any(), "bytes other than the class changed"
    assert ((ra[:, ci] & ~mask & 0xFF) == (rb[:, ci] & ~mask & 0xFF)).all(), "class flags changed"
    sx, sy = a.header.scales[:2]
    ox, oy = a.header.offsets[:2]
    keys = vertex_keys(ply, (sx, sy, ox, oy))
    X = np.asarray(a.X, np.int64).tolist()
    Y = np.asarray(a.Y, np.int64).tolist()
    ground = np.array([(x, y) in keys for x, y in zip(X, Y)])
    kept = np.ones(len(X), bool) if dropped is None else ~dropped
    cls = rb[:, ci] & mask
    assert set(np.unique(cls[kept]).tolist()) <= {1, 2}
    assert ((cls[kept] == 2) == ground[kept]).all()
    assert (rb[~kept] == ra[~kept]).all()
    assert b.header.point_count == len(X)
    assert np.allclose(b.header.mins, [np.min(a.x), np.min(a.y), np.min(a.z)])
    assert np.allclose(b.header.maxs, [np.max(a.x), np.max(a.y), np.max(a.z)])
    return cls


def test_ground_out_classifies_every_record(gdt_bin, clouds, tmp_path):
    """The generator's cloud has duplicated records and noise (class 7):
    with --drop-class 7 the noise records keep their class, every other
    record gets the class of its location."""
    import laspy
    las = clouds["lidar"]
    out, ply = tmp_path / "g.las", tmp_path / "g.ply"
    s = ground_run(gdt_bin, las, ply, "--tile", 256, "--drop-class", 7, "--ground-out", out)
    noise = np.asarray(laspy.read(str(las)).classification) == 7
    assert noise.any()
    cls = check_ground_out(las, out, ply, dropped=noise)
    assert (cls[~noise] == 2).sum() >= s["ground"]["ground_points"]


def test_ground_out_same_records_from_laz_and_las(gdt_bin, data_dir, tmp_path):
    src = data_dir / "autzen_trim.las"
    laz = data_dir / "autzen_trim.laz"
    if not (src.exists() and laz.exists()):
        pytest.skip(f"{data_dir} lacks the autzen samples")
    a, b = tmp_path / "a.las", tmp_path / "b.las"
    ground_run(gdt_bin, src, tmp_path / "a.ply", "--tile", 256, "--ground-out", a)
    ground_run(gdt_bin, laz, tmp_path / "b.ply", "--tile", 1024, "--ground-out", b)
    check_ground_out(src, a, tmp_path / "a.ply")
    assert las_records(a)[1].tobytes() == las_records(b)[1].tobytes()
    head = b.read_bytes()[:400]
    assert head[104] == 3  # the compression bits of the point format cleared
    assert b"laszip encoded" not in b.read_bytes()[:4096]


@pytest.mark.sanitize
def test_ground_out_of_a_reused_job_and_a_job_without_it(gdt_bin, clouds, tmp_path):
    las = clouds["roof"]
    job = tmp_path / "job"
    first = tmp_path / "a.las"
    base = ["--tile", 64, "--job", job, "--keep-job"]
    ground_run(gdt_bin, las, tmp_path / "a.ply", *base)  # no --ground-out: no classes kept
    ground_run(gdt_bin, las, tmp_path / "b.ply", *base, "--ground-out", first)
    again = tmp_path / "c.las"
    s = ground_run(gdt_bin, las, tmp_path / "c.ply", *base, "--ground-out", again)
    assert not s["ground"]["classified"]
    assert first.read_bytes() == again.read_bytes()
    check_ground_out(las, again, tmp_path / "c.ply")


@pytest.mark.parametrize("case", ["no-ground", "laz-name", "las-and-pcd", "layouts"])
def test_ground_out_refusals(gdt_bin, clouds, data_dir, tmp_path, case):
    out = tmp_path / "o.las"
    inputs, args = [clouds["roof"]], ["--ground", "pmf", "--ground-out", out]
    if case == "no-ground":
        args = ["--ground-out", out]
    elif case == "laz-name":
        args = ["--ground", "pmf", "--ground-out", tmp_path / "o.laz"]
    elif case == "las-and-pcd":
        pcd = data_dir / "autzen-utm.pcd"
        if not pcd.exists():
            pytest.skip(f"{pcd} absent")
        inputs = [clouds["roof"], pcd]
    else:
        import laspy
        other = tmp_path / "f1.las"
        las = laspy.read(str(clouds["roof"]))
        conv = laspy.convert(las, point_format_id=1)
        conv.write(str(other))
        inputs = [clouds["roof"], other]
    r = run(command(gdt_bin, inputs, tmp_path / "o.ply", *args))
    assert r.returncode == 2, r.stderr
    assert "--ground" in r.stderr or "LAS" in r.stderr
    assert not out.exists() and not (tmp_path / "o.ply").exists()


def test_ground_out_of_two_inputs_with_other_offsets(gdt_bin, clouds, tmp_path):
    """A cloud cut in two files, the second with another offset (whole
    steps away): its records come back on the first file's lattice, and the
    whole output equals the one-file run's."""
    import laspy
    src = clouds["lidar"]
    las = laspy.read(str(src))
    half = len(las.points) // 2
    parts = []
    for name, sl, shift in (("p1.las", slice(0, half), 0.0), ("p2.las", slice(half, None), 123.45)):
        h = laspy.LasHeader(point_format=las.header.point_format.id,
                            version=str(las.header.version))
        h.scales = las.header.scales
        h.offsets = las.header.offsets + np.array([shift, -shift, 0.0])
        h.vlrs = las.header.vlrs
        part = laspy.LasData(h)
        part.points = laspy.ScaleAwarePointRecord(las.points.array[sl].copy(),
                                                  las.header.point_format, h.scales, h.offsets)
        k = int(round(shift / las.header.scales[0]))
        part.X = np.asarray(las.X[sl]) - k
        part.Y = np.asarray(las.Y[sl]) + k
        part.write(str(tmp_path / name))
        parts.append(tmp_path / name)
    one, two = tmp_path / "one.las", tmp_path / "two.las"
    ground_run(gdt_bin, src, tmp_path / "one.ply", "--tile", 256, "--ground-out", one)
    ground_run(gdt_bin, parts, tmp_path / "two.ply", "--tile", 256, "--ground-out", two)
    assert las_records(one)[1].tobytes() == las_records(two)[1].tobytes()


def test_ground_out_of_pcd_points(gdt_bin, clouds, tmp_path):
    """PCD input: one LAS record per point, in input order, on the cloud's
    lattice (x, y exact, z to the quantum), class 2 where the point's
    location is ground, else 1."""
    import laspy
    src = laspy.read(str(clouds["roof"]))
    pcd = tmp_path / "roof.pcd"
    with open(pcd, "w") as f:
        n = len(src.points)
        f.write("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\n"
                f"COUNT 1 1 1\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
                "DATA ascii\n")
        for a, b, c in zip(np.asarray(src.x), np.asarray(src.y), np.asarray(src.z)):
            f.write(f"{a:.2f} {b:.2f} {c:.2f}\n")
    out, ply = tmp_path / "p.las", tmp_path / "p.ply"
    s = ground_run(gdt_bin, pcd, ply, "--tile", 64, "--ground-out", out)
    b = laspy.read(str(out))
    assert len(b.points) == len(src.points) and b.header.point_format.id == 0
    for k in ("x", "y", "z"):
        assert np.abs(np.asarray(getattr(b, k)) - np.asarray(getattr(src, k))).max() < 6e-4
    sx, sy = b.header.scales[:2]
    lattice = (sx, sy, 0.0, 0.0)
    keys = vertex_keys(ply, lattice)
    ix = np.round(np.asarray(b.x) / sx).astype(np.int64).tolist()
    iy = np.round(np.asarray(b.y) / sy).astype(np.int64).tolist()
    ground = np.array([(p, q) in keys for p, q in zip(ix, iy)])
    cls = np.asarray(b.classification)
    assert ((cls == 2) == ground).all() and set(np.unique(cls).tolist()) <= {1, 2}
    # duplicated locations: several records, one ground point
    assert len({(p, q) for p, q, g in zip(ix, iy, ground) if g}) == s["ground"]["ground_points"]
    assert (np.asarray(b.return_number) == 1).all()
