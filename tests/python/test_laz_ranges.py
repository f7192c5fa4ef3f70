"""A LAZ file read from a chunk on: the records a chunked file can start at
(its chunk table), and a range of records read from there, are those of the
uncompressed LAS file it compresses read over the same range, with one
decoder thread or several; a start inside a chunk is refused."""
import pathlib
import subprocess
import sys

import pytest

from laz_util import write_laz

laspy = pytest.importorskip("laspy")


def gen(root, path, points, seed, *extra):
    r = subprocess.run([sys.executable, root / "scripts" / "gen_cloud.py", path, "--points",
                        str(points), "--seed", str(seed), "-q", *extra],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    return pathlib.Path(path)


def read(runner, tool, path, *args):
    r = runner([tool("src_read"), *args, path])
    return r


def figures(r):
    """(points, checksum) of one src_read line."""
    f = dict(kv.split("=") for kv in r.stdout.split())
    return int(f["points"]), f["checksum"]


@pytest.fixture(scope="module")
def files(root, tmp_path_factory):
    d = tmp_path_factory.mktemp("laz-ranges")
    las = gen(root, d / "a.las", 23000, 31)
    return {"las": las, "laz": write_laz(las, d / "a.laz", chunk=5000),
            "one": write_laz(las, d / "one.laz", chunk=50000)}


def test_starts_are_the_chunk_table(runner, tool, files):
    r = read(runner, tool, files["laz"], "--starts")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.split()
    assert lines[0] == "starts=5"
    assert [int(v) for v in lines[1:]] == [0, 5000, 10000, 15000, 20000]
    # an uncompressed file starts anywhere, a one-chunk LAZ file at 0 only
    assert read(runner, tool, files["las"], "--starts").stdout.split() == ["starts=0"]
    assert read(runner, tool, files["one"], "--starts").stdout.split() == ["starts=1", "0"]


@pytest.mark.parametrize("threads", ["1", "3"])
@pytest.mark.parametrize("first,end", [(0, 5000), (5000, 23000), (10000, 12345),
                                       (20000, 23000), (15000, 15000), (0, 23000)])
def test_a_range_from_a_chunk_is_the_las_range(runner, tool, files, threads, first, end):
    want = read(runner, tool, files["las"], "--range", first, end)
    assert want.returncode == 0, want.stderr
    got = read(runner, tool, files["laz"], "--threads", threads, "--range", first, end)
    assert got.returncode == 0, got.stderr
    assert figures(got) == figures(want) and figures(got)[0] == end - first


def test_a_start_inside_a_chunk_is_refused(runner, tool, files):
    r = read(runner, tool, files["laz"], "--range", 5001, 9000)
    assert r.returncode == 7, r.stdout + r.stderr
    assert "a.laz" in r.stderr and "does not start a LAZ chunk" in r.stderr, r.stderr
    # the first record of a one-chunk file is its only start
    r = read(runner, tool, files["one"], "--range", 0, 777)
    assert r.returncode == 0 and figures(r)[0] == 777, r.stderr
