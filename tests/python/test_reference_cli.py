"""gdt-tile --reference end to end: every real LAS/PCD sample and generated
clouds give a mesh that the exact validator accepts against its input, the
--dup policies keep the promised z, and the output bytes are deterministic."""
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from ply_util import read_ply

ROOT = pathlib.Path(__file__).resolve().parents[2]
VALIDATE = ROOT / "scripts" / "validate_mesh.py"
GEN = ROOT / "scripts" / "gen_cloud.py"

# Readable samples of ../shared/data (the broken ones are covered by the
# reader tests).  Geographic samples are projected by gdt-tile; the validator
# refuses to re-project, so for those only the mesh itself is validated.
REAL = ["autzen_trim.las", "100-points.las", "gps-time-nan.las", "bad_vlr_count.las",
        "autzen-utm.pcd", "epsg_4326.las", "test_epsg_4326.las"]
GEOGRAPHIC = {"epsg_4326.las", "test_epsg_4326.las"}


def validate(mesh, cloud=None):
    cmd = [sys.executable, str(VALIDATE), str(mesh)]
    if cloud is not None:
        cmd += ["--input", str(cloud)]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("name", REAL)
def test_reference_of_real_samples_validates(gdt_bin, runner, data_dir, tmp_path, name):
    src = data_dir / name
    out = tmp_path / "mesh.ply"
    js = tmp_path / "run.json"
    r = runner([gdt_bin, src, "--reference", "--check", "-q", "-o", out, "--json", js])
    assert r.returncode == 0, r.stderr
    v = validate(out, None if name in GEOGRAPHIC else src)
    assert v.returncode == 0, v.stdout + v.stderr
    summary = json.loads(js.read_text())
    header, verts, faces = read_ply(out)
    assert summary["vertices"] == len(verts) and summary["faces"] == len(faces)
    assert summary["vertices"] + summary["duplicates_merged"] == summary["points"]
    if name in GEOGRAPHIC:
        assert "comment crs EPSG:326" in header  # projected to a UTM north zone


@pytest.mark.parametrize("kind", ["lidar", "grid", "dem", "uniform", "mixed"])
def test_reference_of_generated_clouds_validates(gdt_bin, runner, tmp_path, kind):
    cloud = tmp_path / f"{kind}.las"
    g = runner([sys.executable, GEN, cloud, "--points", "30000", "--seed", "7", "--kind", kind])
    assert g.returncode == 0, g.stderr
    out = tmp_path / "mesh.ply"
    r = runner([gdt_bin, cloud, "--reference", "--check", "-q", "-o", out])
    assert r.returncode == 0, r.stderr
    v = validate(out, cloud)
    assert v.returncode == 0, v.stdout + v.stderr


def test_reference_output_is_deterministic(gdt_bin, runner, tmp_path):
    cloud = tmp_path / "c.las"
    assert runner([sys.executable, GEN, cloud, "--points", "20000", "--seed", "3"]).returncode == 0
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    assert runner([gdt_bin, cloud, "--reference", "-q", "-o", a]).returncode == 0
    assert runner([gdt_bin, cloud, "--reference", "-q", "-o", b]).returncode == 0
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize("policy", ["first", "min-z", "max-z"])
def test_dup_policy_keeps_the_promised_z(gdt_bin, runner, tmp_path, policy):
    laspy = pytest.importorskip("laspy")
    # A 10 x 10 grid; every (x, y) appears three times with different z.
    xs, ys = np.meshgrid(np.arange(10), np.arange(10))
    X = np.tile(xs.ravel(), 3) * 100
    Y = np.tile(ys.ravel(), 3) * 100
    rng = np.random.default_rng(5)
    Z = rng.integers(0, 10000, size=X.size)
    hdr = laspy.LasHeader(point_format=0, version="1.2")
    hdr.scales = [0.01, 0.01, 0.01]
    hdr.offsets = [1000.0, 2000.0, 0.0]
    las = laspy.LasData(hdr)
    las.X, las.Y, las.Z = X, Y, Z
    cloud = tmp_path / "dups.las"
    las.write(cloud)
    out = tmp_path / "mesh.ply"
    r = runner([gdt_bin, cloud, "--reference", "-q", "--dup", policy, "-o", out])
    assert r.returncode == 0, r.stderr
    _, verts, faces = read_ply(out)
    assert len(verts) == 100 and len(faces) == 2 * 100 - 36 - 2
    z = Z.reshape(3, 100) * 0.01
    want = {"first": z[0], "min-z": z.min(axis=0), "max-z": z.max(axis=0)}[policy]
    # vertices come in order of first occurrence: the grid order
    assert np.array_equal(verts[:, 2], want)
    assert np.array_equal(verts[:, 0], 1000.0 + X[:100] * 0.01)
