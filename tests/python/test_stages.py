"""The tile stage over a subset of the tiles (tiler/private/stages.h).

tests/tools/stages_subset runs a tiled run's stages up to the tile stage
over the tiles it is given, and prints each tile the stage reports
finished.  The stage must report exactly those tiles, in order, leave
exactly their .tri files in the job, and record them so that the plain run
of the same command reuses them and writes the same bytes as a run that
computed every tile.  Runs of tiles two apart share the parity of their
index: the stage's two buffers must alternate by position in the set, not
by tile index, or a tile's buffers would be refilled while the previous
tile's post stage still reads them.
"""
import json
import re

import pytest

from tiled_util import gen_cloud, run

ARGS = ["--tile", "64", "--cell", "0.25"]
TRI = re.compile(r"^tile_-?\d+_-?\d+\.tri$")


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    d = tmp_path_factory.mktemp("stages")
    return gen_cloud(d / "c.las", 40_000, 5)


@pytest.fixture(scope="module")
def reference(cloud, gdt_bin, tmp_path_factory):
    d = tmp_path_factory.mktemp("stages_ref")
    out = d / "ref.ply"
    r = run([gdt_bin, cloud, *ARGS, "-o", out, "-q", "--json", d / "ref.json"])
    assert r.returncode == 0, r.stderr
    return out.read_bytes(), json.loads((d / "ref.json").read_text())["tiles"]


@pytest.mark.parametrize("pick", ["even", "spread", "single"])
def test_subset_then_full_run(cloud, reference, gdt_bin, tool, tmp_path, pick):
    ref_bytes, ntiles = reference
    assert ntiles >= 8
    subset = {"even": list(range(0, ntiles, 2)),
              "spread": [0, 1, 3, ntiles // 2, ntiles - 1],
              "single": [ntiles - 2]}[pick]
    out = tmp_path / "m.ply"
    job = tmp_path / "m.ply.gdt-job"
    cmd = [tool("stages_subset"), ",".join(map(str, subset)), cloud, *ARGS, "-o", out, "-q"]
    r = run(cmd)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[:-1] == [f"done {k}" for k in subset]
    assert not out.exists()
    tri = [p for p in (job / "tiles").iterdir() if TRI.match(p.name)]
    assert len(tri) == len(subset)
    # a second run of the same subset reuses every tile and reports each
    r = run(cmd)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split("\n")[:-1] == [f"done {k}" for k in subset]
    # the plain run finishes the job from the recorded tiles
    r = run([gdt_bin, cloud, *ARGS, "-o", out, "-q", "--json", tmp_path / "s.json"])
    assert r.returncode == 0, r.stderr
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["reused"]["tiles"] == len(subset)
    assert s["redone"]["tiles"] == ntiles - len(subset)
    assert s["reused"]["pass2"] is True
    assert out.read_bytes() == ref_bytes


def test_bad_tile_index_fails(cloud, reference, tool, tmp_path):
    _, ntiles = reference
    r = run([tool("stages_subset"), f"0,{ntiles}", cloud, *ARGS, "-o", tmp_path / "m.ply",
             "-q"])
    assert r.returncode != 0
    assert f"tile {ntiles} does not exist" in r.stderr
