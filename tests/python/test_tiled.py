"""Acceptance tests of the tiled pipeline (gdt-tile INPUT --tile N -o OUT).

The output must be T_{d1,d2} of the whole cloud whatever the tiling, so every
tiled run is compared, as a canonical triangle set (compare_meshes.py), with
the CPU oracle (--reference) and validated exactly against its input
(validate_mesh.py --input).  Clouds: generated LiDAR with voids and
duplicates, grids, mixed and uniform clouds, sparse and awkward layouts built
with numpy (empty tiles, tiles of one, two or three points, thin strips,
collinear sets, points on tile borders), seeded random clouds, the real
samples of ../shared/data.  Options: --tile 64, 256, 1024, explicit and
automatic --cell and --halo (0 included), permuted and split inputs.

With --keep-job the tiles/*.tri files are parsed and checked against the
output: vertex blocks in tile order, vertices of a tile by lowest input
ordinal, the certified faces = the first faces of the PLY, each a face of
the reference, no face twice, seam vertices and barrier edges consistent
with the certified faces, merge faces only on seam vertices.
"""
import json
import os
import re
import pathlib

import numpy as np
import pytest

import tiled_util as tu

S = 0.01  # LAS scale of every generated cloud: lattice integers = record integers


# ------------------------------------------------------------------ checks

def check_summary(summary, mesh, plan=None, halo=None):
    """The --json summary of a tiled run against its PLY and tile plan."""
    missing = [k for k in tu.SUMMARY_KEYS if k not in summary]
    assert not missing, f"summary lacks {missing}"
    assert summary["mode"] == "tiled", summary["mode"]
    assert summary["vertices"] == mesh.nvert
    assert summary["faces"] == mesh.nface
    assert summary["faces"] == summary["certified_faces"] + summary["merge_faces"]
    assert min(summary["certified_faces"], summary["merge_faces"], summary["seam_vertices"],
               summary["barrier_edges"]) >= 0
    frac = summary["certified_fraction"]
    assert 0.0 <= frac <= 1.0
    if summary["faces"] > 0:
        assert frac == pytest.approx(summary["certified_faces"] / summary["faces"], abs=1e-9)
    times = summary["times"]
    assert set(tu.TIME_KEYS) <= set(times), f"times lacks {set(tu.TIME_KEYS) - set(times)}"
    for k in tu.TIME_KEYS:
        assert isinstance(times[k], (int, float)) and times[k] >= 0.0, (k, times[k])
    assert times["total"] >= max(times[k] for k in tu.TIME_KEYS if k != "total") - 1e-6
    # the post stage (one tile at a time, inside the tile stage) holds the certification
    for k in ("core", "post", "certify"):
        assert isinstance(times[k], (int, float)) and times[k] >= 0.0, (k, times)
    assert times["certify"] <= times["post"] + 1e-6 and times["post"] <= times["tiles"] + 1e-6, times
    assert isinstance(summary["peak_rss_bytes"], int) and summary["peak_rss_bytes"] > 0
    assert isinstance(summary["device"], str) and summary["device"]
    assert tu.tile_count(summary) >= 1
    if halo is not None:
        assert summary["halo"] == int(halo)
    if plan is not None:
        assert summary["halo"] == plan["halo_texels"]
        steps = plan["cell_steps"]
        assert summary["cell"] == pytest.approx(steps) or \
            summary["cell"] == pytest.approx(steps * mesh.lattice.sx), \
            f"cell {summary['cell']} is neither {steps} steps nor {steps * mesh.lattice.sx}"
        assert tu.tile_count(summary) == plan["tiles"]


def check_job(mesh, ref_rows, tris, summary, span=None, XY=None):
    """The .tri files of a kept job against the output PLY and the reference.

    mesh: the tiled output; ref_rows: canonical rows of the reference; tris:
    tu.read_job(); span: tile side in lattice steps (None: not checked);
    XY: the input record integers in input order (None: ordinals not checked).
    """
    assert tris, "no .tri file in the job"
    assert len({(t.i, t.j) for t in tris}) == len(tris)
    assert tu.tile_count(summary) == len(tris), "summary tiles != .tri files (non-empty tiles)"

    # Vertex blocks: tile after tile, in tile order, covering the PLY.
    base = 0
    for t in tris:
        assert t.vertex_base == base, f"{t.path}: vertex base {t.vertex_base}, expected {base}"
        assert t.vertices >= 1, f"{t.path}: an empty tile has a .tri file"
        base += t.vertices
    assert base == mesh.nvert, f".tri vertex counts sum to {base}, the PLY has {mesh.nvert}"

    if span is not None:
        ti, tj = mesh.ix // span, mesh.iy // span
        for t in tris:
            sl = slice(t.vertex_base, t.vertex_base + t.vertices)
            assert np.all(ti[sl] == t.i) and np.all(tj[sl] == t.j), \
                f"{t.path}: vertices outside tile ({t.i}, {t.j}) of {span} lattice steps"
        occupied = set(zip(ti.tolist(), tj.tolist()))
        assert occupied == {(t.i, t.j) for t in tris}, "a non-empty tile has no .tri file"

    if XY is not None:
        X, Y = XY
        ords = tu.first_ordinals(X, Y, mesh.ix, mesh.iy)
        assert np.all(ords >= 0), "a PLY vertex is no input point"
        assert len(np.unique(ords)) == mesh.nvert
        for t in tris:
            o = ords[t.vertex_base:t.vertex_base + t.vertices]
            assert np.all(np.diff(o) > 0), \
                f"{t.path}: vertices not in order of lowest input ordinal"

    # Certified faces: exactly the first faces of the PLY, in tile order.
    cert = np.concatenate([t.faces for t in tris]) if tris else np.zeros((0, 3), np.int64)
    C = len(cert)
    assert summary["certified_faces"] == C
    assert summary["merge_faces"] == mesh.nface - C
    assert C <= mesh.nface
    assert np.array_equal(mesh.faces[:C], cert), \
        "the certified faces of the .tri files are not the first faces of the PLY"
    for t in tris:
        if len(t.faces):
            assert t.faces.min() >= t.vertex_base and \
                t.faces.max() < t.vertex_base + t.vertices, \
                f"{t.path}: a certified face uses a vertex of another tile"

    # Every certified face is a face of the reference (orientation included).
    cert_rows = mesh.rows(cert)
    bad = [r for r in map(tuple, cert_rows.tolist()) if r not in ref_rows]
    assert not bad, f"{len(bad)} of {C} certified faces are not in the reference, " \
                    f"e.g. {bad[:3]} (lattice x0 y0 x1 y1 x2 y2)"

    # No face twice in the PLY (as unordered vertex sets).
    assert tu.unique_face_count(mesh.faces) == mesh.nface, "a face appears twice in the PLY"

    # Seam vertices: own vertices, increasing, merge-frame coordinates.
    gx0 = int(mesh.ix.min()) if mesh.nvert else 0
    gy0 = int(mesh.iy.min()) if mesh.nvert else 0
    seam_ids = set()
    for t in tris:
        ids = t.seam["id"].astype(np.int64)
        if len(ids):
            assert np.all(np.diff(ids) > 0), f"{t.path}: seam vertices not increasing"
            assert ids.min() >= t.vertex_base and ids.max() < t.vertex_base + t.vertices, \
                f"{t.path}: a seam vertex of another tile"
            assert np.array_equal(t.seam["gx"], mesh.ix[ids] - gx0) and \
                np.array_equal(t.seam["gy"], mesh.iy[ids] - gy0), \
                f"{t.path}: seam coordinates are not lattice minus the cloud minimum"
        seam_ids.update(ids.tolist())
        own = set(range(t.vertex_base, t.vertex_base + t.vertices))
        in_cert = set(np.unique(t.faces).tolist()) if len(t.faces) else set()
        lonely = own - in_cert
        assert lonely <= set(ids.tolist()), \
            f"{t.path}: vertices {sorted(lonely - set(ids.tolist()))[:5]} are in no certified " \
            "face and not seam vertices: the merge cannot triangulate them"
        # Barrier edges: the edges of certified faces whose other side is not
        # certified, directed with the certified face on the left.
        de = tu.directed_edges(t.faces)
        want = {(a, b) for (a, b) in de if (b, a) not in de}
        got = list(zip(t.barrier["a"].tolist(), t.barrier["b"].tolist()))
        assert len(set(got)) == len(got), f"{t.path}: a barrier edge twice"
        assert set(got) == want, \
            f"{t.path}: barrier edges differ from the certified faces' border: " \
            f"{len(set(got) - want)} extra, {len(want - set(got))} missing"
        ends = {v for e in got for v in e}
        assert ends <= set(ids.tolist()), f"{t.path}: a barrier edge ends off the seam"
    assert summary["seam_vertices"] == sum(len(t.seam) for t in tris)
    assert summary["barrier_edges"] == sum(len(t.barrier) for t in tris)

    # The merge works on seam vertices only.
    merged = mesh.faces[C:]
    if len(merged):
        off = set(np.unique(merged).tolist()) - seam_ids
        assert not off, f"merge faces use {len(off)} vertices that are no seam vertex"


def tiled_vs_reference(gdt_bin, tmp, inputs, ref, args, *, job=False, plan=True,
                       XY=None, multi=True, valid=True, tag="out"):
    """Runs the tiled pipeline with args and checks it against the reference
    ref (a PLY).  returns (summary, mesh, output path, command line)."""
    out = pathlib.Path(tmp) / f"{tag}.ply"
    extra = []
    jobdir = pathlib.Path(tmp) / f"{tag}.job"
    if job:
        extra = ["--keep-job", "--job", jobdir]
    summary, cmd = tu.run_tiled(gdt_bin, inputs, out, *args, *extra)
    mesh = tu.Mesh(out)
    p = tu.tile_plan(gdt_bin, inputs, pathlib.Path(tmp) / f"{tag}.plan.json", *args) \
        if plan else None
    check_summary(summary, mesh, p)
    if multi:
        assert tu.tile_count(summary) > 1, f"{cmd}: one tile only, the test needs several"
    r = tu.compare(ref, out)
    assert r.returncode == 0, f"tiled != reference: {cmd}\n{r.stdout}{r.stderr}"
    if valid:
        v = tu.validate(out, inputs)
        assert v.returncode == 0, f"validate_mesh fails: {cmd}\n{v.stdout}{v.stderr}"
    if job:
        span = args_span(args, p)
        check_job(mesh, tu.Mesh(ref).row_set(), tu.read_job(jobdir), summary, span, XY)
    else:
        default_job = pathlib.Path(str(out) + ".gdt-job")
        assert not default_job.exists(), f"{cmd}: job directory left after a successful run"
    return summary, mesh, out, cmd


def args_span(args, plan):
    if plan is None:
        return None
    return int(args[args.index("--tile") + 1]) * plan["cell_steps"]


# ------------------------------------------------------------------ 1. generated clouds

KINDS = {
    "lidar": ("--dup-fraction", "0.02"),  # lakes (voids), re-recorded pulses, DEM patches
    "grid": (),
    "mixed": (),
    "uniform": (),
}
NPOINTS = 20000  # about 50 x 50 m at 8 points per square metre

# (tile, cell, halo): cells in CRS units (multiples of the 0.01 lattice step),
# small enough for several tiles; None = automatic.
CONFIGS = [
    ("64", "0.10", "0"),
    ("64", "0.10", "3"),
    ("64", "0.15", "100"),   # a halo wider than the tile
    ("64", None, None),      # automatic cell and halo
    ("256", "0.05", "0"),
    ("256", "0.04", "16"),
    ("1024", "0.02", "0"),
    ("1024", "0.02", None),
]


@pytest.fixture(scope="module")
def generated(tmp_path_factory, gdt_bin):
    d = tmp_path_factory.mktemp("tiled-generated")
    out = {}
    for k, (kind, extra) in enumerate(KINDS.items()):
        cloud = tu.gen_cloud(d / f"{kind}.las", NPOINTS, 11 + k, kind, *extra)
        ref = tu.run_reference(gdt_bin, cloud, d / f"{kind}.ref.ply")
        out[kind] = (cloud, ref)
    return out


@pytest.mark.parametrize("tile,cell,halo", CONFIGS, ids=lambda v: str(v))
@pytest.mark.parametrize("kind", list(KINDS))
def test_tiled_equals_reference(gdt_bin, generated, tmp_path, kind, tile, cell, halo):
    cloud, ref = generated[kind]
    s, *_ = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, tu.tiled_args(tile, cell, halo))
    if halo is not None:
        assert s["halo"] == int(halo)
    else:  # the automatic halo is meant to certify almost every triangle in its tile
        assert s["certified_fraction"] >= 0.5, s["certified_fraction"]


@pytest.mark.sanitize
def test_small_lidar_multi_tile_with_job(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "small.las", 5000, 3, "lidar", "--dup-fraction", "0.05")
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    X, Y, _ = tu.read_las_xy(cloud)
    for halo in ("0", "2"):
        s, *_ = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                   tu.tiled_args("64", "0.05", halo), job=True, XY=(X, Y),
                                   tag=f"h{halo}")
        assert tu.tile_count(s) >= 9


@pytest.mark.parametrize("kind", ["lidar", "mixed"])
@pytest.mark.parametrize("tile,cell,halo", [("64", "0.10", "2"), ("256", "0.05", None)],
                         ids=lambda v: str(v))
def test_permuted_and_split_input_same_triangles(gdt_bin, generated, tmp_path, kind, tile,
                                                 cell, halo):
    cloud, ref = generated[kind]
    args = tu.tiled_args(tile, cell, halo)
    _, _, base, _ = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, args, tag="orig")
    for parts in (1, 3):
        inputs = tu.permute_las(cloud, tmp_path / f"perm{parts}.las", 100 + parts, parts)
        X = np.concatenate([tu.read_las_xy(p)[0] for p in inputs])
        Y = np.concatenate([tu.read_las_xy(p)[1] for p in inputs])
        _, _, out, cmd = tiled_vs_reference(gdt_bin, tmp_path, inputs, ref, args, job=True,
                                            XY=(X, Y), valid=parts == 1, tag=f"perm{parts}")
        tu.assert_equal_meshes(base, out, f"permuted input ({parts} files): {cmd}")


# ------------------------------------------------------------------ 2. one tile

@pytest.mark.sanitize
def test_tiled_equals_single_tile(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 6000, 5, "mixed")
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    single = tmp_path / "single.ply"
    r = tu.run(tu.command(gdt_bin, cloud, single, "--tile", "256", "--single-tile"))
    assert r.returncode == 0, r.stderr
    tu.assert_equal_meshes(ref, single, "--single-tile vs --reference")
    # The same cloud through the tiled pipeline: the tile size of the
    # single-tile run, then many small tiles.
    for tag, args in (("t256", ["--tile", "256"]), ("t64", ["--tile", "64", "--cell", "0.08"])):
        _, _, out, cmd = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, args,
                                            multi=tag == "t64", tag=tag)
        tu.assert_equal_meshes(single, out, f"tiled vs --single-tile: {cmd}")


@pytest.mark.sanitize
def test_single_tile_refuses_a_cloud_larger_than_one_tile(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 3000, 5, "uniform")
    out = tmp_path / "single.ply"
    r = tu.run(tu.command(gdt_bin, cloud, out, "--tile", "64", "--single-tile"))  # 2048 max
    assert r.returncode == 2, r.stderr
    assert "2102" in r.stderr
    assert not out.exists()


# ------------------------------------------------------------------ 3. real samples

REAL = ["autzen_trim.las", "100-points.las", "gps-time-nan.las", "bad_vlr_count.las",
        "autzen-utm.pcd", "epsg_4326.las", "test_epsg_4326.las"]
GEOGRAPHIC = {"epsg_4326.las", "test_epsg_4326.las"}  # projected: validated without --input
MAX_SAMPLE_BYTES = 8 << 20


def fine_cell(mesh, tile, per_side=6):
    """A cell (CRS units, a multiple of the lattice step) giving about
    per_side tiles along the longer side of the mesh's extent."""
    ext = max(int(mesh.ix.max() - mesh.ix.min()), int(mesh.iy.max() - mesh.iy.min()), 1)
    steps = max(1, ext // (tile * per_side))
    return f"{steps * mesh.lattice.sx:.12g}"


@pytest.mark.parametrize("tile", ["64", "256"])
@pytest.mark.parametrize("name", REAL)
def test_real_samples(gdt_bin, data_dir, tmp_path, name, tile):
    src = data_dir / name
    if not src.exists():
        pytest.skip(f"{name} not in {data_dir}")
    if src.stat().st_size > MAX_SAMPLE_BYTES:
        pytest.skip(f"{name}: larger than {MAX_SAMPLE_BYTES} bytes")
    ref = tu.run_reference(gdt_bin, src, tmp_path / "ref.ply")
    refm = tu.Mesh(ref)
    val_in = None if name in GEOGRAPHIC else src
    runs = [("auto", ["--tile", tile])]
    if refm.nvert > 1:
        runs.append(("fine", ["--tile", tile, "--cell", fine_cell(refm, int(tile)), "--halo",
                              "1"]))
    for tag, args in runs:
        out = tmp_path / f"{tag}.ply"
        summary, cmd = tu.run_tiled(gdt_bin, src, out, *args)
        check_summary(summary, tu.Mesh(out))
        if tag == "fine" and refm.nvert > 50:
            assert tu.tile_count(summary) > 1, f"{cmd}: one tile only"
        tu.assert_equal_meshes(ref, out, cmd)
        v = tu.validate(out, val_in)
        assert v.returncode == 0, f"{cmd}\n{v.stdout}{v.stderr}"


def test_unreadable_sample_fails_cleanly(gdt_bin, data_dir, tmp_path):
    src = data_dir / "garbage_nVariableLength.las"
    if not src.exists():
        pytest.skip("garbage_nVariableLength.las not in the data folder")
    out = tmp_path / "out.ply"
    r = tu.run(tu.command(gdt_bin, src, out, "--tile", "64"))
    assert r.returncode == 3, r.stderr
    assert "garbage_nVariableLength.las" in r.stderr
    assert not out.exists()


# ------------------------------------------------------------------ 4. certified faces

def random_cloud(seed):
    """A seeded random cloud (record integers) mixing uniform scatter, a
    grid patch, Gaussian clusters, a collinear run and duplicates, with
    random tile, cell and halo options for it."""
    rng = np.random.default_rng(seed)
    ext = int(rng.integers(3000, 40000))
    n = int(rng.integers(1500, 5000))
    parts_x, parts_y = [], []
    u = int(n * rng.uniform(0.3, 0.9))
    parts_x.append(rng.integers(0, ext, u))
    parts_y.append(rng.integers(0, ext, u))
    step = int(rng.integers(max(1, ext // 400), ext // 40 + 2))
    k = int(rng.integers(5, 25))
    gx, gy = np.meshgrid(np.arange(k), np.arange(k))
    ox, oy = rng.integers(0, ext // 2, 2)
    parts_x.append(ox + step * gx.ravel())
    parts_y.append(oy + step * gy.ravel())
    for _ in range(int(rng.integers(0, 4))):
        c = rng.integers(0, ext, 2)
        m = int(rng.integers(50, 400))
        sd = float(rng.uniform(2, ext / 50))
        parts_x.append(np.rint(c[0] + rng.normal(0, sd, m)).astype(np.int64))
        parts_y.append(np.rint(c[1] + rng.normal(0, sd, m)).astype(np.int64))
    if rng.random() < 0.5:
        d = rng.integers(1, 9, 2)
        m = int(rng.integers(20, 200))
        s0 = rng.integers(0, ext // 2, 2)
        parts_x.append(s0[0] + d[0] * np.arange(m))
        parts_y.append(s0[1] + d[1] * np.arange(m))
    X = np.concatenate(parts_x)
    Y = np.concatenate(parts_y)
    dup = rng.integers(0, len(X), int(len(X) * rng.uniform(0, 0.1)))
    X = np.concatenate([X, X[dup]]) - int(rng.integers(0, ext))  # negative tiles too
    Y = np.concatenate([Y, Y[dup]]) - int(rng.integers(0, ext))
    Z = rng.integers(-1000, 100000, len(X))
    perm = rng.permutation(len(X))
    tile = int(rng.choice([64, 128, 256]))
    side = int(max(X.max() - X.min(), Y.max() - Y.min()))
    per_side = int(rng.integers(2, 8))
    cell_steps = max(1, side // (tile * per_side))
    halo = rng.choice(["0", "1", "2", "5", "20", "auto"])
    args = ["--tile", str(tile), "--cell", f"{cell_steps * S:.2f}"]
    if halo != "auto":
        args += ["--halo", str(halo)]
    return X[perm], Y[perm], Z[perm], args


@pytest.mark.parametrize("seed", range(20))
def test_certified_faces_on_random_clouds(gdt_bin, tmp_path, seed):
    X, Y, Z, args = random_cloud(seed)
    cloud = tu.write_las(tmp_path / f"r{seed}.las", X, Y, Z)
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, args, job=True, XY=(X, Y),
                       multi=False)


@pytest.mark.sanitize
def test_certified_faces_small_random_cloud(gdt_bin, tmp_path):
    X, Y, Z, _ = random_cloud(1000)
    cloud = tu.write_las(tmp_path / "r.las", X, Y, Z)
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    side = int(max(X.max() - X.min(), Y.max() - Y.min()))
    cell = f"{max(1, side // (64 * 5)) * S:.2f}"
    s, *_ = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, ["--tile", "64", "--cell", cell,
                                                               "--halo", "3"],
                               job=True, XY=(X, Y))
    assert s["certified_faces"] > 0 and s["merge_faces"] > 0


# ------------------------------------------------------------------ 5. awkward layouts

T = 64 * 10  # tile side in lattice steps for --tile 64 --cell 0.10
LAYOUT_ARGS = ["--tile", "64", "--cell", "0.10"]


def uniform_in(rng, n, x0, x1, y0, y1):
    return rng.integers(x0, x1, n), rng.integers(y0, y1, n)


def layout(name, seed=1):
    """(X, Y, {(i, j): vertices} expected in some tiles)"""
    rng = np.random.default_rng(seed)
    expect = {}
    if name == "empty_tiles":
        x, y = uniform_in(rng, 5000, 0, 8 * T, 0, 8 * T)
        keep = ~((x >= 2 * T) & (x < 6 * T) & (y >= 2 * T) & (y < 6 * T))
        cx, cy = uniform_in(rng, 400, 12 * T + 50, 13 * T - 50, 3 * T + 50, 4 * T - 50)
        X, Y = np.concatenate([x[keep], cx]), np.concatenate([y[keep], cy])
        for i in range(2, 6):
            for j in range(2, 6):
                expect[(i, j)] = 0
        expect[(10, 3)] = 0
    elif name == "lone_points":
        x, y = uniform_in(rng, 2500, 0, 3 * T, 0, 3 * T)
        lone = [(5 * T + 17, T + 300), (3 * T + 5, 2 * T + 100), (-T + 3, -T + 3),
                (3 * T + T // 2, -2 * T + 1)]
        X = np.concatenate([x, [p[0] for p in lone]])
        Y = np.concatenate([y, [p[1] for p in lone]])
        expect.update({(5, 1): 1, (3, 2): 1, (-1, -1): 1, (3, -2): 1, (4, 1): 0})
    elif name == "two_and_three":
        x, y = uniform_in(rng, 2500, 0, 3 * T, 0, 3 * T)
        extra = [(4 * T + 10, 20), (4 * T + 600, 630),                       # tile (4, 0): two
                 (4 * T + 10, 2 * T + 10), (4 * T + 60, 2 * T + 30),
                 (4 * T + 110, 2 * T + 50),                                   # (4, 2): collinear
                 (T + 100, 3 * T), (T + 200, 3 * T), (T + 300, 3 * T),        # (1, 3): on its edge
                 (3 * T, T + 7), (3 * T + 1, T + 8)]                          # (3, 1): two
        X = np.concatenate([x, [p[0] for p in extra]])
        Y = np.concatenate([y, [p[1] for p in extra]])
        expect.update({(4, 0): 2, (4, 2): 3, (1, 3): 3, (3, 1): 2})
    elif name == "void_larger_than_halo":
        x, y = uniform_in(rng, 9000, 0, 10 * T, 0, 10 * T)
        keep = (x - 5 * T) ** 2 + (y - 5 * T) ** 2 > (5 * T // 2) ** 2
        X = np.concatenate([x[keep], [5 * T + 11]])
        Y = np.concatenate([y[keep], [5 * T + 13]])  # a lone point amid the void
        expect.update({(5, 5): 1, (4, 4): 0})
    elif name == "one_row":
        X, Y = uniform_in(rng, 4000, 0, 12 * T, 2 * T + 1, 3 * T - 1)
    elif name == "one_column":
        Y, X = uniform_in(rng, 4000, -5 * T, 7 * T, 7 * T + 200, 7 * T + 260)
    elif name == "thin_strip":
        k = np.arange(3000)
        X = np.concatenate([5 * k, 5 * k, 5 * k])
        Y = np.concatenate([np.full(3000, 100), np.full(3000, 105), np.full(3000, 110)])
    elif name == "diagonal_strip":
        k = np.arange(2500)
        X = np.concatenate([3 * k + 3 * d for d in range(3)])
        Y = np.concatenate([3 * k for _ in range(3)])
    elif name == "collinear":
        k = np.arange(3000)
        X, Y = 7 * k - 3 * T, 3 * k + 11
    elif name == "collinear_on_tile_border":
        X = np.arange(-2 * T, 6 * T, 3)
        Y = np.full(X.size, 2 * T)  # the south edge of the row j = 2
    elif name == "tile_borders":
        x, y = uniform_in(rng, 1500, 0, 4 * T, 0, 4 * T)
        line = np.arange(0, 4 * T, 20)
        bx = np.concatenate([np.full(line.size, c * T) for c in range(5)] +
                            [line for _ in range(5)])
        by = np.concatenate([line for _ in range(5)] +
                            [np.full(line.size, c * T) for c in range(5)])
        X, Y = np.concatenate([x, bx]), np.concatenate([y, by])
    elif name == "dense_clusters":
        x, y = uniform_in(rng, 800, 0, 6 * T, 0, 6 * T)
        cx = [np.rint(c + rng.normal(0, 15, 600)).astype(np.int64) for c in (T, 3 * T, 5 * T)]
        cy = [np.rint(c + rng.normal(0, 15, 600)).astype(np.int64) for c in (T, 4 * T, 2 * T)]
        X, Y = np.concatenate([x] + cx), np.concatenate([y] + cy)
    elif name == "rotated_grid":
        a, b = np.meshgrid(np.arange(-40, 40), np.arange(-40, 40))
        X = 3 * T + 9 * a.ravel() - 12 * b.ravel()   # basis (9, 12), (-12, 9): co-circular quads
        Y = 3 * T + 12 * a.ravel() + 9 * b.ravel()
    else:
        raise ValueError(name)
    perm = rng.permutation(len(X))
    return np.asarray(X, np.int64)[perm], np.asarray(Y, np.int64)[perm], expect


LAYOUTS = ["empty_tiles", "lone_points", "two_and_three", "void_larger_than_halo", "one_row",
           "one_column", "thin_strip", "diagonal_strip", "collinear", "collinear_on_tile_border",
           "tile_borders", "dense_clusters", "rotated_grid"]


def run_layout(gdt_bin, tmp_path, name, halo):
    X, Y, expect = layout(name)
    Z = np.arange(len(X)) % 5000
    cloud = tu.write_las(tmp_path / f"{name}.las", X, Y, Z)
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    s, mesh, out, cmd = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                           LAYOUT_ARGS + ["--halo", halo], job=True,
                                           XY=(X, Y))
    tris = {(t.i, t.j): t for t in tu.read_job(tmp_path / "out.job")}
    for ij, nv in expect.items():
        if nv == 0:
            assert ij not in tris, f"{cmd}: empty tile {ij} has a .tri file"
        else:
            assert ij in tris and tris[ij].vertices == nv, \
                f"{cmd}: tile {ij} should hold {nv} vertices"
    return s, mesh


@pytest.mark.parametrize("halo", ["0", "2"])
@pytest.mark.parametrize("name", LAYOUTS)
def test_awkward_layouts(gdt_bin, tmp_path, name, halo):
    s, mesh = run_layout(gdt_bin, tmp_path, name, halo)
    if name.startswith("collinear"):
        assert mesh.nface == 0 and s["faces"] == 0
    else:
        assert mesh.nface > 0


@pytest.mark.sanitize
def test_lone_point_tiles_sanitized(gdt_bin, tmp_path):
    run_layout(gdt_bin, tmp_path, "two_and_three", "1")


@pytest.mark.parametrize("rule", ["first", "min-z", "max-z"])
def test_duplicates_across_the_cloud(gdt_bin, tmp_path, rule):
    """Every (x, y) recorded 1-4 times with distinct z, shuffled over the
    file: vertices and their z as the reference gives them."""
    rng = np.random.default_rng(9)
    x, y = uniform_in(rng, 3000, 0, 5 * T, 0, 5 * T)
    reps = rng.integers(1, 5, x.size)
    X, Y = np.repeat(x, reps), np.repeat(y, reps)
    Z = rng.permutation(X.size)  # distinct z
    perm = rng.permutation(X.size)
    X, Y, Z = X[perm], Y[perm], Z[perm]
    cloud = tu.write_las(tmp_path / "dups.las", X, Y, Z)
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply", "--dup", rule)
    s, mesh, out, cmd = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                           LAYOUT_ARGS + ["--halo", "2", "--dup", rule],
                                           job=True, XY=(X, Y))
    assert mesh.nvert == len(set(zip(x.tolist(), y.tolist())))
    zt, zr = mesh.z_by_point(), tu.Mesh(ref).z_by_point()
    diff = [p for p in zr if zt.get(p) != zr[p]]
    assert not diff, f"{cmd}: z differs from --reference --dup {rule} at {len(diff)} points, " \
                     f"e.g. {diff[:3]}"


DEGENERATE = ["grid", "rotgrid", "circle", "thincircle", "clusters", "mixed", "sparse",
              "uniform"]


@pytest.mark.parametrize("kind", DEGENERATE)
def test_degenerate_corpus(gdt_bin, tmp_path, kind):
    """gen_degenerate.py clouds (co-circular grids, points on one circle,
    clusters, points spread over 2^31 lattice steps) at --tile 64."""
    cloud = tu.gen_degenerate(tmp_path / f"{kind}.las", kind, "--n", "3000", "--seed", "2")
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    X, Y, _ = tu.read_las_xy(cloud)
    for halo in (None, "0"):
        tiled_vs_reference(gdt_bin, tmp_path, cloud, ref, tu.tiled_args("64", None, halo),
                           job=True, XY=(X, Y), tag=f"h{halo}")


@pytest.mark.sanitize
def test_cloud_wider_than_the_merge_frame_is_refused(gdt_bin, tmp_path):
    """Corners of the int32 range: wider than 2^31 - 1 lattice steps, which
    the seam merge cannot hold: a clean bad-input exit, no output."""
    cloud = tu.gen_degenerate(tmp_path / "extreme.las", "extreme", "--n", "200", "--seed", "2")
    out = tmp_path / "out.ply"
    r = tu.run(tu.command(gdt_bin, cloud, out, "--tile", "64"))
    assert r.returncode == 3, r.stderr
    assert "GDT-" in r.stderr and "2^31" in r.stderr
    assert not out.exists()


# ------------------------------------------------------------------ 6. determinism, summary

@pytest.mark.sanitize
def test_deterministic_bytes_and_job_handling(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 8000, 21, "lidar", "--dup-fraction", "0.02")
    args = ["--tile", "64", "--cell", "0.06", "--halo", "2"]
    a, b, c, d = (tmp_path / f"{n}.ply" for n in "abcd")
    sa, cmd = tu.run_tiled(gdt_bin, cloud, a, *args)
    assert tu.tile_count(sa) > 1
    assert not pathlib.Path(str(a) + ".gdt-job").exists(), "job directory left after success"
    sb, _ = tu.run_tiled(gdt_bin, cloud, b, *args)
    assert a.read_bytes() == b.read_bytes(), f"two runs of {cmd} differ"
    job = tmp_path / "kept"
    sc, _ = tu.run_tiled(gdt_bin, cloud, c, *args, "--keep-job", "--job", job)
    assert (job / "tiles").is_dir() and any(p.suffix == ".tri" for p in (job / "tiles").iterdir())
    assert a.read_bytes() == c.read_bytes(), "--keep-job/--job change the output"
    sd, _ = tu.run_tiled(gdt_bin, cloud, d, *args, "--threads", "1")
    assert a.read_bytes() == d.read_bytes(), "--threads 1 changes the output"
    e = tmp_path / "e.ply"
    se, _ = tu.run_tiled(gdt_bin, cloud, e, *args, "--mem-budget", "16M")
    assert a.read_bytes() == e.read_bytes(), "--mem-budget 16M changes the output"
    for s in (sb, sc, sd, se):
        assert tu.tile_count(s) == tu.tile_count(sa)
        for k in ("vertices", "faces", "certified_faces", "merge_faces", "seam_vertices",
                  "barrier_edges", "halo", "cell"):
            assert s[k] == sa[k], k
    mesh = tu.Mesh(a)
    check_summary(sa, mesh, tu.tile_plan(gdt_bin, cloud, tmp_path / "plan.json", *args),
                  halo="2")
    assert sa["certified_faces"] > 0


def test_summary_against_job_and_output_header(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 12000, 8, "mixed")
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    s, mesh, out, _ = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                         ["--tile", "64", "--cell", "0.12"], job=True)
    head = out.read_bytes()[:4096].split(b"end_header")[0].decode("latin-1")
    refhead = ref.read_bytes()[:4096].split(b"end_header")[0].decode("latin-1")
    for key in ("comment lattice", "comment crs"):
        want = [ln for ln in refhead.splitlines() if ln.startswith(key)]
        assert want and [ln for ln in head.splitlines() if ln.startswith(key)] == want, key
    assert s["halo"] >= 0  # automatic halo reported
    checked = tmp_path / "checked.ply"
    r = tu.run(tu.command(gdt_bin, cloud, checked, "--tile", "64", "--cell", "0.12", "--check"))
    assert r.returncode == 0, r.stderr
    assert checked.read_bytes() == out.read_bytes(), "--check changes the output"
    assert os.path.getsize(out) == len(head.encode("latin-1")) + len(b"end_header\n") + \
        24 * mesh.nvert + 13 * mesh.nface


def test_without_tile_the_device_chooses(gdt_bin, tmp_path):
    """Without --tile the run chooses the side for its device (a CPU device here:
    4096), says so with -v and in --json, records it in the job, and a --resume
    keeps it; a given --tile is not a choice."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 3000, 5, "lidar")
    out, js, job = tmp_path / "a.ply", tmp_path / "a.json", tmp_path / "a.job"
    r = tu.run([gdt_bin, cloud, "-o", out, "--json", js, "--job", job, "--keep-job", "-v"])
    assert r.returncode == 0, r.stderr
    s = json.loads(js.read_text())
    assert s["tile"] == 4096 and s["tile_auto"] is True, (s["tile"], s["tile_auto"])
    assert "--tile 4096 for " in r.stderr and "a CPU device" in r.stderr, r.stderr
    first = out.read_bytes()
    out.unlink()
    r = tu.run([gdt_bin, "--resume", job, "--json", tmp_path / "b.json", "-v"])
    assert r.returncode == 0, r.stderr
    b = json.loads((tmp_path / "b.json").read_text())
    assert b["tile"] == 4096 and b["tile_auto"] is False and "--tile 4096 for" not in r.stderr
    assert b["reused"]["tiles"] == b["tiles"], b["reused"]
    assert out.read_bytes() == first
    r = tu.run([gdt_bin, cloud, "-o", tmp_path / "c.ply", "--json", tmp_path / "c.json",
                "--tile", "1024", "-v"])
    assert r.returncode == 0, r.stderr
    c = json.loads((tmp_path / "c.json").read_text())
    assert c["tile"] == 1024 and c["tile_auto"] is False and "--tile 1024 for" not in r.stderr


@pytest.mark.parametrize("extra", [pytest.param(["--device", "0,0"], marks=pytest.mark.sanitize),
                                   ["--device", "0,0,0"], ["--device", "cpu:all"],
                                   ["--device", "all"],
                                   pytest.param(["--queues", "2"], marks=pytest.mark.sanitize),
                                   ["--queues", "3", "--device", "0,0"]])
def test_several_devices_give_the_same_bytes(gdt_bin, tmp_path, extra):
    """Tiles shared by several cores (several command queues of the one PoCL
    device, or every device of a type) give the bytes of one device, --json
    figures included."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 20000, 9, "lidar", "--dup-fraction", "0.02")
    outs = []
    for tag, extra in (("one", []), ("many", extra)):
        out, js = tmp_path / f"{tag}.ply", tmp_path / f"{tag}.json"
        r = tu.run([gdt_bin, cloud, "--tile", "64", "--cell", "0.1", "-o", out, "--json", js,
                    "-q", *extra])
        assert r.returncode == 0, r.stderr
        outs.append((out.read_bytes(), json.loads(js.read_text())))
    (a, sa), (b, sb) = outs
    assert a == b
    for key in ("tiles", "gcd_tiles", "insert_tiles", "max_tile_points", "max_halo_points",
                "certified_faces", "merge_faces"):
        assert sa.get(key) == sb.get(key), key


@pytest.mark.parametrize("extra", [[], ["--device", "0,0"], ["--queues", "3"]])
def test_device_busy_share_is_reported(gdt_bin, tmp_path, extra):
    """--json reports the device's busy time in the tile stage (the time at
    least one of its queues was executing a command) and its share of the
    stage's time; -v prints both.  The share is a fraction: above 0 when
    tiles were triangulated, at most 1 also with several queues on the one
    device (their commands' overlaps are counted once), and 0 when every
    tile is reused."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 60000, 5, "lidar")
    out, js, job = tmp_path / "o.ply", tmp_path / "o.json", tmp_path / "job"
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "--json", js, "-v", "--keep-job",
                "--job", job, *extra])
    assert r.returncode == 0, r.stderr
    t = json.loads(js.read_text())["times"]
    ndev = 1  # the one PoCL device, however many queues
    assert 0 < t["device_busy"] <= t["tiles"] * ndev * 1.001, t
    assert 0 < t["device_busy_share"] <= 1.0, t
    assert abs(t["device_busy_share"] - t["device_busy"] / (t["tiles"] * ndev)) < 1e-6, t
    assert "device busy" in r.stderr and "% of the stage" in r.stderr, r.stderr
    # a rerun that reuses every tile keeps its devices idle
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "--json", js, "-q", "--job", job,
                *extra])
    assert r.returncode == 0, r.stderr
    t = json.loads(js.read_text())["times"]
    assert t["device_busy"] == 0 and t["device_busy_share"] == 0, t


@pytest.mark.parametrize("spec,code", [("0,,0", 2), ("0,x", 2), ("gpu:all", 5)])
def test_bad_device_lists(gdt_bin, tmp_path, spec, code):
    """A malformed list is a usage error before any work; a list element that
    finds no device is exit 5 naming it."""
    if code == 5:
        types = [ln.split(None, 2)[-1] for ln in tu.run(["clinfo"]).stdout.splitlines()
                 if ln.strip().startswith("Device Type")]
        if any("GPU" in t for t in types):
            pytest.skip("this machine has an OpenCL GPU")
    cloud = tu.gen_cloud(tmp_path / "c.las", 500, 2, "uniform")
    r = tu.run([gdt_bin, cloud, "-o", tmp_path / "o.ply", "--device", spec])
    assert r.returncode == code, r.stderr
    assert spec in r.stderr
    assert not (tmp_path / "o.ply").exists()


@pytest.mark.parametrize("args", [["--queues", "0"], ["--queues", "9"], ["--queues", "x"],
                                  ["--queues", "2", "--single-tile"],
                                  ["--queues", "2", "--reference"]])
def test_bad_queue_counts(gdt_bin, tmp_path, args):
    """--queues takes 1..8, for the tiled run only: anything else is a usage
    error naming the option, before any output."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 500, 2, "uniform")
    r = tu.run([gdt_bin, cloud, "-o", tmp_path / "o.ply", *args])
    assert r.returncode == 2, r.stderr
    assert "--queues" in r.stderr
    assert not (tmp_path / "o.ply").exists()


def test_queues_share_the_device(gdt_bin, tmp_path):
    """--queues N gives the device N command queues in the tile stage, the
    further ones in its context with its built kernels (-v says so), and a
    device named twice in --device gets one further queue, not a second
    context; a CPU device gets one queue unless asked.  Where the runtime
    cannot launch one program's kernels from two queues (PoCL's CPU drivers
    before PoCL 7), every further queue has programs of its own and says so.
    The mesh is the same bytes whatever the queues."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 5000, 3, "lidar")
    meshes = set()
    for args, queues in (([], 1), (["--queues", "3"], 3), (["--device", "0,0"], 2),
                         (["--device", "0,0", "--queues", "3"], 3)):
        r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", tmp_path / "o.ply", "-v", *args])
        assert r.returncode == 0, r.stderr
        assert r.stderr.count("a further command queue") == queues - 1, (args, r.stderr)
        assert (f"{queues} command queues in the tile stage" in r.stderr) == (queues > 1), \
            (args, r.stderr)
        own = r.stderr.count("a further command queue, with programs of its own")
        assert own in (0, queues - 1), (args, r.stderr)
        pocl = re.search(r"\(PoCL (\d+)\.\d+\S*'s CPU driver", r.stderr)
        if own:
            assert pocl and int(pocl.group(1)) < 7, r.stderr
            assert r.stderr.count("OpenCL programs:") == queues, (args, r.stderr)
        meshes.add((tmp_path / "o.ply").read_bytes())
    assert len(meshes) == 1


def test_single_tile_refuses_a_device_list(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 500, 2, "uniform")
    r = tu.run([gdt_bin, cloud, "-o", tmp_path / "o.ply", "--single-tile", "--device", "0,0"])
    assert r.returncode == 2 and "--single-tile" in r.stderr, r.stderr
