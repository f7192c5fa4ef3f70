"""Host threads do not change the result: the tiled pipeline's certification
splits each tile's triangles over --threads K workers, and the PLY bytes,
the certification counters and the merge must not depend on K.

Tiles of --tile 256 hold tens of thousands of triangles, so K = 2, 3 and 7
really split them (a worker gets at least 4096 triangles)."""
import filecmp
import json

import pytest

import tiled_util as tu


@pytest.fixture(scope="module")
def cloud(tmp_path_factory):
    d = tmp_path_factory.mktemp("threads")
    return tu.gen_cloud(d / "lidar.las", 120000, 17, "lidar")


def run_k(gdt_bin, cloud, out, k):
    s, _ = tu.run_tiled(gdt_bin, cloud, out, "--tile", "256", "--threads", str(k))
    return s


@pytest.mark.sanitize
def test_certification_independent_of_threads(gdt_bin, cloud, tmp_path):
    outs, sums = {}, {}
    for k in (1, 2, 3, 7):
        outs[k] = tmp_path / f"t{k}.ply"
        sums[k] = run_k(gdt_bin, cloud, outs[k], k)
    assert sums[1]["tiles"] >= 4, sums[1]["tiles"]
    # a tile large enough to be split (several workers of >= 4096 triangles)
    assert sums[1]["certification"]["triangles"] / sums[1]["tiles"] > 3 * 4096
    for k in (2, 3, 7):
        assert filecmp.cmp(outs[1], outs[k], shallow=False), f"--threads {k} changed the PLY"
        for key in ("certified_faces", "merge_faces", "seam_vertices", "barrier_edges"):
            assert sums[k][key] == sums[1][key], (k, key)
        assert sums[k]["certification"] == sums[1]["certification"], k
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / "ref.ply")
    tu.assert_equal_meshes(outs[7], ref, "--threads 7 vs the reference")


@pytest.mark.sanitize
def test_more_threads_than_merge_workers(gdt_bin, cloud, tmp_path):
    """--threads 40 on dozens of tiles: the --dup merge (in memory here, the
    budget holds the cloud) runs at most its 16 workers; the PLY is the same
    bytes as with one thread."""
    outs = {}
    for k in (1, 40):
        outs[k] = tmp_path / f"m{k}.ply"
        s, _ = tu.run_tiled(gdt_bin, cloud, outs[k], "--tile", "64", "--threads", str(k))
        assert s["tiles"] > 40, s["tiles"]
    assert filecmp.cmp(outs[1], outs[40], shallow=False), "--threads 40 changed the PLY"
