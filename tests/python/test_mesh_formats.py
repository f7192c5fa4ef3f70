"""TIN output formats picked by the extension of -o: Wavefront OBJ (with its
.prj) and LandXML 1.2, against the PLY of the same run as the oracle, read by
independent parsers (trimesh for OBJ, lxml for LandXML, pyproj for the WKT);
every mode writes them, a resumed job writes the format it recorded, and a
refused output path leaves nothing behind."""
import json
import os
import pathlib
import sys

import laspy
import numpy as np
import pyproj
import pytest
import trimesh
from lxml import etree
from ply_util import read_ply_triangles as read_ply

ROOT = pathlib.Path(__file__).resolve().parents[2]
GEN = ROOT / "scripts" / "gen_cloud.py"
NS = "http://www.landxml.org/schema/LandXML-1.2"


def read_obj(path):
    m = trimesh.load(str(path), process=False, force="mesh")
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def read_landxml(path):
    doc = etree.parse(str(path))
    root = doc.getroot()
    pts = root.findall(f".//{{{NS}}}Pnts/{{{NS}}}P")
    ids = [int(p.get("id")) for p in pts]
    assert ids == list(range(1, len(pts) + 1))
    neh = np.array([[float(t) for t in p.text.split()] for p in pts], dtype=np.float64)
    neh = neh.reshape(len(pts), 3)
    faces = root.findall(f".//{{{NS}}}Faces/{{{NS}}}F")
    f = np.array([[int(t) for t in e.text.split()] for e in faces], dtype=np.int64)
    return root, neh, f.reshape(len(faces), 3)


def triangles(verts, faces):
    """The mesh as a set of triangles of coordinates, each rotated to start at
    its smallest vertex (orientation kept), independent of vertex order."""
    out = set()
    for t in faces:
        c = [tuple(verts[i]) for i in t]
        k = c.index(min(c))
        out.add(tuple(c[k:] + c[:k]))
    return out


def gen(runner, path, points=20000, seed=5, *extra):
    r = runner([sys.executable, GEN, path, "--points", str(points), "--seed", str(seed), "-q",
                *extra])
    assert r.returncode == 0, r.stderr
    return path


def temporaries(folder):
    return sorted(p.name for p in pathlib.Path(folder).rglob("*") if ".tmp-" in p.name)


@pytest.fixture(scope="module")
def cloud(tmp_path_factory, runner):
    return gen(runner, tmp_path_factory.mktemp("cloud") / "c.las")


@pytest.mark.parametrize("tile", [64, 128])
def test_obj_of_tiled_run_equals_its_ply(gdt_bin, runner, cloud, tmp_path, tile):
    ply, obj = tmp_path / "m.ply", tmp_path / "m.obj"
    for out in (ply, obj):
        r = runner([gdt_bin, cloud, "--tile", tile, "-q", "-o", out])
        assert r.returncode == 0, r.stderr
    header, pv, pf = read_ply(ply)
    ov, of = read_obj(obj)
    assert len(pf) > 1000
    assert ov.shape == pv.shape and np.array_equal(ov, pv)  # every double exactly
    assert np.array_equal(of, pf)
    text = obj.read_text()
    assert text.startswith("# gdt-tile ")
    assert "# crs EPSG:26910\n" in text
    lattice = [l for l in header.splitlines() if l.startswith("comment lattice ")][0]
    assert "# lattice " + lattice.split("comment lattice ")[1] + "\n" in text
    # the .prj beside it: WKT of the input's EPSG code (GeoKeys only)
    prj = tmp_path / "m.prj"
    crs = pyproj.CRS.from_wkt(prj.read_text())
    assert crs == pyproj.CRS.from_epsg(26910)
    assert temporaries(tmp_path) == []


def test_prj_holds_the_inputs_wkt(gdt_bin, runner, tmp_path):
    cloud = gen(runner, tmp_path / "w.las", 5000, 2, "--crs", "wkt", "--las-version", "1.4",
                "--point-format", "6")
    wkt = [v for v in laspy.read(cloud).header.vlrs if v.record_id == 2112][0].string
    out = tmp_path / "w.obj"
    r = runner([gdt_bin, cloud, "--tile", 64, "-q", "-o", out])
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "w.prj").read_text() == wkt.rstrip("\0") + "\n"


def test_prj_of_projected_geographic_input(gdt_bin, runner, data_dir, tmp_path):
    src = data_dir / "epsg_4326.las"
    if not src.exists():
        pytest.skip(f"{src} not found")
    out = tmp_path / "g.obj"
    r = runner([gdt_bin, src, "--reference", "-q", "-o", out])
    assert r.returncode == 0, r.stderr
    code = int(out.read_text().split("# crs EPSG:")[1].split()[0])
    assert 32601 <= code <= 32660
    assert pyproj.CRS.from_wkt((tmp_path / "g.prj").read_text()) == pyproj.CRS.from_epsg(code)


def test_no_prj_without_a_crs_warns_and_removes_a_stale_one(gdt_bin, runner, tmp_path):
    cloud = gen(runner, tmp_path / "n.las", 3000, 4, "--epsg", "0")
    out, prj = tmp_path / "n.obj", tmp_path / "n.prj"
    prj.write_text("PROJCS[\"of an earlier output\"]\n")
    r = runner([gdt_bin, cloud, "--tile", 64, "-o", out])
    assert r.returncode == 0, r.stderr
    assert out.exists() and not prj.exists()
    assert "# crs unknown\n" in out.read_text()


@pytest.mark.parametrize("tile", [64, 128])
def test_landxml_of_tiled_run_equals_its_ply(gdt_bin, runner, cloud, tmp_path, tile):
    ply, xml = tmp_path / "m.ply", tmp_path / "m.xml"
    for out in (ply, xml):
        r = runner([gdt_bin, cloud, "--tile", tile, "-q", "-o", out])
        assert r.returncode == 0, r.stderr
    _, pv, pf = read_ply(ply)
    root, neh, f = read_landxml(xml)
    assert root.tag == f"{{{NS}}}LandXML" and root.get("version") == "1.2"
    assert root.get("date") and root.get("time")
    assert root.find(f"{{{NS}}}Units/{{{NS}}}Metric").get("linearUnit") == "meter"
    cs = root.find(f"{{{NS}}}CoordinateSystem")
    assert cs.get("epsgCode") == "26910"
    assert pyproj.CRS.from_wkt(cs.get("ogcWktCode")) == pyproj.CRS.from_epsg(26910)
    surf = root.find(f"{{{NS}}}Surfaces/{{{NS}}}Surface")
    assert surf.get("name") == "m"
    assert surf.find(f"{{{NS}}}Definition").get("surfType") == "TIN"
    assert np.array_equal(neh, pv[:, [1, 0, 2]])  # northing easting elevation
    assert np.array_equal(f - 1, pf)
    assert not (tmp_path / "m.prj").exists()


@pytest.mark.parametrize("ext", ["obj", "xml"])
def test_in_memory_modes_write_the_same_mesh(gdt_bin, runner, cloud, tmp_path, ext):
    tiled, ref, single = (tmp_path / f"{n}.{ext}" for n in ("t", "r", "s"))
    for out, mode in ((tiled, ["--tile", "128"]), (ref, ["--reference"]),
                      (single, ["--tile", "256", "--single-tile"])):
        r = runner([gdt_bin, cloud, *mode, "-q", "-o", out])
        assert r.returncode == 0, r.stderr
    # the two in-memory modes share their writer: the same bytes (but the name)
    a = ref.read_text().replace('name="r"', "N")
    b = single.read_text().replace('name="s"', "N")
    assert a == b
    load = read_obj if ext == "obj" else (lambda p: (lambda r: (r[1][:, [1, 0, 2]], r[2] - 1))(
        read_landxml(p)))
    tv, tf = load(tiled)
    rv, rf = load(ref)
    assert len(tv) == len(rv) and len(tf) == len(rf)
    assert triangles(tv, tf) == triangles(rv, rf)
    if ext == "obj":
        assert (tmp_path / "t.prj").read_bytes() == (tmp_path / "r.prj").read_bytes()
        # the same header comments in every mode
        head = lambda p: [l for l in p.read_text().splitlines() if l.startswith("# ")][:4]
        assert head(tiled) == head(ref)


def test_extension_is_case_insensitive(gdt_bin, runner, cloud, tmp_path):
    for name, start in (("A.OBJ", b"# gdt-tile "), ("b.Xml", b"<?xml "), ("c.stl", b"ply\n"),
                        ("d.ply", b"ply\n")):
        out = tmp_path / name
        r = runner([gdt_bin, cloud, "--reference", "-q", "-o", out])
        assert r.returncode == 0, r.stderr
        assert out.read_bytes().startswith(start), name
    assert (tmp_path / "A.prj").exists()


@pytest.mark.parametrize("ext", ["obj", "xml"])
def test_check_of_a_text_output(gdt_bin, runner, cloud, tmp_path, ext):
    out, job, js = tmp_path / f"m.{ext}", tmp_path / "job", tmp_path / "run.json"
    r = runner([gdt_bin, cloud, "--tile", 64, "--check", "--keep-job", "--job", job, "-o", out,
                "--json", js])
    assert r.returncode == 0, r.stderr
    assert "checked exactly" in r.stderr
    summary = json.loads(js.read_text())
    assert summary["checked"] is True
    assert summary["output_format"] == {"obj": "OBJ", "xml": "LandXML"}[ext]
    assert not (job / "check.ply").exists()  # the PLY copy goes after the check
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("ext", ["obj", "xml"])
def test_resume_writes_the_recorded_format(gdt_bin, runner, cloud, tmp_path, ext):
    out, job = tmp_path / f"m.{ext}", tmp_path / "job"
    r = runner([gdt_bin, cloud, "--tile", 64, "-q", "--keep-job", "--job", job, "-o", out])
    assert r.returncode == 0, r.stderr
    first = out.read_bytes()
    prj = tmp_path / "m.prj"
    first_prj = prj.read_bytes() if ext == "obj" else None
    out.unlink()
    if prj.exists():
        prj.unlink()
    r = runner([gdt_bin, "--resume", job, "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == first
    if ext == "obj":
        assert prj.read_bytes() == first_prj
    else:
        assert not prj.exists()


def _nothing_written(folder, out, keep=()):
    names = sorted(p.name for p in pathlib.Path(folder).iterdir())
    assert not out.exists() or out.name in keep
    assert temporaries(folder) == [], names
    assert not any(n.endswith(".gdt-job") for n in names), names


def test_output_in_missing_directory_is_refused(gdt_bin, runner, cloud, tmp_path):
    out = tmp_path / "nowhere" / "m.obj"
    r = runner([gdt_bin, cloud, "--tile", 64, "-o", out])
    assert r.returncode == 2 and "GDT-2206" in r.stderr, r.stderr
    _nothing_written(tmp_path, out)


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write into any directory")
def test_output_in_unwritable_directory_is_refused(gdt_bin, runner, cloud, tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o555)
    try:
        r = runner([gdt_bin, cloud, "--tile", 64, "-o", d / "m.xml"])
        assert r.returncode == 2 and "GDT-2207" in r.stderr, r.stderr
        assert list(d.iterdir()) == []
    finally:
        d.chmod(0o755)


@pytest.mark.parametrize("mode", [["--tile", "64"], ["--reference"]])
def test_output_that_is_an_input_is_refused(gdt_bin, runner, cloud, tmp_path, mode):
    src = tmp_path / "in.obj"
    os.link(cloud, src)  # the same file under an .obj name
    before = src.read_bytes()
    r = runner([gdt_bin, src, *mode, "-o", src])
    assert r.returncode == 2 and "GDT-2202" in r.stderr, r.stderr
    assert src.read_bytes() == before
    assert temporaries(tmp_path) == []


@pytest.mark.parametrize("mode", [["--tile", "64"], ["--reference"]])
def test_prj_that_is_an_input_is_refused(gdt_bin, runner, cloud, tmp_path, mode):
    src = tmp_path / "m.prj"
    os.link(cloud, src)
    before = src.read_bytes()
    out = tmp_path / "m.obj"
    r = runner([gdt_bin, src, *mode, "-o", out])
    assert r.returncode == 2 and "GDT-2202" in r.stderr and "m.prj" in r.stderr, r.stderr
    assert src.read_bytes() == before
    _nothing_written(tmp_path, out)


@pytest.mark.parametrize("mode", [["--tile", "64"], ["--reference"], ["--single-tile"]])
def test_prj_that_is_a_directory_is_refused(gdt_bin, runner, cloud, tmp_path, mode):
    (tmp_path / "m.prj").mkdir()
    out = tmp_path / "m.obj"
    extra = ["--tile", "256"] if mode == ["--single-tile"] else []
    r = runner([gdt_bin, cloud, *mode, *extra, "-o", out])
    assert r.returncode == 2 and "GDT-2204" in r.stderr, r.stderr
    assert (tmp_path / "m.prj").is_dir()
    _nothing_written(tmp_path, out)


def test_resume_checks_the_recorded_prj_path(gdt_bin, runner, cloud, tmp_path):
    out, job = tmp_path / "m.obj", tmp_path / "job"
    r = runner([gdt_bin, cloud, "--tile", 64, "-q", "--keep-job", "--job", job, "-o", out])
    assert r.returncode == 0, r.stderr
    out.unlink()
    (tmp_path / "m.prj").unlink()
    (tmp_path / "m.prj").mkdir()
    r = runner([gdt_bin, "--resume", job])
    assert r.returncode == 2 and "GDT-2204" in r.stderr, r.stderr
    assert not out.exists() and temporaries(tmp_path) == []


def test_help_names_the_formats(gdt_bin, runner):
    r = runner([gdt_bin, "--help"])
    assert r.returncode == 0
    assert ".obj" in r.stdout and ".xml" in r.stdout and "LandXML" in r.stdout


def _limit_file_size(limit):
    def pre():
        import resource
        import signal
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # write() fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, resource.RLIM_INFINITY))
    return pre


@pytest.fixture(scope="module")
def big_cloud(tmp_path_factory, runner):
    # its text meshes exceed 16 MiB; the job's files and the OpenCL kernel
    # cache stay far below
    return gen(runner, tmp_path_factory.mktemp("big") / "b.las", 300000, 9)


@pytest.mark.parametrize("ext", ["obj", "xml"])
@pytest.mark.parametrize("mode", [["--reference"], ["--tile", "128"]])
def test_write_failure_leaves_the_earlier_output(gdt_bin, runner, big_cloud, tmp_path, ext,
                                                 mode):
    """A write that fails half-way (the file size limit: EFBIG, as on a full
    disk) exits 4 and leaves the files of an earlier run as they were: no
    half-written mesh, no new .prj beside the old mesh, no temporaries."""
    out, prj, job = tmp_path / f"m.{ext}", tmp_path / "m.prj", tmp_path / "job"
    jobargs = [] if mode == ["--reference"] else ["--job", job]
    out.write_bytes(b"earlier mesh\n")
    prj.write_bytes(b"earlier prj\n")
    r = runner([gdt_bin, big_cloud, *mode, "-q", *jobargs, "-o", out],
               preexec_fn=_limit_file_size(16 << 20))
    assert r.returncode == 4 and "GDT-4712" in r.stderr, r.stderr
    assert out.read_bytes() == b"earlier mesh\n"
    assert prj.read_bytes() == b"earlier prj\n"
    assert temporaries(tmp_path) == []
    if jobargs:  # the job stays: the same command completes it
        r = runner([gdt_bin, big_cloud, *mode, "-q", *jobargs, "-o", out])
        assert r.returncode == 0, r.stderr
        assert out.read_bytes().startswith(b"# gdt-tile " if ext == "obj" else b"<?xml ")
        assert (ext == "obj") == (prj.read_bytes() != b"earlier prj\n")
        assert temporaries(tmp_path) == []


def _dead_pid():
    pid = 4000000
    while True:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return pid
        except PermissionError:
            pass
        pid -= 1


def test_tiled_run_removes_temporaries_of_killed_writers(gdt_bin, runner, cloud, tmp_path):
    """A killed run leaves its "<name>.tmp-<pid>" files; the next tiled run
    removes those of dead processes, the .prj's included, and leaves a live
    process's alone."""
    out = tmp_path / "m.obj"
    dead, live = _dead_pid(), os.getpid()
    stale = [tmp_path / f"m.obj.tmp-{dead}", tmp_path / f"m.prj.tmp-{dead}"]
    kept = tmp_path / f"m.prj.tmp-{live}"
    for p in stale + [kept]:
        p.write_bytes(b"half-written\n")
    r = runner([gdt_bin, cloud, "--tile", 64, "-q", "-o", out])
    assert r.returncode == 0, r.stderr
    assert not any(p.exists() for p in stale)
    assert kept.exists()
    assert out.exists() and (tmp_path / "m.prj").exists()


@pytest.mark.parametrize("mode", [["--tile", "64"], ["--tile", "256", "--threads", "1"],
                                  ["--reference"]])
def test_trimmed_text_outputs_hold_the_plys_faces(gdt_bin, runner, cloud, tmp_path, mode):
    """--concavity and --max-edge: the OBJ and the LandXML hold exactly the trimmed PLY's
    vertices and faces (the same triangles, in the same order), fewer than untrimmed."""
    rules = ["--concavity", "0.9", "--max-edge", "1.2"]
    full = tmp_path / "full.ply"
    r = runner([gdt_bin, cloud, *mode, "-q", "-o", full])
    assert r.returncode == 0, r.stderr
    outs = {}
    for ext in ("ply", "obj", "xml"):
        outs[ext] = tmp_path / f"m.{ext}"
        r = runner([gdt_bin, cloud, *mode, *rules, "-q", "-o", outs[ext]])
        assert r.returncode == 0, r.stderr
    _, fv, ff = read_ply(full)
    _, pv, pf = read_ply(outs["ply"])
    assert 1000 < len(pf) < len(ff)
    assert triangles(pv, pf) < triangles(fv, ff)  # trimming only removes triangles
    ov, of = read_obj(outs["obj"])
    assert np.array_equal(ov, pv) and np.array_equal(of, pf)
    _, neh, xf = read_landxml(outs["xml"])
    assert np.array_equal(neh, pv[:, [1, 0, 2]]) and np.array_equal(xf - 1, pf)
    assert triangles(ov, of) == triangles(neh[:, [1, 0, 2]], xf - 1) == triangles(pv, pf)
