"""The streaming PLY writer, read back by two independent readers.

tests/tools/ply_write streams a seeded mesh (extreme doubles included)
through the writer and prints every value it wrote.  The file must read back
identically with plyfile and with the minimal numpy reader below, carry the
exact header (generator, CRS, lattice, extra comments, fixed-width counts),
and be exactly header + 24 V + 13 F bytes long.  Failures of every kind must
leave nothing at the final path and no temporary file.
"""
import os
import pathlib
import re
import shutil
import subprocess

import numpy as np
import pytest
from plyfile import PlyData

ROOT = pathlib.Path(__file__).resolve().parents[2]
COUNT_WIDTH = 20


@pytest.fixture(scope="module")
def ply_write(tool):
    return tool("ply_write")


@pytest.fixture(scope="module")
def version():
    m = re.search(r"project\(gdt_tile\s+VERSION\s+([0-9.]+)", (ROOT / "CMakeLists.txt").read_text())
    assert m, "project version not found in CMakeLists.txt"
    return m.group(1)


def write(runner, tool, out, *args):
    return runner([tool, *args, out])


def parse_printed(stdout):
    """The values ply_write reports: (xyz float64 (V, 3), tri int64 (F, 3))."""
    tok = stdout.split()
    nv, nf = int(tok[0]), int(tok[1])
    assert len(tok) == 2 + 3 * nv + 3 * nf, "tool output is incomplete"
    xyz = np.array([float(t) for t in tok[2:2 + 3 * nv]], dtype=np.float64).reshape(nv, 3)
    tri = np.array(tok[2 + 3 * nv:], dtype=np.int64).reshape(nf, 3)
    return xyz, tri


def read_numpy(path):
    """Minimal PLY reader for exactly the layout gdt-tile writes."""
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    lines = data[:end].decode("ascii").split("\n")[:-1]
    assert lines[0] == "ply"
    assert lines[1] == "format binary_little_endian 1.0"
    counts = {}
    props = {}
    current = None
    for ln in lines[2:-1]:
        word, _, rest = ln.partition(" ")
        if word == "element":
            name, count = rest.split()
            counts[name] = int(count)
            props[name] = []
            current = name
        elif word == "property":
            props[current].append(rest)
        else:
            assert word == "comment", ln
    assert list(counts) == ["vertex", "face"]
    assert props["vertex"] == ["double x", "double y", "double z"]
    assert props["face"] == ["list uchar int vertex_indices"]
    nv, nf = counts["vertex"], counts["face"]
    assert len(data) == end + 24 * nv + 13 * nf, "file size is not header + 24 V + 13 F"
    xyz = np.frombuffer(data, dtype="<f8", count=3 * nv, offset=end).reshape(nv, 3)
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    faces = np.frombuffer(data, dtype=fdt, count=nf, offset=end + 24 * nv)
    assert (faces["n"] == 3).all()
    return {"lines": lines, "header_len": end, "xyz": xyz, "tri": faces["i"].astype(np.int64)}


def read_plyfile(path, nface_hint=None):
    if nface_hint is None:
        ply = PlyData.read(str(path))
        faces = ply["face"]["vertex_indices"]
        tri = np.array([list(f) for f in faces], dtype=np.int64).reshape(len(faces), 3)
    else:
        ply = PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3}})
        tri = np.asarray(ply["face"]["vertex_indices"], dtype=np.int64).reshape(-1, 3)
    v = ply["vertex"]
    xyz = np.stack([v["x"], v["y"], v["z"]], axis=1).astype(np.float64).reshape(-1, 3)
    assert ply.byte_order == "<"
    return ply, xyz, tri


def same_bits(a, b):
    a = np.ascontiguousarray(a, dtype=np.float64)
    b = np.ascontiguousarray(b, dtype=np.float64)
    return a.shape == b.shape and np.array_equal(a.view(np.uint64), b.view(np.uint64))


def wkt_line(wkt):
    """What the writer must make of a WKT: one printable ASCII line."""
    out = []
    for b in wkt.encode("utf-8"):
        if b >= 0x80:
            out.append("?")
        elif b < 0x20 or b == 0x7F:
            out.append(" ")
        else:
            out.append(chr(b))
    return "".join(out)


def leftovers(folder, name):
    return sorted(p.name for p in pathlib.Path(folder).iterdir() if p.name.startswith(name))


CRS_CASES = {
    "epsg": (["--epsg", "2056"], "EPSG:2056"),
    "wkt": (["--wkt", 'PROJCS["CH1903+ / LV95",\r\n  GEOGCS["Bern\u00e9"],\tUNIT["metre",1]]'],
            None),
    "unknown": ([], "unknown"),
}


@pytest.mark.sanitize
@pytest.mark.parametrize("crs", sorted(CRS_CASES))
def test_values_and_header_round_trip(runner, ply_write, version, tmp_path, crs):
    crs_args, crs_text = CRS_CASES[crs]
    if crs_text is None:
        crs_text = wkt_line(crs_args[1])
    lattice = [0.1 + 0.2, 1.0 / 3.0, -2600000.123456789, 5e-324]
    comments = ["tile 4096 halo 12", "input a b.las\tsecond field", "x=1 (unit m)"]
    out = tmp_path / "mesh.ply"
    args = ["--vertices", "2000", "--faces", "3001", "--seed", "11", "--chunk", "333",
            "--lattice", *[repr(v) for v in lattice], *crs_args]
    for c in comments:
        args += ["--comment", c]
    r = write(runner, ply_write, out, *args)
    assert r.returncode == 0, r.stderr
    xyz, tri = parse_printed(r.stdout)
    assert xyz.shape == (2000, 3) and tri.shape == (3001, 3)
    # the generator mixes in extreme values: check they are really there
    flat = xyz.ravel()
    assert np.isin(np.finfo(np.float64).max, flat) and np.isin(-np.finfo(np.float64).max, flat)
    assert (np.signbit(flat) & (flat == 0)).any(), "no -0.0 in the sample"
    assert ((flat != 0) & (np.abs(flat) < np.finfo(np.float64).tiny)).any(), "no subnormal"

    mine = read_numpy(out)
    assert same_bits(mine["xyz"], xyz)
    assert np.array_equal(mine["tri"], tri)
    ply, pxyz, ptri = read_plyfile(out)
    assert same_bits(pxyz, xyz)
    assert np.array_equal(ptri, tri)
    assert ply["vertex"].count == 2000 and ply["face"].count == 3001

    expected_comments = [f"generator gdt-tile {version}", f"crs {crs_text}",
                         "lattice " + " ".join(mine["lines"][4].split()[2:]), *comments]
    assert ply.comments == expected_comments
    lines = mine["lines"]
    assert lines[:4] == ["ply", "format binary_little_endian 1.0",
                         f"comment generator gdt-tile {version}", f"comment crs {crs_text}"]
    lat = lines[4].split()
    assert lat[:2] == ["comment", "lattice"] and len(lat) == 6
    got = [float(t) for t in lat[2:]]
    assert [v.hex() for v in got] == [v.hex() for v in lattice], "lattice does not round-trip"
    assert lines[5:8] == [f"comment {c}" for c in comments]
    assert lines[8:] == ["element vertex " + "2000".ljust(COUNT_WIDTH), "property double x",
                         "property double y", "property double z",
                         "element face " + "3001".ljust(COUNT_WIDTH),
                         "property list uchar int vertex_indices", "end_header"]
    assert leftovers(tmp_path, "mesh.ply") == ["mesh.ply"]


@pytest.mark.sanitize
def test_header_length_does_not_depend_on_counts(runner, ply_write, tmp_path):
    sizes = {}
    for nv, nf in [(0, 0), (3, 1), (12345, 54321), (100, 0)]:
        out = tmp_path / f"m{nv}_{nf}.ply"
        r = write(runner, ply_write, out, "--vertices", nv, "--faces", nf, "--quiet",
                  "--epsg", "32632", "--comment", "fixed")
        assert r.returncode == 0, r.stderr
        mine = read_numpy(out)
        assert mine["xyz"].shape == (nv, 3) and mine["tri"].shape == (nf, 3)
        assert f"element vertex {str(nv).ljust(COUNT_WIDTH)}" in mine["lines"]
        assert f"element face {str(nf).ljust(COUNT_WIDTH)}" in mine["lines"]
        sizes[(nv, nf)] = mine["header_len"]
        assert out.stat().st_size == mine["header_len"] + 24 * nv + 13 * nf
    assert len(set(sizes.values())) == 1, sizes


@pytest.mark.sanitize
@pytest.mark.parametrize("nv", [0, 5])
def test_zero_faces(runner, ply_write, tmp_path, nv):
    out = tmp_path / "empty.ply"
    r = write(runner, ply_write, out, "--vertices", nv)
    assert r.returncode == 0, r.stderr
    xyz, tri = parse_printed(r.stdout)
    mine = read_numpy(out)
    assert same_bits(mine["xyz"], xyz) and mine["tri"].shape == (0, 3)
    ply = PlyData.read(str(out))
    assert ply["vertex"].count == nv and ply["face"].count == 0
    assert out.stat().st_size == mine["header_len"] + 24 * nv


def test_million_faces_streamed(runner, ply_write, tmp_path):
    out = tmp_path / "big.ply"
    r = write(runner, ply_write, out, "--vertices", "50000", "--faces", "1000000",
              "--seed", "3", "--chunk", "4093")
    assert r.returncode == 0, r.stderr
    xyz, tri = parse_printed(r.stdout)
    mine = read_numpy(out)
    assert same_bits(mine["xyz"], xyz)
    assert np.array_equal(mine["tri"], tri)
    ply, pxyz, ptri = read_plyfile(out, nface_hint=3)
    assert same_bits(pxyz, xyz)
    assert np.array_equal(ptri, tri)
    assert out.stat().st_size == mine["header_len"] + 24 * 50000 + 13 * 1000000


def test_memory_does_not_grow_with_mesh_size(runner, ply_write, tmp_path):
    """4e6 faces are 52 MB on disk; a writer holding them would show it."""
    rss = {}
    for nf in (200000, 4000000):
        out = tmp_path / f"rss{nf}.ply"
        r = write(runner, ply_write, out, "--vertices", "1000", "--faces", nf, "--quiet",
                  "--rss")
        assert r.returncode == 0, r.stderr
        m = re.search(r"maxrss_kib (\d+)", r.stderr)
        assert m, r.stderr
        rss[nf] = int(m.group(1))
        assert out.stat().st_size == read_numpy(out)["header_len"] + 24 * 1000 + 13 * nf
        out.unlink()
    assert rss[4000000] - rss[200000] < 8 * 1024, rss


def assert_nothing_left(folder, name):
    assert leftovers(folder, name) == [], f"left behind: {leftovers(folder, name)}"


@pytest.mark.sanitize
def test_missing_directory(runner, ply_write, tmp_path):
    out = tmp_path / "no" / "such" / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "10", "--faces", "3")
    assert r.returncode == 4
    assert "GDT-4701" in r.stderr and str(out) in r.stderr
    assert "No such file or directory" in r.stderr
    assert not (tmp_path / "no").exists()


@pytest.mark.sanitize
def test_write_error_removes_temporary_and_keeps_old_file(runner, ply_write, tmp_path):
    out = tmp_path / "out.ply"
    out.write_bytes(b"previous complete file")
    r = write(runner, ply_write, out, "--vertices", "100000", "--faces", "10", "--quiet",
              "--fsize-limit", "300000")
    assert r.returncode == 4, r.stderr
    assert "GDT-4702" in r.stderr and str(out) in r.stderr and "File too large" in r.stderr
    assert out.read_bytes() == b"previous complete file"
    assert leftovers(tmp_path, "out.ply") == ["out.ply"]


@pytest.mark.sanitize
def test_failed_rename_removes_temporary(runner, ply_write, tmp_path):
    """A directory appears at the final path while the mesh is written: the
    writer checks the path again before the rename and refuses to replace
    anything but a regular file."""
    out = tmp_path / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "100", "--faces", "50", "--quiet",
              "--block-final")
    assert r.returncode == 4, r.stderr
    assert "GDT-4010" in r.stderr and "is a directory" in r.stderr
    assert out.is_dir() and not any(out.iterdir())
    assert leftovers(tmp_path, "out.ply") == ["out.ply"]


@pytest.mark.sanitize
@pytest.mark.parametrize("mode,code", [("--bad-index", "GDT-7705"),
                                       ("--vertex-after-face", "GDT-7704")])
def test_misuse_leaves_nothing(runner, ply_write, tmp_path, mode, code):
    out = tmp_path / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "100", "--faces", "5000", "--quiet", mode)
    assert r.returncode == 7, r.stderr
    assert code in r.stderr and str(out) in r.stderr
    assert "finish succeeded" not in r.stderr
    assert_nothing_left(tmp_path, "out.ply")


@pytest.mark.sanitize
@pytest.mark.parametrize("comment", ["two\nlines", "carriage\rreturn"])
def test_comment_with_line_break_refused(runner, ply_write, tmp_path, comment):
    out = tmp_path / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "10", "--comment", comment)
    assert r.returncode == 7
    assert "GDT-7702" in r.stderr and "line break" in r.stderr
    assert_nothing_left(tmp_path, "out.ply")


@pytest.mark.sanitize
def test_abort_leaves_nothing(runner, ply_write, tmp_path):
    out = tmp_path / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "300000", "--faces", "10", "--quiet",
              "--abort-after-vertices")
    assert r.returncode == 0, r.stderr
    assert_nothing_left(tmp_path, "out.ply")


@pytest.mark.sanitize
def test_crash_never_leaves_a_file_at_the_final_path(runner, ply_write, tmp_path):
    out = tmp_path / "out.ply"
    r = write(runner, ply_write, out, "--vertices", "300000", "--faces", "10", "--quiet",
              "--kill-after-vertices")
    assert r.returncode == -9
    assert not out.exists()
    left = leftovers(tmp_path, "out.ply")
    assert len(left) == 1 and re.fullmatch(r"out\.ply\.tmp-\d+", left[0]), left


def run_in_private_mount(runner, tmp_path, setup, tool_cmd):
    """Runs tool_cmd with tmp_path/mnt replaced by a private mount (setup is
    the shell code that mounts it); returns (result, listing after the run),
    or skips when mount namespaces are not available."""
    if shutil.which("unshare") is None:
        pytest.skip("unshare not available")
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    script = (f"set -u; {setup} || exit 99; echo MOUNTED; "
              '"$@"; rc=$?; echo LISTING; ls -A "$MNT"; cat "$MNT/out.ply" 2>/dev/null; '
              "exit $rc")
    r = runner(["unshare", "-m", "sh", "-c", script, "sh", *tool_cmd],
               env={**os.environ, "MNT": str(mnt)})
    if "MOUNTED" not in r.stdout:
        pytest.skip(f"cannot mount in a private namespace: {r.stderr.strip()}")
    return r, r.stdout.split("LISTING\n", 1)[1]


@pytest.mark.sanitize
def test_disk_full_leaves_old_file_and_no_temporary(runner, ply_write, tmp_path):
    out = tmp_path / "mnt" / "out.ply"
    setup = ('mount -t tmpfs -o size=256k tmpfs "$MNT" && '
             'printf "previous complete file" > "$MNT/out.ply"')
    r, listing = run_in_private_mount(
        runner, tmp_path, setup,
        [ply_write, "--vertices", "100000", "--faces", "1000", "--quiet", out])
    assert r.returncode == 4, r.stderr
    assert "GDT-4702" in r.stderr and "No space left on device" in r.stderr
    assert str(out) in r.stderr
    assert listing == "out.ply\nprevious complete file"


@pytest.mark.sanitize
def test_read_only_directory(runner, ply_write, tmp_path):
    out = tmp_path / "mnt" / "out.ply"
    setup = 'mount --bind "$MNT" "$MNT" && mount -o remount,bind,ro "$MNT"'
    r, listing = run_in_private_mount(runner, tmp_path, setup,
                                      [ply_write, "--vertices", "10", "--quiet", out])
    assert r.returncode == 4, r.stderr
    assert "GDT-4701" in r.stderr and "Read-only file system" in r.stderr
    assert listing == ""
    assert_nothing_left(tmp_path / "mnt", "out.ply")
