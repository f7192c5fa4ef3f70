"""Point filters (--keep-class, --drop-class, --returns, --keep-withheld) and
the per-class statistics of --info, against laspy.

Fixtures: LAS files written with laspy in point formats 1 and 3 (classes
0-31, the synthetic / key-point / withheld flags) and 6 (classes above 31,
the overlap flag), with known mixes of classes, returns and flags; and the
real sample autzen_trim.las (classes 1: 83,893, 2: 26,107).

The oracle of a filtered run is the same run on the file laspy filtered: the
PLY bodies (vertices and faces) must be byte for byte the same, because the
ordinals count kept points only.  A dropped point is counted once, under
the first test it fails, in the order withheld, class, return.
"""
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

laspy = pytest.importorskip("laspy")

ROOT = pathlib.Path(__file__).resolve().parents[2]
VALIDATE = ROOT / "scripts" / "validate_mesh.py"

# name -> (point format, LAS version, classes to draw from)
FIXTURES = {
    "fmt1": (1, "1.2", [0, 1, 2, 3, 5, 6, 7, 9, 18, 31]),
    "fmt3": (3, "1.2", [1, 2, 2, 2, 4, 6, 7, 11, 17]),
    "fmt6": (6, "1.4", [1, 2, 2, 6, 7, 18, 40, 64, 65, 200, 255]),
}
NPTS = 3000


def make_las(path, name, seed=11):
    """A LAS fixture with a class, return and flag mix; 5% of its points
    repeat the (x, y) of another."""
    fmt, version, classes = FIXTURES[name]
    rng = np.random.default_rng(seed)
    cells = rng.choice(200 * 200, size=NPTS, replace=False)
    hdr = laspy.LasHeader(point_format=fmt, version=version)
    hdr.scales = [0.01, 0.01, 0.01]
    hdr.offsets = [500000.0, 4000000.0, 0.0]
    las = laspy.LasData(hdr)
    X = (cells % 200) * 97 + rng.integers(0, 40, NPTS)
    Y = (cells // 200) * 89 + rng.integers(0, 40, NPTS)
    # 5% share the (x, y) of another point: the --dup rule sees kept ordinals
    src, dst = rng.choice(NPTS, size=(2, NPTS // 20), replace=False)
    X[dst], Y[dst] = X[src], Y[src]
    las.X, las.Y = X, Y
    las.Z = rng.integers(0, 5000, NPTS)
    maxret = 7 if fmt < 6 else 15
    nret = rng.integers(1, 5 if fmt < 6 else 9, NPTS)
    nret[rng.random(NPTS) < 0.02] = 0          # a few records with no return count
    ret = np.array([rng.integers(0, n + 1) if n > 0 else rng.integers(0, 3) for n in nret])
    las.number_of_returns = np.minimum(nret, maxret)
    las.return_number = np.minimum(ret, maxret)
    las.classification = rng.choice(classes, NPTS)
    las.withheld = rng.random(NPTS) < 0.05
    las.synthetic = rng.random(NPTS) < 0.03
    las.key_point = rng.random(NPTS) < 0.02
    if fmt >= 6:
        las.overlap = rng.random(NPTS) < 0.04
    las.write(str(path))
    return path


def attrs(path):
    """The laspy view of a file's attributes, as numpy arrays."""
    las = laspy.read(str(path))
    a = {
        "cls": np.asarray(las.classification, dtype=np.int64),
        "ret": np.asarray(las.return_number, dtype=np.int64),
        "nret": np.asarray(las.number_of_returns, dtype=np.int64),
        "withheld": np.asarray(las.withheld, dtype=bool),
        "synthetic": np.asarray(las.synthetic, dtype=bool),
        "key_point": np.asarray(las.key_point, dtype=bool),
    }
    names = list(las.point_format.dimension_names)
    a["overlap"] = (np.asarray(las.overlap, dtype=bool) if "overlap" in names
                    else np.zeros(len(a["cls"]), dtype=bool))
    return las, a


def oracle(a, keep=None, drop=None, returns="all", keep_withheld=False):
    """(mask of kept records, counts by reason) with gdt-tile's precedence."""
    n = len(a["cls"])
    wh = np.zeros(n, dtype=bool) if keep_withheld else a["withheld"]
    if keep is not None:
        cls_bad = ~np.isin(a["cls"], keep)
    elif drop is not None:
        cls_bad = np.isin(a["cls"], drop)
    else:
        cls_bad = np.zeros(n, dtype=bool)
    ret_bad = {"all": np.zeros(n, dtype=bool), "first": a["ret"] != 1,
               "last": a["ret"] != a["nret"], "single": a["nret"] != 1}[returns]
    d_wh = wh
    d_cls = ~d_wh & cls_bad
    d_ret = ~d_wh & ~cls_bad & ret_bad
    kept = ~(d_wh | d_cls | d_ret)
    return kept, {"points_read": n, "points_kept": int(kept.sum()),
                  "dropped_withheld": int(d_wh.sum()), "dropped_class": int(d_cls.sum()),
                  "dropped_return": int(d_ret.sum())}


def write_subset(src, mask, dst):
    """The records of src where mask holds, same header (scale, offset, CRS)."""
    las = laspy.read(str(src))
    out = laspy.LasData(las.header)
    out.points = las.points[mask]
    out.write(str(dst))
    return dst


def run(cmd, **kw):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True,
                          timeout=600, **kw)


def body(ply):
    data = pathlib.Path(ply).read_bytes()
    return data[data.index(b"end_header\n") + len(b"end_header\n"):]


def header(ply):
    data = pathlib.Path(ply).read_bytes()
    return data[:data.index(b"end_header\n")].decode("ascii").splitlines()


def filter_args(keep=None, drop=None, returns="all", keep_withheld=False):
    args = []
    if keep is not None:
        args += ["--keep-class", ",".join(str(c) for c in keep)]
    if drop is not None:
        args += ["--drop-class", ",".join(str(c) for c in drop)]
    if returns != "all":
        args += ["--returns", returns]
    if keep_withheld:
        args += ["--keep-withheld"]
    return args


MODES = {
    "reference": ["--reference"],
    "tiled": ["--tile", "64"],
}


def mesh(gdt_bin, inputs, out, mode, *extra):
    js = pathlib.Path(str(out) + ".json")
    r = run([gdt_bin, *inputs, *MODES[mode], "-o", out, "--json", js, *extra])
    assert r.returncode == 0, f"{inputs} {mode} {extra}: exit {r.returncode}\n{r.stderr}"
    return json.loads(js.read_text()), r.stderr


# ----------------------------------------------------------------- --info

@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_info_counts_equal_laspy(gdt_bin, tmp_path, name):
    """--info (text and --json): per-class counts with ASPRS names, return
    numbers, numbers of returns and the four flags equal laspy's counts."""
    las_path = make_las(tmp_path / f"{name}.las", name)
    _, a = attrs(las_path)
    js = tmp_path / "info.json"
    r = run([gdt_bin, las_path, "--info", "--json", js])
    assert r.returncode == 0, r.stderr
    inp = json.loads(js.read_text())["inputs"][0]
    assert inp["records"] == NPTS
    got = {c["class"]: c["points"] for c in inp["classes"]}
    want = {int(c): int(n) for c, n in zip(*np.unique(a["cls"], return_counts=True))}
    assert got == want
    assert {c["class"]: c["name"] for c in inp["classes"]}[2] == "ground"
    got = {c["return"]: c["points"] for c in inp["return_numbers"]}
    assert got == {int(c): int(n) for c, n in zip(*np.unique(a["ret"], return_counts=True))}
    got = {c["returns"]: c["points"] for c in inp["numbers_of_returns"]}
    assert got == {int(c): int(n) for c, n in zip(*np.unique(a["nret"], return_counts=True))}
    flags = {k: int(a[k].sum()) for k in ("withheld", "synthetic", "key_point", "overlap")}
    assert inp["flags"] == flags
    assert flags["withheld"] > 0 and (name != "fmt6" or flags["overlap"] > 0)
    # the text: one line per class present, with its name
    for c, n in want.items():
        from_names = {0: "never classified", 1: "unassigned", 2: "ground", 3: "low vegetation",
                      5: "high vegetation", 6: "building", 7: "low point (noise)",
                      9: "water", 18: "high noise", 40: "reserved", 64: "user definable",
                      255: "user definable"}
        line = [x for x in r.stdout.splitlines() if x.split(":")[0].split() == ["class", str(c)]]
        assert len(line) == 1 and line[0].split(":", 1)[1].split()[0] == str(n), r.stdout
        if c in from_names:
            assert line[0].endswith(f"({from_names[c]})"), line
    # the default filter dropped the withheld points, and says so
    _, cnt = oracle(a)
    f = json.loads(js.read_text())["filter"]
    assert {k: f[k] for k in cnt} == cnt
    assert json.loads(js.read_text())["points"] == cnt["points_kept"]


def test_info_of_autzen(gdt_bin, data_dir, tmp_path):
    """The real sample: classes 1 (83,893) and 2 (26,107), named."""
    src = data_dir / "autzen_trim.las"
    _, a = attrs(src)
    js = tmp_path / "info.json"
    r = run([gdt_bin, src, "--info", "--json", js])
    assert r.returncode == 0, r.stderr
    assert "  class 1      : 83893 (unassigned)" in r.stdout.splitlines()
    assert "  class 2      : 26107 (ground)" in r.stdout.splitlines()
    inp = json.loads(js.read_text())["inputs"][0]
    assert [(c["class"], c["name"], c["points"]) for c in inp["classes"]] == \
        [(1, "unassigned", 83893), (2, "ground", 26107)]
    got = {c["return"]: c["points"] for c in inp["return_numbers"]}
    assert got == {int(c): int(n) for c, n in zip(*np.unique(a["ret"], return_counts=True))}
    r = run([gdt_bin, src, "--info", "--keep-class", "2"])
    assert r.returncode == 0, r.stderr
    assert "  kept         : 26107 (110000 read; dropped: 83893 by class, 0 by return, " \
           "0 withheld)" in r.stdout.splitlines()


# The real samples that are point clouds; the others in the folder are
# hostile headers with tests of their own (laspy itself would try to
# allocate what garbage_nVariableLength.las claims).
REAL_SAMPLES = ["100-points.las", "autzen_trim.las", "autzen_trim.laz", "epsg_4326.las",
                "gps-time-nan.las", "test_epsg_4326.las"]
REAL_FILTERS = [["--keep-class", "2"], ["--drop-class", "1,7"], ["--returns", "first"],
                ["--returns", "last"], ["--returns", "single"], ["--keep-withheld"]]


def test_filter_counts_equal_laspy_on_every_real_file(gdt_bin, data_dir, tmp_path):
    """Every real LAS and LAZ sample laspy reads: --info's class counts and
    the counts of each filter equal laspy's."""
    seen = 0
    for name in REAL_SAMPLES:
        src = data_dir / name
        if not src.is_file():
            continue
        js = tmp_path / f"{src.name}.json"
        r = run([gdt_bin, src, "--info", "--json", js])
        assert r.returncode == 0, f"{name}: {r.stderr}"
        _, a = attrs(src)
        seen += 1
        inp = json.loads(js.read_text())["inputs"][0]
        got = {c["class"]: c["points"] for c in inp["classes"]}
        assert got == {int(c): int(n) for c, n in
                       zip(*np.unique(a["cls"], return_counts=True))}, src.name
        for args in REAL_FILTERS:
            opts = {"--keep-class": {"keep": [2]}, "--drop-class": {"drop": [1, 7]},
                    "--returns": {"returns": args[-1]},
                    "--keep-withheld": {"keep_withheld": True}}[args[0]]
            _, cnt = oracle(a, **opts)
            r = run([gdt_bin, src, "--info", "--json", js, *args])
            assert r.returncode == 0, f"{src.name} {args}: {r.stderr}"
            f = json.loads(js.read_text())["filter"]
            assert {k: f[k] for k in cnt} == cnt, f"{src.name} {args}"
    assert seen >= 4, "fewer real samples than expected were readable"


# ------------------------------------------------- filtered mesh == laspy's

@pytest.mark.parametrize("sample", ["autzen_trim.las", "autzen_trim.laz"])
def test_keep_class_2_of_autzen_equals_the_prefiltered_file(gdt_bin, data_dir, tmp_path,
                                                            sample):
    """The everyday call on the real sample, LAS and LAZ: the mesh of
    --keep-class 2 is the mesh of the file laspy filtered to class 2 (a
    LAS file), and it validates against that file."""
    src = data_dir / sample
    _, a = attrs(src)
    mask, cnt = oracle(a, keep=[2])
    pre = write_subset(src, mask, tmp_path / "ground.las")
    s, err = mesh(gdt_bin, [src], tmp_path / "f.ply", "tiled", "--keep-class", "2",
                  "--tile", "256")
    s0, _ = mesh(gdt_bin, [pre], tmp_path / "p.ply", "tiled", "--tile", "256")
    assert body(tmp_path / "f.ply") == body(tmp_path / "p.ply")
    assert s["points_read"] == 26107 == s0["points_read"]
    assert {k: s["filter"][k] for k in cnt} == cnt
    assert "26107 points (110000 read; dropped: 83893 by class, 0 by return, 0 withheld)" in err
    assert "comment filter keep-class 2 returns all withheld drop" in header(tmp_path / "f.ply")
    r = run([sys.executable, VALIDATE, "--input", pre, tmp_path / "f.ply"])
    assert r.returncode == 0, r.stdout + r.stderr


CASES = {
    "default": {},
    "keep-withheld": {"keep_withheld": True},
    "first": {"returns": "first"},
    "last": {"returns": "last"},
    "single": {"returns": "single"},
    "drop-noise": {"drop": [7, 18]},
    "ground-last": {"keep": [2], "returns": "last"},
    "high-classes": {"keep": [2, 40, 64, 65, 66, 67, 200]},
}


@pytest.mark.parametrize("mode", sorted(MODES))
@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("name", sorted(FIXTURES))
def test_filtered_mesh_equals_the_prefiltered_file(gdt_bin, tmp_path, name, case, mode):
    """Each filter, each fixture, in memory and tiled: same PLY body as the
    run on laspy's filtered file, and the counts of --json equal laspy's."""
    spec = CASES[case]
    if case == "high-classes" and name != "fmt6":
        pytest.skip("classes above 31 need point format 6-10")
    src = make_las(tmp_path / f"{name}.las", name)
    _, a = attrs(src)
    mask, cnt = oracle(a, **spec)
    assert 0 < cnt["points_kept"] <= NPTS
    pre = write_subset(src, mask, tmp_path / "pre.las")
    s, err = mesh(gdt_bin, [src], tmp_path / "f.ply", mode, *filter_args(**spec))
    mesh(gdt_bin, [pre], tmp_path / "p.ply", mode, "--keep-withheld")
    assert body(tmp_path / "f.ply") == body(tmp_path / "p.ply")
    assert {k: s["filter"][k] for k in cnt} == cnt
    assert s["filter"]["inputs"][0]["points_kept"] == cnt["points_kept"]
    want = (f"{cnt['points_kept']} points ({NPTS} read; dropped: {cnt['dropped_class']} "
            f"by class, {cnt['dropped_return']} by return, {cnt['dropped_withheld']} withheld)")
    if cnt["points_kept"] == NPTS and set(spec) <= {"keep_withheld"}:
        want = f"{NPTS} points, "  # nothing dropped, nothing to say
    assert want in err, err


def test_counts_per_input_and_total(gdt_bin, tmp_path):
    """Two inputs: counts per input and their sum; ordinals run on across
    the inputs over kept points only (same body as the two filtered files)."""
    a_path = make_las(tmp_path / "a.las", "fmt3", seed=3)
    b_path = make_las(tmp_path / "b.las", "fmt3", seed=4)
    # b beside a, not on top of it
    las = laspy.read(str(b_path))
    las.X = np.asarray(las.X) + 200 * 97 + 1000
    las.write(str(b_path))
    spec = {"keep": [2, 4], "returns": "first"}
    pres, cnts = [], []
    for p in (a_path, b_path):
        _, at = attrs(p)
        mask, cnt = oracle(at, **spec)
        pres.append(write_subset(p, mask, tmp_path / f"pre_{p.name}"))
        cnts.append(cnt)
    s, _ = mesh(gdt_bin, [a_path, b_path], tmp_path / "f.ply", "tiled", *filter_args(**spec))
    mesh(gdt_bin, pres, tmp_path / "p.ply", "tiled")
    assert body(tmp_path / "f.ply") == body(tmp_path / "p.ply")
    for k in cnts[0]:
        assert [i[k] for i in s["filter"]["inputs"]] == [c[k] for c in cnts]
        assert s["filter"][k] == cnts[0][k] + cnts[1][k]


@pytest.mark.parametrize("mode", sorted(MODES))
def test_whole_read_chunks_dropped(gdt_bin, tmp_path, mode):
    """Runs of thousands of dropped records (whole read chunks, at the start,
    inside and at the end of the file): the ordinals and the mesh are still
    those of the filtered file."""
    n = 20000
    rng = np.random.default_rng(8)
    cells = rng.choice(400 * 400, size=n, replace=False)
    hdr = laspy.LasHeader(point_format=1, version="1.2")
    hdr.scales = [0.01, 0.01, 0.01]
    hdr.offsets = [0.0, 0.0, 0.0]
    las = laspy.LasData(hdr)
    las.X = (cells % 400) * 50 + rng.integers(0, 20, n)
    las.Y = (cells // 400) * 50 + rng.integers(0, 20, n)
    las.Z = rng.integers(0, 1000, n)
    cls = np.full(n, 2)
    cls[:9000] = 1          # the first two chunks and more
    cls[12000:17000] = 5
    cls[19000:] = 6
    las.classification = cls
    las.number_of_returns = np.ones(n, dtype=np.uint8)
    las.return_number = np.ones(n, dtype=np.uint8)
    src = tmp_path / "runs.las"
    las.write(str(src))
    _, a = attrs(src)
    mask, cnt = oracle(a, keep=[2])
    pre = write_subset(src, mask, tmp_path / "pre.las")
    s, _ = mesh(gdt_bin, [src], tmp_path / "f.ply", mode, "--keep-class", "2")
    mesh(gdt_bin, [pre], tmp_path / "p.ply", mode)
    assert body(tmp_path / "f.ply") == body(tmp_path / "p.ply")
    assert {k: s["filter"][k] for k in cnt} == cnt and cnt["points_kept"] == 5000


def test_dropped_records_are_not_checked_and_indices_stay_the_files(gdt_bin, tmp_path):
    """A record whose coordinate is outside the lattice range fails the run
    (GDT-3402) with its index in the file, after dropped records too; a
    dropped one is never looked at, as in the filtered file."""
    a = make_las(tmp_path / "a.las", "fmt1")
    hdr = laspy.LasHeader(point_format=1, version="1.2")
    hdr.scales = [54321.125, 54321.125, 0.01]   # no integer multiple of 0.01: snapped
    hdr.offsets = [0.0, 0.0, 0.0]
    las = laspy.LasData(hdr)
    m = 12
    las.X = np.arange(m) * 3
    las.Y = np.arange(m) * 7 % 5
    las.Z = np.arange(m)
    las.X[[2, 7]] = 2_000_000_000  # 1.1e14 CRS units: 1.1e16 steps of 0.01 > 2^53
    cls = np.full(m, 2)
    cls[[1, 2, 3, 4]] = 7
    las.classification = cls
    b = tmp_path / "b.las"
    las.write(str(b))
    out = tmp_path / "x.ply"
    r = run([gdt_bin, a, b, "--reference", "-o", out, "--keep-withheld"])
    assert r.returncode == 3 and "GDT-3402" in r.stderr and f"{b}: point 2:" in r.stderr, \
        r.stderr
    r = run([gdt_bin, a, b, "--reference", "-o", out, "--keep-withheld", "--drop-class", "7"])
    assert r.returncode == 3 and "GDT-3402" in r.stderr and f"{b}: point 7:" in r.stderr, \
        r.stderr
    cls[7] = 7
    las.classification = cls
    las.write(str(b))
    r = run([gdt_bin, a, b, "--reference", "-o", out, "--keep-withheld", "--drop-class", "7"])
    assert r.returncode == 0, r.stderr


def test_single_tile_filters_too(gdt_bin, tmp_path):
    """--single-tile reads through the same filter."""
    src = make_las(tmp_path / "fmt6.las", "fmt6")
    _, a = attrs(src)
    mask, cnt = oracle(a, drop=[7, 18], returns="last")
    pre = write_subset(src, mask, tmp_path / "pre.las")
    for inp, out, extra in ((src, "f.ply", ["--drop-class", "7,18", "--returns", "last"]),
                            (pre, "p.ply", ["--keep-withheld"])):
        js = tmp_path / (out + ".json")
        r = run([gdt_bin, inp, "--single-tile", "--tile", "256", "-o", tmp_path / out,
                 "--json", js, *extra])
        assert r.returncode == 0, r.stderr
    assert body(tmp_path / "f.ply") == body(tmp_path / "p.ply")
    f = json.loads((tmp_path / "f.ply.json").read_text())["filter"]
    assert {k: f[k] for k in cnt} == cnt


def test_single_tile_limit_counts_the_kept_points(gdt_bin, data_dir, tmp_path):
    """--single-tile --tile 256 takes 32,768 points: autzen's 110,000 are
    refused before the reading, its 26,107 ground points are taken, its
    83,893 unassigned ones refused after it."""
    src = data_dir / "autzen_trim.las"
    out = tmp_path / "x.ply"
    r = run([gdt_bin, src, "--single-tile", "--tile", "256", "-o", out])
    assert r.returncode == 2 and "GDT-2102" in r.stderr, r.stderr
    r = run([gdt_bin, src, "--single-tile", "--tile", "256", "-o", out, "--keep-class", "1"])
    assert r.returncode == 2 and "GDT-2109" in r.stderr and "83893 points" in r.stderr, \
        r.stderr
    assert not out.exists()
    r = run([gdt_bin, src, "--single-tile", "--tile", "256", "-o", out, "--keep-class", "2"])
    assert r.returncode == 0, r.stderr
    assert "26107 points (110000 read" in r.stderr


def test_withheld_dropped_by_default_kept_on_request(gdt_bin, tmp_path):
    """No option: the withheld points are gone; --keep-withheld: all kept."""
    src = make_las(tmp_path / "fmt1.las", "fmt1")
    _, a = attrs(src)
    s, err = mesh(gdt_bin, [src], tmp_path / "d.ply", "reference")
    assert s["points"] == NPTS - int(a["withheld"].sum())
    assert s["filter"]["dropped_withheld"] == int(a["withheld"].sum()) > 0
    s, err = mesh(gdt_bin, [src], tmp_path / "k.ply", "reference", "--keep-withheld")
    assert s["points"] == NPTS and s["filter"]["points_kept"] == NPTS
    assert "comment filter classes all returns all withheld keep" in header(tmp_path / "k.ply")


# ------------------------------------------------------------ header, usage

def test_header_comment_is_canonical(gdt_bin, tmp_path):
    """Two spellings of one filter: the same 'comment filter' line, and the
    same file."""
    src = make_las(tmp_path / "fmt3.las", "fmt3")
    mesh(gdt_bin, [src], tmp_path / "a.ply", "reference", "--keep-class", "4,2,3-3,17,11",
         "--keep-class", "6")
    mesh(gdt_bin, [src], tmp_path / "b.ply", "reference", "--keep-class", "2-4,6,11,17")
    want = "comment filter keep-class 2-4,6,11,17 returns all withheld drop"
    assert want in header(tmp_path / "a.ply")
    assert (tmp_path / "a.ply").read_bytes() == (tmp_path / "b.ply").read_bytes()


@pytest.mark.parametrize("args,code", [
    (["--keep-class", ""], "2301"), (["--keep-class", "2,"], "2301"),
    (["--keep-class", "a"], "2301"), (["--keep-class", "5-3"], "2301"),
    (["--keep-class", "-2"], "2301"), (["--drop-class", "2 3"], "2301"),
    (["--keep-class", "256"], "2302"), (["--drop-class", "1-300"], "2302"),
    (["--keep-class", "2", "--drop-class", "7"], "2303"),
    (["--returns", "second"], "2304"), (["--returns", ""], "2304"),
])
def test_bad_filter_options_are_usage_errors(gdt_bin, tmp_path, args, code):
    src = make_las(tmp_path / "fmt1.las", "fmt1")
    r = run([gdt_bin, src, "--reference", "-o", tmp_path / "x.ply", *args])
    assert r.returncode == 2, r.stderr
    assert f"GDT-{code}" in r.stderr, r.stderr
    assert not (tmp_path / "x.ply").exists()


@pytest.mark.parametrize("args", [["--keep-class", "2"], ["--drop-class", "7"],
                                  ["--returns", "first"]])
@pytest.mark.parametrize("mode", [["--reference"], ["--tile", "64"], ["--info"]])
def test_pcd_input_with_class_or_return_filter_is_a_usage_error(gdt_bin, tmp_path, args,
                                                                 mode):
    src = make_las(tmp_path / "a.las", "fmt1")
    pcd = tmp_path / "cloud.pcd"
    pcd.write_text("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\n"
                   "COUNT 1 1 1\nWIDTH 3\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\n"
                   "DATA ascii\n0 0 0\n1 0 0\n0 1 0\n")
    out = [] if mode == ["--info"] else ["-o", tmp_path / "x.ply"]
    r = run([gdt_bin, src, pcd, *mode, *out, *args])
    assert r.returncode == 2, r.stderr
    assert "GDT-2305" in r.stderr and str(pcd) in r.stderr, r.stderr
    assert not (tmp_path / "x.ply").exists()


def test_high_class_with_legacy_format_warns(gdt_bin, tmp_path):
    """Point format 3 stores classes 0-31: naming 40 is worth a warning."""
    src = make_las(tmp_path / "fmt3.las", "fmt3")
    r = run([gdt_bin, src, "--reference", "-o", tmp_path / "x.ply", "--keep-class", "2,40"])
    assert r.returncode == 0, r.stderr
    assert "GDT-3430" in r.stderr and str(src) in r.stderr, r.stderr
    r = run([gdt_bin, src, "--reference", "-o", tmp_path / "y.ply", "--keep-class", "2,31"])
    assert r.returncode == 0 and "GDT-3430" not in r.stderr, r.stderr


@pytest.mark.parametrize("mode", sorted(MODES))
def test_a_filter_that_keeps_nothing_warns(gdt_bin, tmp_path, mode):
    """Nothing kept: an empty mesh, and a warning naming the filter."""
    src = make_las(tmp_path / "fmt3.las", "fmt3")
    s, err = mesh(gdt_bin, [src], tmp_path / "e.ply", mode, "--keep-class", "30")
    assert "GDT-3431" in err and "keep-class 30 returns all" in err, err
    assert err.count("GDT-3431") == 1, err
    assert s["filter"]["points_kept"] == 0 and s["filter"]["points_read"] == NPTS
    s, err = mesh(gdt_bin, [src], tmp_path / "f.ply", mode, "--keep-class", "2")
    assert "GDT-3431" not in err, err


# ------------------------------------------------------------------ jobs

def test_changed_filter_on_a_job_is_exit_6_unless_restart(gdt_bin, tmp_path):
    """The filter is part of the job: another one is exit 6 naming it; the
    same one reuses the job; --resume DIR keeps the recorded filter; with
    --restart the new filter is used."""
    src = make_las(tmp_path / "fmt6.las", "fmt6")
    out, job = tmp_path / "out.ply", tmp_path / "job"
    base = [gdt_bin, src, "--tile", "64", "-o", out, "--job", job, "--keep-job"]
    r = run([*base, "--keep-class", "2,6"])
    assert r.returncode == 0, r.stderr
    first = out.read_bytes()
    for change in (["--keep-class", "2"], ["--keep-class", "2,6", "--returns", "first"],
                   ["--keep-class", "2,6", "--keep-withheld"], ["--drop-class", "2,6"]):
        r = run([*base, *change])
        assert r.returncode == 6, f"{change}: {r.stderr}"
        assert "GDT-6903" in r.stderr and "filter=" in r.stderr, r.stderr
        assert out.read_bytes() == first
    js = tmp_path / "again.json"
    r = run([*base, "--keep-class", "6,2", "--json", js])
    assert r.returncode == 0, r.stderr
    assert json.loads(js.read_text())["reused"]["pass2"] is True
    assert out.read_bytes() == first
    r = run([gdt_bin, "--resume", job])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == first
    r = run([gdt_bin, "--resume", job, "--keep-class", "2"])
    assert r.returncode == 2 and "GDT-2306" in r.stderr, r.stderr
    r = run([*base, "--keep-class", "2", "--restart"])
    assert r.returncode == 0, r.stderr
    assert "comment filter keep-class 2 returns all withheld drop" in header(out)
    assert out.read_bytes() != first
