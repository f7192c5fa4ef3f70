"""The out-of-core tiler, driven by the tiler_run tool on generated LAS files.

Clouds have voids (a lake, a strip without returns), dense clusters,
re-recorded (x, y) with another z, and negative record integers.  Checked
against brute force in numpy:
  - every input point lands in exactly one tile, the right one, in input
    order (the .raw files are a permutation of the input records);
  - each tile's .pts is the --dup merge of its points, sorted by ordinal;
  - each halo is exactly the merged points of other tiles in the halo box;
  - the tiny test budget takes every spill and merge path and writes
    byte-identical files;
  - index.vdb, read with OpenVDB's own API (tiler_vdb_dump), holds the
    counts pass 2 wrote, and its density grid sums to them;
  - the plan: about N^2/4 points per tile with --cell auto, the printed
    min/median/max/empty figures, and refused tile-local ranges.
"""
import os
import re

import laspy
import numpy as np
import pytest

REC = np.dtype([("x", "<i8"), ("y", "<i8"), ("z", "<f8"), ("ord", "<u8")])


@pytest.fixture(scope="session")
def tiler_run(tools_dir):
    exe = tools_dir / "tiler_run"
    if not exe.exists():
        pytest.fail(f"tiler_run not built at {exe} (set GDT_BUILD_DIR)")
    return exe


@pytest.fixture(scope="session")
def vdb_dump(tools_dir):
    exe = tools_dir / "tiler_vdb_dump"
    if not exe.exists():
        pytest.fail(f"tiler_vdb_dump not built at {exe} (set GDT_BUILD_DIR)")
    return exe


def make_cloud(seed, n_background=40000, clusters=5, per_cluster=2500, dup_fraction=0.03):
    """Record integers X, Y, Z (scale 0.01) with voids, clusters, duplicates."""
    rng = np.random.default_rng(seed)
    x = rng.integers(-20000, 20000, size=3 * n_background)
    y = rng.integers(-15000, 25000, size=3 * n_background)
    lake = (x - 6000) ** 2 + (y - 2000) ** 2 < 7000 ** 2
    strip = (x > -14000) & (x < -9000)
    keep = ~lake & ~strip
    x, y = x[keep][:n_background], y[keep][:n_background]
    cx = rng.integers(-18000, 18000, size=clusters)
    cy = rng.integers(-13000, 23000, size=clusters)
    x = np.concatenate([x] + [c + rng.integers(-300, 301, per_cluster) for c in cx])
    y = np.concatenate([y] + [c + rng.integers(-300, 301, per_cluster) for c in cy])
    nd = int(dup_fraction * len(x))
    src = rng.integers(0, len(x), nd)
    x = np.concatenate([x, x[src]])
    y = np.concatenate([y, y[src]])
    z = rng.integers(-5000, 90000, size=len(x))
    perm = rng.permutation(len(x))
    return x[perm].astype(np.int32), y[perm].astype(np.int32), z[perm].astype(np.int32)


def write_las(path, X, Y, Z):
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    hdr.scales = np.array([0.01, 0.01, 0.01])
    hdr.offsets = np.array([500000.0, 4000000.0, 0.0])
    las = laspy.LasData(hdr)
    las.X, las.Y, las.Z = X, Y, Z
    las.write(str(path))


def read_input(paths):
    """The cloud as the tiler sees it: lattice = the LAS record integers."""
    xs, ys, zs = [], [], []
    for p in paths:
        las = laspy.read(str(p))
        xs.append(np.asarray(las.X, dtype=np.int64))
        ys.append(np.asarray(las.Y, dtype=np.int64))
        zs.append(np.asarray(las.z, dtype=np.float64))
    a = np.zeros(sum(len(x) for x in xs), dtype=REC)
    a["x"], a["y"], a["z"] = np.concatenate(xs), np.concatenate(ys), np.concatenate(zs)
    a["ord"] = np.arange(len(a), dtype=np.uint64)
    return a


def dedup(a, rule):
    """Brute-force --dup merge: one record per (x, y), ord = lowest, z by rule."""
    order = np.lexsort((a["ord"], a["y"], a["x"]))
    s = a[order]
    start = np.ones(len(s), dtype=bool)
    start[1:] = (s["x"][1:] != s["x"][:-1]) | (s["y"][1:] != s["y"][:-1])
    idx = np.flatnonzero(start)
    out = s[idx].copy()  # lowest ord of each group, and its z
    if rule == "min-z":
        out["z"] = np.minimum.reduceat(s["z"], idx)
    elif rule == "max-z":
        out["z"] = np.maximum.reduceat(s["z"], idx)
    return out[np.argsort(out["ord"], kind="stable")]


def run_tiler(runner, exe, job, inputs, *args, tiny=False):
    os.makedirs(job, exist_ok=True)
    env = dict(os.environ)
    env.pop("GDT_TEST_TINY_BUDGET", None)
    if tiny:
        env["GDT_TEST_TINY_BUDGET"] = "1"
    r = runner([exe, job, *inputs, *args], env=env)
    assert r.returncode == 0, r.stderr
    res = {"plan": {}, "stats": {}, "tiles": [], "halos": {}, "text": r.stdout}
    for line in r.stdout.splitlines():
        f = line.split()
        if not f or line[0] == " " or line.startswith("tile plan:"):
            continue  # the human-readable plan
        if f[0] in ("plan", "stats"):
            res[f[0]] = {k: int(v) for k, v in (kv.split("=") for kv in f[1:])}
        elif f[0] == "tile":
            k, i, j, x0, y0, raw, pts, edge = map(int, f[1:])
            res["tiles"].append(dict(k=k, i=i, j=j, x0=x0, y0=y0, raw=raw, pts=pts, edge=edge))
        elif f[0] == "halo":
            res["halos"][(int(f[2]), int(f[3]))] = int(f[4])
    return res


def records(path):
    return np.fromfile(path, dtype=REC)


@pytest.fixture(scope="module")
def cloud_las(tmp_path_factory):
    d = tmp_path_factory.mktemp("tiler-cloud")
    X, Y, Z = make_cloud(7)
    a, b = d / "part-a.las", d / "part-b.las"  # two inputs form one cloud
    h = len(X) // 3
    write_las(a, X[:h], Y[:h], Z[:h])
    write_las(b, X[h:], Y[h:], Z[h:])
    return [a, b]


def check_run(res, job, cloud, rule):
    """Every point in one tile; merged tiles, edges and halos = brute force."""
    T = res["plan"]["span"]
    h = res["plan"]["halo"] * res["plan"]["cell"]
    tiles_dir = os.path.join(job, "tiles")
    raws = []
    for t in res["tiles"]:
        raw = records(os.path.join(tiles_dir, f"tile_{t['i']}_{t['j']}.raw"))
        assert len(raw) == t["raw"]
        assert np.all(raw["x"] // T == t["i"]) and np.all(raw["y"] // T == t["j"])
        assert np.all(np.diff(raw["ord"].astype(np.int64)) > 0), "raw file not in input order"
        raws.append(raw)
    allraw = np.concatenate(raws)
    allraw = allraw[np.argsort(allraw["ord"])]
    assert len(allraw) == len(cloud)
    assert np.array_equal(allraw, cloud), "tile files are not a permutation of the input"

    merged = dedup(cloud, rule)
    mi, mj = merged["x"] // T, merged["y"] // T
    for t in res["tiles"]:
        base = os.path.join(tiles_dir, f"tile_{t['i']}_{t['j']}")
        pts = records(base + ".pts")
        exp = merged[(mi == t["i"]) & (mj == t["j"])]
        assert np.array_equal(pts, exp), f"tile {t['i']},{t['j']}: --dup {rule} merge differs"
        x0, y0 = t["x0"], t["y0"]
        border = ((exp["x"] - x0 < h) | (x0 + T - 1 - exp["x"] < h) |
                  (exp["y"] - y0 < h) | (y0 + T - 1 - exp["y"] < h))
        assert np.array_equal(records(base + ".edge"), exp[border])
        if res["halos"]:
            inbox = ((merged["x"] >= x0 - h) & (merged["x"] < x0 + T + h) &
                     (merged["y"] >= y0 - h) & (merged["y"] < y0 + T + h) &
                     ~((mi == t["i"]) & (mj == t["j"])))
            halo = records(os.path.join(job, "halo", f"halo_{t['i']}_{t['j']}.bin"))
            assert np.array_equal(halo, merged[inbox]), f"halo of tile {t['i']},{t['j']}"
    assert sum(t["pts"] for t in res["tiles"]) == len(merged)


@pytest.mark.parametrize("rule", ["first", "min-z", "max-z"])
def test_tiles_and_halos_match_brute_force(runner, tiler_run, cloud_las, tmp_path, rule):
    cloud = read_input(cloud_las)
    job = tmp_path / "job"
    os.makedirs(job / "halo")
    res = run_tiler(runner, tiler_run, job, cloud_las, "--tile", "64", "--cell", "0.37",
                    "--halo", "9", "--dup", rule, "--keep-spill", "--no-sync",
                    "--dump-halo", job / "halo")
    assert res["plan"]["cell"] == 37 and res["plan"]["cell_auto"] == 0
    assert len(res["tiles"]) > 20
    assert res["stats"]["merged_duplicates"] == len(cloud) - len(dedup(cloud, rule))
    check_run(res, str(job), cloud, rule)


@pytest.mark.sanitize
def test_tiny_budget_gives_identical_files(runner, tiler_run, cloud_las, tmp_path):
    """The tiny budget goes through bucket levels and the out-of-core merge."""
    cloud = read_input(cloud_las)
    args = ["--tile", "64", "--cell", "0.5", "--halo", "6", "--dup", "min-z", "--keep-spill",
            "--no-sync"]
    jobs = []
    for tiny in (False, True):
        job = tmp_path / ("tiny" if tiny else "normal")
        os.makedirs(job / "halo")
        res = run_tiler(runner, tiler_run, job, cloud_las, *args, "--dump-halo", job / "halo",
                        tiny=tiny)
        jobs.append((job, res))
    (ja, ra), (jb, rb) = jobs
    assert ra["stats"]["spill_levels"] == 0 and ra["stats"]["external_merges"] == 0
    assert rb["stats"]["spill_levels"] >= 2 and rb["stats"]["bucket_records"] >= 2 * len(cloud)
    assert rb["stats"]["external_merges"] > 0 and rb["stats"]["merge_levels"] >= 2
    assert rb["stats"]["fd_budget"] == 4
    assert ra["plan"] == rb["plan"] and ra["tiles"] == rb["tiles"]
    for sub in ("tiles", "halo"):
        names = sorted(os.listdir(ja / sub))
        assert names == sorted(os.listdir(jb / sub))
        assert not [n for n in names if n.endswith(".tmp")]
        for n in names:
            assert (ja / sub / n).read_bytes() == (jb / sub / n).read_bytes(), f"{sub}/{n}"
    check_run(rb, str(jb), cloud, "min-z")


def collapse_table_bytes(n):
    """The --dup merge's hash table for a tile of n records."""
    cap = 16
    while cap < 2 * n:
        cap *= 2
    return 4 * cap


@pytest.mark.sanitize
def test_pass2_in_memory_when_the_budget_holds_it(runner, tiler_run, tmp_path):
    """Pass 2 keeps the records in memory (no .raw files) exactly when half the
    budget holds them and the merge's hash table; either way, and with the
    tiny out-of-core budget, the tile files are the same bytes."""
    X, Y, Z = make_cloud(11, n_background=300000)
    las = tmp_path / "big.las"
    write_las(las, X, Y, Z)
    cloud = read_input([las])
    args = ["--tile", "64", "--cell", "2.5", "--halo", "4", "--dup", "max-z", "--no-sync"]
    runs = {}
    for name, extra, tiny in (("mem", ["--mem-budget", str(64 << 20)], False),
                              ("file", ["--mem-budget", str(16 << 20)], False),
                              ("tiny", ["--keep-spill"], True)):
        job = tmp_path / name
        runs[name] = (job, run_tiler(runner, tiler_run, job, [las], *args, *extra, tiny=tiny))
    largest = max(t["raw"] for t in runs["mem"][1]["tiles"])
    need = 32 * len(cloud) + collapse_table_bytes(largest)
    assert need <= (64 << 20) // 2 and need > (16 << 20) // 2, "the cloud does not split the budgets"
    assert runs["mem"][1]["stats"]["spill_in_memory"] == 1
    assert runs["file"][1]["stats"]["spill_in_memory"] == 0
    assert runs["tiny"][1]["stats"]["spill_in_memory"] == 0
    names = {k: sorted(os.listdir(job / "tiles")) for k, (job, _) in runs.items()}
    assert not [n for n in names["mem"] if ".raw" in n or n.endswith(".tmp")]
    assert names["mem"] == names["file"]
    assert names["mem"] == [n for n in names["tiny"] if not n.endswith(".raw")]
    for n in names["mem"]:
        data = (runs["mem"][0] / "tiles" / n).read_bytes()
        assert data == (runs["file"][0] / "tiles" / n).read_bytes(), n
        assert data == (runs["tiny"][0] / "tiles" / n).read_bytes(), n
    check_run(runs["tiny"][1], str(runs["tiny"][0]), cloud, "max-z")


def parse_dump(text):
    tiles, density, meta = {}, {}, {}
    for line in text.splitlines():
        f = line.split()
        if f[0] == "tile":
            tiles[(int(f[1]), int(f[2]))] = int(f[3])
        elif f[0] == "density":
            density[(int(f[1]), int(f[2]))] = int(f[3])
        elif f[0] == "meta":
            meta[(f[1], f[2])] = f[3]
        elif f[0] == "xform":
            meta[(f[1], "xform")] = tuple(float(v) for v in f[2:5])
    return tiles, density, meta


@pytest.mark.sanitize
def test_index_vdb_holds_pass2_counts(runner, tiler_run, vdb_dump, cloud_las, tmp_path):
    job = tmp_path / "job"
    res = run_tiler(runner, tiler_run, job, cloud_las, "--tile", "64", "--keep-spill",
                    "--no-sync")
    r = runner([vdb_dump, job / "index.vdb", "--density"])
    assert r.returncode == 0, r.stderr
    tiles, density, meta = parse_dump(r.stdout)
    p = res["plan"]
    assert int(meta[("tile_points", "gdt_span")]) == p["span"]
    assert int(meta[("density", "gdt_density_shift")]) == p["shift"]
    assert int(meta[("tile_points", "gdt_points")]) == p["points"]
    i0, j0 = int(meta[("tile_points", "gdt_tile_i0")]), int(meta[("tile_points", "gdt_tile_j0")])
    spilled = {}
    for t in res["tiles"]:
        n = os.path.getsize(job / "tiles" / f"tile_{t['i']}_{t['j']}.raw") // 32
        spilled[(t["i"] - i0, t["j"] - j0)] = n
    assert tiles == spilled, "index.vdb tile counts differ from the spill files"
    # The finer grid: its voxels divide the tiles and sum to their counts.
    V = 1 << p["shift"]
    assert p["span"] % V == 0
    per_tile = {}
    for (vx, vy), n in density.items():
        key = ((vx * V) // p["span"] - i0, (vy * V) // p["span"] - j0)
        per_tile[key] = per_tile.get(key, 0) + n
    assert per_tile == spilled
    assert len(density) == p["voxels"]
    # Transforms in lattice steps: voxel (0, 0) of tile_points is the centre
    # of tile (i0, j0), that of density the centre of density voxel (0, 0).
    T = p["span"]
    assert meta[("tile_points", "xform")] == (T, T * (i0 + 0.5), T * (j0 + 0.5))
    assert meta[("density", "xform")] == (V, V / 2, V / 2)
    assert meta[("tile_points", "gdt_world")] == "lattice"


def test_auto_cell_and_printed_plan(runner, tiler_run, tmp_path):
    """--cell auto: about N^2/4 points per tile; the printed plan matches."""
    rng = np.random.default_rng(3)
    n = 120000
    X = rng.integers(0, 300000, n).astype(np.int32)
    Y = rng.integers(0, 200000, n).astype(np.int32)
    las = tmp_path / "uniform.las"
    write_las(las, X, Y, np.zeros(n, dtype=np.int32))
    job = tmp_path / "job"
    res = run_tiler(runner, tiler_run, job, [las], "--tile", "64", "--keep-spill", "--no-sync")
    p = res["plan"]
    assert p["cell_auto"] == 1 and p["halo_auto"] == 1
    target = 64 * 64 // 4
    counts = sorted(t["raw"] for t in res["tiles"])
    assert 0.6 * target <= counts[(len(counts) - 1) // 2] <= 1.6 * target
    assert (p["min"], p["median"], p["max"]) == (counts[0], counts[(len(counts) - 1) // 2],
                                                 counts[-1])
    assert p["tiles"] == len(counts) and p["empty"] == p["nx"] * p["ny"] - len(counts)
    assert 1 <= p["halo"] <= 32
    text = res["text"]
    assert "tile plan:" in text
    assert re.search(rf"grid\s+: {p['nx']} x {p['ny']} tiles", text)
    assert re.search(rf"tiles\s+: {p['tiles']} with points, {p['empty']} empty", text)
    assert re.search(rf"points/tile\s+: min {p['min']}, median {p['median']}, max {p['max']}",
                     text)
    assert f"texel        : {p['cell']} lattice steps" in text


def test_auto_cell_bounds_the_densest_tile(runner, tiler_run, tmp_path):
    """--cell auto: a patch twice as dense as the rest does not make any tile
    hold more than N^2/4 points; a cluster far denser than that may, since
    the texel shrinks by at most sqrt 2 from the mean-density one."""
    rng = np.random.default_rng(11)
    target = 64 * 64 // 4
    side = 300000
    n = 150000
    X = rng.integers(0, side, n)
    Y = rng.integers(0, side, n)
    # the dense patch: one extra point per background point in a quarter
    patch = (X < side // 2) & (Y < side // 2)
    X = np.concatenate([X, X[patch] + 1])
    Y = np.concatenate([Y, Y[patch]])
    las = tmp_path / "patch.las"
    write_las(las, X.astype(np.int32), Y.astype(np.int32), np.zeros(len(X), dtype=np.int32))
    p = run_tiler(runner, tiler_run, tmp_path / "job", [las], "--tile", "64",
                  "--plan-only")["plan"]
    assert p["cell_auto"] == 1
    assert p["max"] <= target, p
    # the mean-density texel: sqrt(area / points) / 2 (area: the whole square)
    creal = np.sqrt(float(side) * side / len(X)) / 2
    assert creal / np.sqrt(2) - 1 <= p["cell"] < creal, (p["cell"], creal)

    # 90% of the points in a small cluster: the floor holds
    m = 100000
    Xc = np.concatenate([rng.integers(0, side, m // 10), rng.integers(0, 3000, m - m // 10)])
    Yc = np.concatenate([rng.integers(0, side, m // 10), rng.integers(0, 3000, m - m // 10)])
    las2 = tmp_path / "cluster.las"
    write_las(las2, Xc.astype(np.int32), Yc.astype(np.int32), np.zeros(m, dtype=np.int32))
    p2 = run_tiler(runner, tiler_run, tmp_path / "job2", [las2], "--tile", "64",
                   "--plan-only")["plan"]
    assert p2["max"] > target
    # at most about twice the tiles of the texel sqrt 2 coarser
    coarse = int(np.ceil(p2["cell"] * np.sqrt(2)))
    p3 = run_tiler(runner, tiler_run, tmp_path / "job3", [las2], "--tile", "64",
                   "--plan-only", "--cell", f"{coarse * 0.01:.2f}")["plan"]
    assert p3["cell"] == coarse
    assert p2["tiles"] <= 2.5 * p3["tiles"], (p2, p3)


def test_plan_empty_tiles_with_voids(runner, tiler_run, tmp_path):
    """Two clusters far apart: the grid between them is empty tiles."""
    rng = np.random.default_rng(5)
    X = np.concatenate([rng.integers(0, 5000, 3000), rng.integers(200000, 205000, 3000)])
    Y = np.concatenate([rng.integers(0, 5000, 3000), rng.integers(100000, 105000, 3000)])
    las = tmp_path / "two.las"
    write_las(las, X.astype(np.int32), Y.astype(np.int32), np.zeros(6000, dtype=np.int32))
    res = run_tiler(runner, tiler_run, tmp_path / "job", [las], "--tile", "64", "--cell",
                    "0.5", "--plan-only")
    p = res["plan"]
    T = p["span"]
    assert T == 64 * 50
    ti, tj = X // T, Y // T
    occupied = set(zip(ti.tolist(), tj.tolist()))
    assert p["tiles"] == len(occupied)
    assert p["nx"] == ti.max() - ti.min() + 1 and p["ny"] == tj.max() - tj.min() + 1
    assert p["empty"] == p["nx"] * p["ny"] - len(occupied) > 1000


@pytest.mark.sanitize
@pytest.mark.parametrize("args,code", [
    (["--tile", "1024", "--cell", "30000"], "GDT-2502"),       # N c > 2^31 lattice steps
    (["--tile", "1024", "--cell", "20971.52", "--halo", "1"], "GDT-2502"),  # (N + 2H) c > 2^31
    (["--tile", "64", "--mem-budget", "4194304"], "GDT-2504"),
])
def test_refused_options(runner, tiler_run, cloud_las, tmp_path, args, code):
    job = tmp_path / "job"
    os.makedirs(job)
    r = runner([tiler_run, job, *cloud_las, *args])
    assert r.returncode == 2, r.stderr
    assert code in r.stderr


def test_halo_zero_and_wide(runner, tiler_run, cloud_las, tmp_path):
    cloud = read_input(cloud_las)
    for halo in ("0", "150"):  # 150 texels: wider than a tile of 64
        job = tmp_path / f"job{halo}"
        os.makedirs(job / "halo")
        res = run_tiler(runner, tiler_run, job, cloud_las, "--tile", "64", "--cell", "0.6",
                        "--halo", halo, "--keep-spill", "--no-sync", "--dump-halo", job / "halo")
        if halo == "0":
            assert all(t["edge"] == 0 for t in res["tiles"]) and not any(res["halos"].values())
        check_run(res, str(job), cloud, "first")


def test_real_lidar_sample(runner, tiler_run, data_dir, tmp_path):
    las = data_dir / "autzen_trim.las"
    if not las.exists():
        pytest.skip("autzen_trim.las not in the data folder")
    cloud = read_input([las])
    job = tmp_path / "job"
    os.makedirs(job / "halo")
    res = run_tiler(runner, tiler_run, job, [las], "--tile", "64", "--keep-spill", "--no-sync",
                    "--dump-halo", job / "halo")
    assert res["plan"]["points"] == len(cloud) == 110000
    check_run(res, str(job), cloud, "first")
