"""gdt-tile under mpirun: one tiled job shared by K ranks.

The mesh (and every other output) is byte for byte that of a single process
for any K, a job killed under one K resumes under another, and a failure is
the whole job's exit code with one message.  Run as root in CI, so Open MPI
is told that is allowed; --oversubscribe lets K exceed this machine's cores."""
import json
import os
import signal
import sqlite3
import subprocess
import sys
import time

import pytest

import mpi_util as mu
from laz_util import write_laz


def env():
    e = mu.clean_env(**mu.ROOT_OK)
    # one PoCL thread per rank: K ranks on this machine's few cores
    e["POCL_MAX_PTHREAD_COUNT"] = "1"
    if "ASAN_OPTIONS" in e:
        # the sanitized build: Open MPI's own allocations are not ours to
        # report as leaks, and a failure test's LD_PRELOAD shim comes before
        # the ASan runtime
        e["ASAN_OPTIONS"] += ":detect_leaks=0:verify_asan_link_order=0"
    return e


@pytest.fixture(scope="module")
def mpi_bin(gdt_bin):
    why = mu.why_no_mpi(gdt_bin)
    if why is not None:
        pytest.skip(why)
    return gdt_bin


def gen(root, path, points, seed, *extra):
    r = subprocess.run([sys.executable, root / "scripts" / "gen_cloud.py", path, "--points",
                        str(points), "--seed", str(seed), "-q", *extra],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return path


def run(cmd, timeout=300):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, env=env(),
                          timeout=timeout)


def mpirun(k, gdt, args, timeout=300):
    return run(["mpirun", "--oversubscribe", "-np", str(k), gdt, *args], timeout)


@pytest.fixture(scope="module")
def clouds(root, tmp_path_factory):
    d = tmp_path_factory.mktemp("mpi-clouds")
    a = gen(root, d / "a.las", 30000, 11)
    b = gen(root, d / "b.las", 12000, 12, "--offset", "500340", "4100100")
    laz = write_laz(a, d / "a.laz", chunk=7000)
    # one chunk: pass 1 cannot be cut, so rank 0 reads it alone
    laz1 = write_laz(a, d / "a1.laz", chunk=50000)
    return {"a": a, "b": b, "laz": laz, "laz1": laz1, "dir": d}


CASES = {
    # name: (inputs, options)
    "las-64": (("a",), ("--tile", "64")),
    # binary PLY in parts with --check reading the finished file back
    "las-64-check": (("a",), ("--tile", "64", "--check")),
    "las-256-dem-trim": (("a",), ("--tile", "256", "--dem", "{d}/x.tif", "--dem-res", "2",
                                  "--max-edge", "6")),
    # trimmed meshes written by the tiles' owners: --max-edge beside the
    # merge, --concavity after it (the peel's drops come from rank 0)
    "max-edge-64": (("a",), ("--tile", "64", "--max-edge", "3")),
    "concavity-64": (("a",), ("--tile", "64", "--max-edge", "4", "--concavity", "1.5")),
    "two-inputs-64": (("a", "b"), ("--tile", "64")),
    "laz-128": (("laz",), ("--tile", "128")),
    # the ground filter inside pass 2, each rank classifying its tiles
    "ground-128": (("a",), ("--tile", "128", "--ground", "pmf")),
    # and every input record classified: the ranks' bits ORed by rank 0
    "ground-out-128": (("a",), ("--tile", "128", "--ground", "pmf", "--ground-out",
                                "{d}/g.las")),
    "ground-out-laz-64": (("laz",), ("--tile", "64", "--ground", "pmf", "--ground-out",
                                     "{d}/g.las")),
    # and rank 0 writes them all when pass 1 was not read in shares
    "ground-out-laz1-64": (("laz1",), ("--tile", "64", "--ground", "pmf", "--ground-out",
                                       "{d}/g.las")),
    # every rank of the node takes the node's CPU devices in turn (here: the one)
    "device-local-64": (("b",), ("--tile", "64", "--device", "cpu/local")),
    # text meshes: each rank formats its tiles into fragments, placed once
    # every fragment's length is known (the third field: -o's extension)
    "obj-two-inputs-64": (("a", "b"), ("--tile", "64"), "obj"),
    "xml-concavity-64": (("a",), ("--tile", "64", "--max-edge", "4", "--concavity", "1.5"),
                         "xml"),
    # with a DEM: the owners rasterise their tiles into windows rank 0 takes
    "obj-dem-128": (("a",), ("--tile", "128", "--dem", "{d}/x.tif", "--dem-res", "1.5",
                             "--preview", "{d}/x.png"), "obj"),
}


# also run against the ASan+UBSan build: the mesh in parts (PLY and text),
# the DEM's windows, the peel's drops, LAZ shares
SANITIZED = {"las-256-dem-trim", "obj-two-inputs-64", "concavity-64", "laz-128"}


@pytest.mark.parametrize("case", [pytest.param(c, marks=pytest.mark.sanitize)
                                  if c in SANITIZED else c for c in sorted(CASES)])
def test_any_rank_count_writes_the_same_bytes(mpi_bin, clouds, tmp_path, case):
    names, opts = CASES[case][:2]
    ext = CASES[case][2] if len(CASES[case]) > 2 else "ply"
    inputs = [clouds[n] for n in names]
    outs = {}
    for k in (1, 2, 3, 4):
        d = tmp_path / f"k{k}"
        d.mkdir()
        args = [*inputs, "-o", d / f"o.{ext}", "-q", "--json", d / "run.json",
                *[o.replace("{d}", str(d)) for o in opts]]
        # K = 1: a plain process, no mpirun
        r = run([mpi_bin, *args]) if k == 1 else mpirun(k, mpi_bin, args)
        assert r.returncode == 0, (k, r.stdout + r.stderr)
        assert r.stderr == "", (k, r.stderr)  # -q: nothing, from any rank
        outs[k] = d
        assert not (d / f"o.{ext}.gdt-job").exists()  # the job is removed as in a plain run
        # no fragment of a text mesh or DEM window is left
        assert not list(d.glob("**/*.[vf]tx")) and not list(d.glob("**/*.dwin"))
    ref = (outs[1] / f"o.{ext}").read_bytes()
    for k in (2, 3, 4):
        assert (outs[k] / f"o.{ext}").read_bytes() == ref, k
        if ext == "obj":
            assert (outs[k] / "o.prj").read_bytes() == (outs[1] / "o.prj").read_bytes(), k
        if "--dem" in opts:
            assert (outs[k] / "x.tif").read_bytes() == (outs[1] / "x.tif").read_bytes(), k
        if "--preview" in opts:
            assert (outs[k] / "x.png").read_bytes() == (outs[1] / "x.png").read_bytes(), k
        if "--ground-out" in opts:
            assert (outs[k] / "g.las").read_bytes() == (outs[1] / "g.las").read_bytes(), k
            assert not list(outs[k].glob("**/ground.bits*"))
            # each rank wrote the records of its pass-1 share in place
            jk = json.loads((outs[k] / "run.json").read_text())
            assert jk["mpi"]["ground_out_written_by"] == \
                ("rank 0" if "laz1" in case else "ranks in shares"), k
        j = json.loads((outs[k] / "run.json").read_text())
        j1 = json.loads((outs[1] / "run.json").read_text())
        for key in ("faces", "vertices", "certified_faces", "merge_faces", "gcd_tiles",
                    "insert_tiles", "max_tile_points", "max_halo_points", "certification",
                    "trim"):
            assert j.get(key) == j1.get(key), (k, key)
        assert "mpi" not in j1
        mpi = j["mpi"]
        assert mpi["ranks"] == k and len(mpi["per_rank"]) == k
        assert [q["rank"] for q in mpi["per_rank"]] == list(range(k))
        assert sum(q["tiles"] for q in mpi["per_rank"]) == j["tiles"]
        # the tiles of the last quarter of the vertices are taken on demand
        # by the ranks that run out first (GO dealt the others)
        taken = [q["tiles_on_demand"] for q in mpi["per_rank"]]
        assert all(0 <= t <= q["tiles"] for t, q in zip(taken, mpi["per_rank"])), (k, taken)
        assert sum(taken) > 0, (k, case, taken)
        assert sum(q["vertices"] for q in mpi["per_rank"]) == j["vertices"]
        assert sum(q["certified_faces"] for q in mpi["per_rank"]) == j["certified_faces"]
        # each rank's own parts of the passes lie inside the job's: a share of
        # pass 1 (none for the other ranks when a LAZ of one chunk cannot be
        # cut) and of pass 2 (every rank merges tiles of its own)
        p1 = [q["pass1_s"] for q in mpi["per_rank"]]
        p2 = [q["pass2_s"] for q in mpi["per_rank"]]
        # (1 ms: where a rank's part is the whole pass, two clocks around it)
        assert all(0 < t <= j["times"]["pass2"] + 1e-3 for t in p2), (k, case, p2, j["times"])
        assert all(t <= j["times"]["pass1"] + 1e-3 for t in p1), (k, case, p1, j["times"])
        assert [t > 0 for t in p1] == [r == 0 or names != ("laz1",) for r in range(k)], \
            (k, case, p1)
        assert mpi["load_balance"] >= 1.0
        # every rank that triangulated a tile kept its device busy, and the
        # job's busy time is the ranks' sum
        busy = [q["device_busy_s"] for q in mpi["per_rank"]]
        assert all(q["device_busy_s"] > 0 for q in mpi["per_rank"]
                   if q["tiles"] > q["tiles_reused"]), (k, busy)
        assert abs(sum(busy) - j["times"]["device_busy"]) < 1e-6 * max(1.0, sum(busy)), k
        assert all(0 <= q["device_busy_share"] <= 1.0 for q in mpi["per_rank"]), k
        assert 0 <= j["times"]["device_busy_share"] <= 1.0, k
        # LAZ chunks are decoded once: each rank's pass 2 reads its share of
        # pass 1 back from its replay (rank 0 alone reads a LAZ of one chunk)
        want = [1 if names == ("laz",) or (names == ("laz1",) and q == 0) else 0
                for q in range(k)]
        assert [q["replayed_inputs"] for q in mpi["per_rank"]] == want, (k, case)
        if "--ground" in opts:
            # every tile classified once, by the rank that merged it in pass 2
            assert j["ground"] == j1["ground"] | {"seconds": j["ground"]["seconds"]}, k
            assert sum(q["ground_tiles"] for q in mpi["per_rank"]) == j["tiles"], k
            assert all(q["ground_tiles"] > 0 and q["ground_s"] > 0 for q in mpi["per_rank"]), k
        else:
            assert all("ground_tiles" not in q for q in mpi["per_rank"]), k
        # the mesh is written by the tiles' owners in parts, trimmed or not,
        # PLY or text, and with a DEM they rasterise their tiles for it
        if "--dem" in opts:
            assert mpi["dem_rasterised_by"] == "tile owners", k
        else:
            assert "dem_rasterised_by" not in mpi, k
        if "--max-edge" in opts:
            # the rules drop faces (of the tiles, which the owners write)
            assert j["trim"]["dropped_max_edge"] > 0, k
            assert ("--concavity" not in opts) == (j["trim"]["dropped_concavity"] == 0), k
        assert mpi["mesh_written_by"] == "tile owners", (k, case)
        # the parts' writing is timed: the stage beside the merge, and each rank's share
        assert "parts" in j["times"], (k, case)
        assert j["times"]["parts"] > 0 and all(q["write_s"] > 0 for q in mpi["per_rank"])
        # a PLY's faces are placed as the prefix of done tiles grows, every
        # tile by its owner before PARTS (rank 0's own directly, the others'
        # through FPLACE); a text mesh or --concavity places them all after
        early = [q["tiles_placed_early"] for q in mpi["per_rank"]]
        if ext == "ply" and "--concavity" not in opts:
            assert early == [q["tiles"] for q in mpi["per_rank"]], (k, case, early)
        else:
            assert early == [0] * k, (k, case, early)


def test_dem_windows_written_as_runs(mpi_bin, clouds, tmp_path):
    """A DEM far finer than the points: a rank's window of a tile's cells
    is then written run by run as the faces are rasterised, not held in
    memory (here forced with a small limit); rank 0 reads either kind, and
    the DEM and mesh are a plain run's, trimmed by --max-edge too."""
    opts = ["--tile", "64", "--dem-res", "0.05", "--max-edge", "2", "-q"]
    ref = tmp_path / "ref"
    ref.mkdir()
    r = run([mpi_bin, clouds["a"], "-o", ref / "o.ply", "--dem", ref / "o.tif", *opts])
    assert r.returncode == 0, r.stderr
    for limit in ("1000", "1"):
        d = tmp_path / f"w{limit}"
        d.mkdir()
        r = subprocess.run(["mpirun", "--oversubscribe", "-x", f"GDT_DEM_WINDOW_CELLS={limit}",
                            "-np", "3", str(mpi_bin), str(clouds["a"]), "-o", str(d / "o.ply"),
                            "--dem", str(d / "o.tif"), "--json", str(d / "j.json"), *opts],
                           capture_output=True, text=True, env=env(), timeout=300)
        assert r.returncode == 0, r.stdout + r.stderr
        assert (d / "o.tif").read_bytes() == (ref / "o.tif").read_bytes(), limit
        assert (d / "o.ply").read_bytes() == (ref / "o.ply").read_bytes(), limit
        assert json.loads((d / "j.json").read_text())["mpi"]["dem_rasterised_by"] == \
            "tile owners"


def test_a_rank_that_cannot_save_its_dem_windows_fails_the_job(mpi_bin, clouds, tools_dir,
                                                                 tmp_path):
    """Rank 1 cannot create its DEM windows (an LD_PRELOAD shim fails its
    opens of .dwin files with EIO): the job exits 4 with rank 1's message
    once, leaves neither mesh nor DEM nor temporary, keeps its job, and a
    plain rerun writes the bytes of an undisturbed run."""
    shim = tools_dir / "libgdt_fail_open.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_open.so not built at {shim}")
    out, tif, job, log = (tmp_path / "o.ply", tmp_path / "o.tif", tmp_path / "job",
                          tmp_path / "refused.log")
    args = [str(clouds["a"]), "-o", str(out), "--dem", str(tif), "--tile", "64", "-q",
            "--job", str(job)]
    r = run(["mpirun", "--oversubscribe", "-np", "1", mpi_bin, *args, ":", "-np", "1", "env",
             f"LD_PRELOAD={shim}", "GDT_TEST_FAIL_OPEN_MATCH=.dwin",
             f"GDT_TEST_FAIL_OPEN_LOG={log}", mpi_bin, *args])
    assert log.exists(), r.stdout + r.stderr  # the shim refused an open of rank 1
    assert r.returncode == 4, r.stdout + r.stderr
    assert r.stderr.count("error GDT-4806") == 1 and "rank 1: " in r.stderr, r.stderr
    assert not out.exists() and not tif.exists() and job.is_dir()
    assert [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name] == []
    r = run([mpi_bin, *args])
    assert r.returncode == 0, r.stderr
    ref = tmp_path / "ref"
    ref.mkdir()
    r = run([mpi_bin, clouds["a"], "-o", ref / "o.ply", "--dem", ref / "o.tif", "--tile", "64",
             "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == (ref / "o.ply").read_bytes()
    assert tif.read_bytes() == (ref / "o.tif").read_bytes()


def test_shared_pass2_out_of_core(mpi_bin, root, tmp_path):
    """A budget too small to hold the points: pass 2 spills to .raw files on
    the shared job directory (each rank its share, or rank 0 alone for a
    LAZ input that cannot be cut at chunks), and each tile's owner merges it
    from there."""
    c = gen(root, tmp_path / "c.las", 300000, 8)
    args = ["--tile", "128", "--mem-budget", "16M"]
    ref = tmp_path / "ref.ply"
    r = run([mpi_bin, c, "-o", ref, *args, "-v"])
    assert r.returncode == 0, r.stderr
    assert "bucket levels" in r.stderr, r.stderr  # not in memory
    out = tmp_path / "o.ply"
    r = mpirun(3, mpi_bin, [c, "-o", out, *args, "-v"])
    assert r.returncode == 0, r.stdout + r.stderr
    # every rank spilled its share into .raw files of its own; each owner read
    # its tiles' shares into memory (a tile is far below half the budget;
    # which path a tile takes is checked in test_tiler)
    assert "in shares of 3 ranks (each rank's .raw files)" in r.stderr, r.stderr
    assert out.read_bytes() == ref.read_bytes()
    # one tile of 220000 points, its records and merge table beyond half the
    # budget (but the tile within it): its owner (rank 1) joins the shares'
    # files into the tile's .raw file and merges from there (which path a
    # tile takes is checked in test_tiler)
    c1 = gen(root, tmp_path / "c1.las", 220000, 9)
    one = ["--tile", "4096", "--mem-budget", "16M"]
    ref1 = tmp_path / "ref1.ply"
    r = run([mpi_bin, c1, "-o", ref1, *one, "-q"])
    assert r.returncode == 0, r.stderr
    out1 = tmp_path / "o1.ply"
    r = mpirun(3, mpi_bin, [c1, "-o", out1, *one, "-v"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert "in shares of 3 ranks (each rank's .raw files)" in r.stderr, r.stderr
    assert out1.read_bytes() == ref1.read_bytes()
    # a LAZ input of 6 chunks: each rank decodes whole chunks of its share,
    # in both passes, and spills them into its own files
    laz = write_laz(c, tmp_path / "c.laz", chunk=50000)
    out2 = tmp_path / "o2.ply"
    r = mpirun(2, mpi_bin, [laz, "-o", out2, *args, "-v"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert "in shares of 2 ranks (each rank's .raw files)" in r.stderr, r.stderr
    assert out2.read_bytes() == ref.read_bytes()
    # one chunk cannot be cut: pass 1 stays with rank 0 (it decodes once,
    # for pass 2 too), which spills alone
    one = write_laz(c, tmp_path / "one.laz", chunk=400000)
    out3 = tmp_path / "o3.ply"
    r = mpirun(2, mpi_bin, [one, "-o", out3, *args, "-v"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert "bucket levels" in r.stderr and "in shares" not in r.stderr, r.stderr
    assert out3.read_bytes() == ref.read_bytes()


def vdb_without_uuid(path):
    """index.vdb's bytes but its UUID (36 characters at byte 21, new for
    every file written)."""
    b = path.read_bytes()
    return b[:21] + b[57:]


def write_binary_pcd(las_path, out, nan_every=0):
    """The points of a LAS file as a PCD DATA binary file (x y z, F8), with
    the x of every nan_every-th record NaN (records the reader skips)."""
    import numpy as np
    las = laspy_mod().read(str(las_path))
    xyz = np.stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)], axis=1)
    if nan_every:
        xyz[3::nan_every, 0] = np.nan
    n = len(xyz)
    head = ("VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
            f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA binary\n")
    out.write_bytes(head.encode() + xyz.astype("<f8").tobytes())
    return out


def laspy_mod():
    return pytest.importorskip("laspy")


@pytest.mark.parametrize("case", ["cell-keep-class", "las-and-pcd", "laz-chunks-keep-class",
                                  "pcd-binary-records"])
def test_shared_pass1_plans_what_one_process_plans(mpi_bin, root, clouds, tmp_path, case):
    """Pass 1 read in shares by the ranks (records of a LAS file or a binary
    PCD file, whole chunks of a LAZ file, whole other inputs) gives the index, the plan and
    the filter's counts of one process reading everything, and so the same
    bytes."""
    if case == "cell-keep-class":
        inputs = [clouds["a"], clouds["b"]]
        opts = ["--tile", "64", "--cell", "3", "--keep-class", "2,3,4,5"]
    elif case == "laz-chunks-keep-class":
        inputs = [clouds["laz"], clouds["b"]]  # 30000 points in chunks of 7000, then LAS
        opts = ["--tile", "64", "--keep-class", "2,3,4,5"]
    elif case == "pcd-binary-records":
        # cut inside at records; NaN records skipped, so shares count records
        inputs = [write_binary_pcd(clouds["a"], tmp_path / "a.pcd", nan_every=41), clouds["b"]]
        opts = ["--tile", "64", "--quantum", "0.01"]
    else:
        pcd = tmp_path / "p.pcd"
        r = run([sys.executable, root / "scripts" / "gen_cloud.py", pcd, "--points", "9000",
                 "--seed", "5", "-q", "--offset", "500340", "4100000"])
        assert r.returncode == 0, r.stderr
        inputs = [clouds["a"], pcd, clouds["b"]]
        opts = ["--tile", "128", "--quantum", "0.01"]
    got = {}
    for k in (1, 2, 3):
        d = tmp_path / f"k{k}"
        d.mkdir()
        args = [*inputs, "-o", d / "o.ply", "-v", "--keep-job", "--json", d / "run.json",
                *opts]
        r = run([mpi_bin, *args]) if k == 1 else mpirun(k, mpi_bin, args)
        assert r.returncode == 0, (k, r.stdout + r.stderr)
        notes = [ln for ln in r.stderr.splitlines() if " records, " in ln and " kept " in ln]
        assert len(notes) == len(inputs), r.stderr
        plan = [ln.split(" in ")[0] + ln.split(" s,", 1)[1] for ln in r.stderr.splitlines()
                if "tiler pass 1:" in ln]
        got[k] = (d, notes, plan, json.loads((d / "run.json").read_text()))
    d1, notes1, plan1, j1 = got[1]
    if "keep-class" in case:
        assert j1["filter"]["points_kept"] < j1["filter"]["points_read"]
    for k in (2, 3):
        d, notes, plan, j = got[k]
        assert (d / "o.ply").read_bytes() == (d1 / "o.ply").read_bytes(), k
        assert notes == notes1, k
        assert plan == plan1, k
        for key in ("tiles", "tile", "cell", "halo", "filter", "points_read"):
            assert j[key] == j1[key], (k, key)
        assert (vdb_without_uuid(d / "o.ply.gdt-job" / "index.vdb") ==
                vdb_without_uuid(d1 / "o.ply.gdt-job" / "index.vdb")), k


def test_bad_point_in_another_ranks_share(mpi_bin, root, tmp_path):
    """A point outside the lattice range in the last share of pass 1: rank 2
    reads it, and the job fails with its message, once, and exit 3."""
    laspy = pytest.importorskip("laspy")
    import numpy as np
    fine = gen(root, tmp_path / "fine.las", 20000, 3)
    hdr = laspy.LasHeader(point_format=0, version="1.2")
    hdr.scales = [1e6, 1e6, 0.01]
    hdr.offsets = [0.0, 0.0, 0.0]
    far = laspy.LasData(hdr)
    n = 20000
    xs = np.zeros(n, dtype=np.int32)
    xs[-5] = 2_000_000_000  # 2e15 CRS units: far beyond 2^53 steps of fine.las's lattice
    far.X = xs
    far.Y = np.zeros(n, dtype=np.int32)
    far.Z = np.arange(n, dtype=np.int32)
    far.write(str(tmp_path / "far.las"))
    out = tmp_path / "o.ply"
    r = mpirun(3, mpi_bin, [fine, tmp_path / "far.las", "-o", out, "--tile", "64", "-q"])
    assert r.returncode == 3, r.stdout + r.stderr
    assert r.stderr.count("error GDT-34") == 1, r.stderr
    assert "rank 2" in r.stderr and "far.las" in r.stderr, r.stderr
    assert not out.exists()


def test_bad_input_fails_the_whole_job(mpi_bin, clouds, tmp_path):
    bad = tmp_path / "bad.las"
    data = clouds["a"].read_bytes()
    bad.write_bytes(data[: len(data) // 2])  # records cut off: the header says more
    out = tmp_path / "o.ply"
    r = mpirun(3, mpi_bin, [bad, "-o", out, "--tile", "64", "-q"])
    assert r.returncode == 3, r.stdout + r.stderr
    assert r.stderr.count("error GDT-3") == 1, r.stderr  # said once, by rank 0
    assert str(bad) in r.stderr
    assert not out.exists()


def journal_count(job, query):
    """What a count query of the job's journal gives (0 while there is none)."""
    db = job / "job.db"
    if not db.exists():
        return 0
    try:
        con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=0.2)
        n = con.execute(query).fetchone()[0]
        con.close()
        return n
    except sqlite3.Error:
        return 0


def tiles_recorded(job):
    return journal_count(job, "select count(*) from tile")


def rank_pids(marker):
    """pid -> rank of the gdt-tile processes whose command line holds marker."""
    out = {}
    for p in os.listdir("/proc"):
        if not p.isdigit():
            continue
        try:
            cmd = open(f"/proc/{p}/cmdline", "rb").read().split(b"\0")
            if not cmd or not cmd[0].endswith(b"gdt-tile") or marker.encode() not in cmd:
                continue
            envs = open(f"/proc/{p}/environ", "rb").read().split(b"\0")
        except OSError:
            continue
        for e in envs:
            if e.startswith(b"OMPI_COMM_WORLD_RANK="):
                out[int(p)] = int(e.split(b"=")[1])
    return out


def kill_rank_when(mpi_bin, k, args, out, rank, ready):
    """Runs mpirun -np k gdt-tile args and SIGKILLs the given rank (found by
    the output path out in its command line) as soon as ready() holds; the
    job must then fail."""
    p = subprocess.Popen(["mpirun", "--oversubscribe", "-np", str(k), str(mpi_bin),
                          *[str(a) for a in args]], env=env(), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.time() + 120
        while not ready() and time.time() < deadline and p.poll() is None:
            time.sleep(0.02)
        assert p.poll() is None, "the run ended before it could be killed"
        pids = {r: pid for pid, r in rank_pids(str(out)).items()}
        assert rank in pids, pids
        os.kill(pids[rank], signal.SIGKILL)
        _, err = p.communicate(timeout=120)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode != 0, err


@pytest.mark.parametrize("killed,k_first,k_then", [(1, 3, 2), (0, 2, 1)])
def test_killed_rank_then_rerun_with_another_count(mpi_bin, root, tmp_path, killed, k_first,
                                                   k_then):
    """SIGKILL of one rank (another rank, or rank 0) mid-run: mpirun stops the
    job; a rerun with another number of ranks (or a plain process) reuses the
    recorded tiles and writes the bytes of an uninterrupted run."""
    c = gen(root, tmp_path / "c.las", 1000000, 5)  # a tile stage of seconds
    ref = tmp_path / "ref.ply"
    r = run([mpi_bin, c, "-o", ref, "--tile", "64", "-q"])
    assert r.returncode == 0, r.stderr
    out = tmp_path / "o.ply"
    job = tmp_path / "o.ply.gdt-job"
    args = [c, "-o", out, "--tile", "64", "-q", "--threads", "1"]
    # rank 0 records the others' tiles in batches: kill once some are
    # recorded and at most a third of the tile files exist
    kill_rank_when(mpi_bin, k_first, args, out, killed,
                   lambda: tiles_recorded(job) >= 20 and
                   len(list((job / "tiles").glob("*.tri"))) >= 40)
    assert not out.exists()
    recorded = tiles_recorded(job)
    assert recorded >= 20
    rerun = ([*args, "--json", tmp_path / "j.json"])
    r = run([mpi_bin, *rerun]) if k_then == 1 else mpirun(k_then, mpi_bin, rerun)
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.read_bytes() == ref.read_bytes()
    j = json.loads((tmp_path / "j.json").read_text())
    assert j["reused"]["tiles"] >= recorded, (j["reused"], recorded)


def test_resume_under_mpirun(mpi_bin, root, tmp_path):
    """A plain run interrupted (SIGINT, exit 130) and resumed by
    mpirun -np 2 gdt-tile --resume JOB: the bytes of an uninterrupted run."""
    c = gen(root, tmp_path / "c.las", 300000, 6)
    ref = tmp_path / "ref.ply"
    r = run([mpi_bin, c, "-o", ref, "--tile", "64", "-q"])
    assert r.returncode == 0, r.stderr
    out, job = tmp_path / "o.ply", tmp_path / "job"
    p = subprocess.Popen([str(mpi_bin), str(c), "-o", str(out), "--tile", "64", "-q",
                          "--threads", "1", "--job", str(job)], env=env(),
                         stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while tiles_recorded(job) < 20 and time.time() < deadline and p.poll() is None:
        time.sleep(0.05)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    r = mpirun(2, mpi_bin, ["--resume", job, "-q", "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.read_bytes() == ref.read_bytes()
    j = json.loads((tmp_path / "j.json").read_text())
    assert j["resumed"] and j["reused"]["tiles"] >= 20 and j["mpi"]["ranks"] == 2


def test_another_rank_failing_fails_the_job_with_its_message(mpi_bin, clouds, tmp_path):
    """Rank 1 alone has no OpenCL platform (an MPMD launch gives it another
    environment): the job exits 5, rank 0 prints rank 1's error once, the
    job directory stays, and a plain rerun finishes it."""
    out, job = tmp_path / "o.ply", tmp_path / "job"
    args = [str(clouds["a"]), "-o", str(out), "--tile", "64", "-q", "--job", str(job)]
    r = run(["mpirun", "--oversubscribe", "-np", "1", mpi_bin, *args, ":", "-np", "1", "env",
             "OCL_ICD_VENDORS=/nonexistent", mpi_bin, *args])
    assert r.returncode == 5, r.stdout + r.stderr
    assert r.stderr.count("error GDT-5") == 1 and "rank 1: " in r.stderr, r.stderr
    assert not out.exists() and job.is_dir()
    r = run([mpi_bin, *args])
    assert r.returncode == 0, r.stderr
    ref = tmp_path / "ref.ply"
    r = run([mpi_bin, clouds["a"], "-o", ref, "--tile", "64", "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == ref.read_bytes()


@pytest.mark.sanitize
@pytest.mark.parametrize("ext,after", [("ply", 0), ("ply", 40), ("obj", 0)])
def test_a_failing_part_write_fails_the_job(mpi_bin, clouds, tools_dir, tmp_path, ext, after):
    """Rank 1's positional writes into the mesh's temporary fail as on a full
    disk (an LD_PRELOAD shim, rank 1 only): its first vertex write (after=0)
    or a later one, of its vertices or faces (after=40); for a text mesh,
    the copy of its first fragment into place.  The job exits 4 with rank
    1's message once, nothing is left at the output (no temporary, no .prj
    either), and a plain rerun resumes the job to the bytes of an
    undisturbed run."""
    shim = tools_dir / "libgdt_fail_write.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_write.so not built at {shim}")
    out, job, log = tmp_path / f"o.{ext}", tmp_path / "job", tmp_path / "refused.log"
    args = [str(clouds["a"]), "-o", str(out), "--tile", "64", "-q", "--job", str(job)]
    r = run(["mpirun", "--oversubscribe", "-np", "1", mpi_bin, *args, ":", "-np", "1", "env",
             f"LD_PRELOAD={shim}", f"GDT_TEST_FAIL_WRITE_MATCH=o.{ext}.tmp-",
             f"GDT_TEST_FAIL_WRITE_AFTER={after}", f"GDT_TEST_FAIL_WRITE_LOG={log}", mpi_bin,
             *args])
    assert log.exists(), r.stdout + r.stderr  # the shim refused a write of rank 1
    assert r.returncode == 4, r.stdout + r.stderr
    assert r.stderr.count("error GDT-4") == 1 and "rank 1: " in r.stderr, r.stderr
    assert "No space left on device" in r.stderr, r.stderr
    assert not out.exists() and job.is_dir() and not (tmp_path / "o.prj").exists()
    assert [p.name for p in tmp_path.iterdir() if ".tmp-" in p.name] == []
    r = run([mpi_bin, *args, "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stderr
    assert json.loads((tmp_path / "j.json").read_text())["reused"]["tiles"] > 0
    ref = tmp_path / f"ref.{ext}"
    r = run([mpi_bin, clouds["a"], "-o", ref, "--tile", "64", "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == ref.read_bytes()


@pytest.mark.sanitize
def test_a_rank_whose_tile_files_cannot_be_synced_fails_the_job(mpi_bin, clouds, tools_dir,
                                                                 tmp_path):
    """Each rank makes the pass-2 files of its tiles durable (one sync)
    before it reports them to rank 0, which records pass 2 only with every
    report: when rank 1's sync fails (an LD_PRELOAD shim on rank 1 only),
    the job exits 4 with rank 1's message, and a rerun redoes pass 2 to the
    bytes of a plain run."""
    shim = tools_dir / "libgdt_fail_write.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_write.so not built at {shim}")
    out, job, log = tmp_path / "o.ply", tmp_path / "job", tmp_path / "refused.log"
    args = [str(clouds["a"]), "-o", str(out), "--tile", "64", "-q", "--job", str(job)]
    r = run(["mpirun", "--oversubscribe", "-np", "1", mpi_bin, *args, ":", "-np", "1", "env",
             f"LD_PRELOAD={shim}", f"GDT_TEST_FAIL_SYNCFS_MATCH={job / 'tiles'}",
             f"GDT_TEST_FAIL_WRITE_LOG={log}", mpi_bin, *args])
    assert log.exists(), r.stdout + r.stderr  # the shim refused rank 1's sync
    assert r.returncode == 4, r.stdout + r.stderr
    assert "rank 1: " in r.stderr and "cannot sync the files of" in r.stderr, r.stderr
    assert not out.exists() and job.is_dir()
    r = mpirun(2, mpi_bin, [*args, "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert json.loads((tmp_path / "j.json").read_text())["reused"]["pass2"] is False
    ref = tmp_path / "ref.ply"
    r = run([mpi_bin, clouds["a"], "-o", ref, "--tile", "64", "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == ref.read_bytes()


def ground_recorded(job):
    """The ground subsets the journal records (.gpts files)."""
    return journal_count(job, "select count(*) from pfile where kind = 5")


@pytest.fixture(scope="module")
def ground_ref(mpi_bin, root, tmp_path_factory):
    """A cloud whose ground filter takes seconds at --tile 128, and its plain
    run's mesh and --ground-out file."""
    d = tmp_path_factory.mktemp("mpi-ground")
    c = gen(root, d / "c.las", 300000, 5)
    r = run([mpi_bin, c, "-o", d / "ref.ply", "--tile", "128", "--ground", "pmf",
             "--ground-out", d / "ref.las", "-q"])
    assert r.returncode == 0, r.stderr
    return {"cloud": c, "ply": d / "ref.ply", "las": d / "ref.las"}


def test_killed_in_the_ground_filter_then_rerun(mpi_bin, ground_ref, tmp_path):
    """SIGKILL of rank 1 while the ranks classify: rank 0 has recorded the
    subsets it heard of (its own and rank 1's, one by one); a rerun under
    three ranks takes them again (each rank verifies the files of its
    tiles) and writes the mesh and the classified records of a plain run."""
    out, job, las = tmp_path / "o.ply", tmp_path / "job", tmp_path / "g.las"
    args = [ground_ref["cloud"], "-o", out, "--tile", "128", "--ground", "pmf", "--ground-out",
            las, "-q", "--threads", "1", "--job", job]
    kill_rank_when(mpi_bin, 2, args, out, 1, lambda: ground_recorded(job) >= 30)
    assert not out.exists() and not las.exists()
    recorded = ground_recorded(job)
    assert 30 <= recorded < 144, recorded  # killed inside the filter
    r = mpirun(3, mpi_bin, [*args, "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.read_bytes() == ground_ref["ply"].read_bytes()
    assert las.read_bytes() == ground_ref["las"].read_bytes()
    j = json.loads((tmp_path / "j.json").read_text())
    g = j["ground"]
    assert g["classified"] and g["tiles_reused"] >= recorded, (g, recorded)
    assert j["mpi"]["ground_out_written_by"] == "ranks in shares"


@pytest.mark.parametrize("match,after", [("ground.bits.1", 5), ("g.las.tmp", 2)])
def test_a_rank_failing_in_the_ground_stages_fails_the_job(mpi_bin, ground_ref, tools_dir,
                                                           tmp_path, match, after):
    """Rank 1 cannot write (a full disk, through the LD_PRELOAD shim on rank
    1 only) its --ground-out bits in the ground filter, or its share of the
    classified records after the mesh: the job exits 4 with rank 1's
    message once, no classified file and no temporary are left (and no mesh
    when the filter failed), and a plain rerun finishes the job with the
    bytes of an undisturbed run."""
    shim = tools_dir / "libgdt_fail_write.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_write.so not built at {shim}")
    out, job, las = tmp_path / "o.ply", tmp_path / "job", tmp_path / "g.las"
    log = tmp_path / "refused.log"
    args = [str(a) for a in (ground_ref["cloud"], "-o", out, "--tile", "128", "--ground", "pmf",
                             "--ground-out", las, "-q", "--job", job)]
    r = run(["mpirun", "--oversubscribe", "-np", "1", mpi_bin, *args, ":", "-np", "1", "env",
             f"LD_PRELOAD={shim}", f"GDT_TEST_FAIL_WRITE_MATCH={match}",
             f"GDT_TEST_FAIL_WRITE_AFTER={after}", f"GDT_TEST_FAIL_WRITE_LOG={log}", mpi_bin,
             *args])
    assert log.exists(), r.stdout + r.stderr
    assert r.returncode == 4, r.stdout + r.stderr
    assert r.stderr.count("error GDT-4") == 1 and "rank 1: " in r.stderr, r.stderr
    assert "No space left on device" in r.stderr and match in r.stderr, r.stderr
    assert not las.exists() and job.is_dir()
    assert out.exists() == (match == "g.las.tmp")  # the mesh comes first
    assert [p.name for p in tmp_path.iterdir() if ".tmp" in p.name] == []
    r = run([mpi_bin, *args])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == ground_ref["ply"].read_bytes()
    assert las.read_bytes() == ground_ref["las"].read_bytes()
    assert not list(job.parent.glob("**/ground.bits*"))


def test_ground_out_of_a_job_resumed_after_pass_2(mpi_bin, ground_ref, tmp_path):
    """A plain run stopped after its ground filter (SIGINT) and resumed under
    two ranks: pass 2 and the classes are the journal's, pass 1 is read
    again in shares (which gives each rank its ordinals), and the ranks
    write the classified records: the bytes of a plain run."""
    out, job, las = tmp_path / "o.ply", tmp_path / "job", tmp_path / "g.las"
    p = subprocess.Popen([str(a) for a in (mpi_bin, ground_ref["cloud"], "-o", out, "--tile",
                                           "128", "--ground", "pmf", "--ground-out", las, "-q",
                                           "--threads", "1", "--job", job)],
                         env=env(), stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    # as soon as pass 2 (with the classes) is recorded: the tile stage follows
    while journal_count(job, "select count(*) from stage where name = 'pass2' and done = 1") \
            == 0 and time.time() < deadline and p.poll() is None:
        time.sleep(0.01)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    r = mpirun(2, mpi_bin, ["--resume", job, "-q", "--json", tmp_path / "j.json"])
    assert r.returncode == 0, r.stdout + r.stderr
    assert out.read_bytes() == ground_ref["ply"].read_bytes()
    assert las.read_bytes() == ground_ref["las"].read_bytes()
    j = json.loads((tmp_path / "j.json").read_text())
    assert j["reused"]["pass2"] and not j["ground"]["classified"], (j["reused"], j["ground"])
    assert j["mpi"]["ground_out_written_by"] == "ranks in shares"
