"""--max-edge and --concavity: the trimmed mesh is the Delaunay mesh less
exactly what the rules drop, applied by brute force (scripts/gdtmesh/trim.py,
a peel by a work list, independent of the union-find of merge/trim.c), for
every tiling, in every mode, on generated, void-rich and real clouds; the
options enter the job; a run killed midway resumes to the same bytes."""
import json
import pathlib
import sys

import numpy as np
import pytest

import resume_util as ru
from tiled_util import (SCALE, assert_equal_meshes, command, gen_cloud, run, shell, validate,
                        write_las)

ROOT = pathlib.Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "scripts"))
from gdtmesh.ply import PlyMesh  # noqa: E402
from gdtmesh.trim import check_trimmed, trimmed_faces  # noqa: E402

TILES = (64, 256, 1024)


def void_cloud(path, n, seed):
    """Uniform points on 60 x 60 m with lakes: some inside, some cut into
    the hull, and a channel, so the peel has to travel from the hull inwards
    through long edges."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(0, 60, 3 * n)
    y = rng.uniform(0, 60, 3 * n)
    keep = np.ones(x.size, bool)
    for cx, cy, r in ((20, 20, 7), (45, 35, 9), (0, 30, 8), (60, 60, 12), (30, 50, 4)):
        keep &= (x - cx) ** 2 + (y - cy) ** 2 > r * r
    keep &= ~((np.abs(y - 8) < 1.5) & (x > 30))  # a channel from the east side
    x, y = x[keep][:n], y[keep][:n]
    z = 100 + 0.2 * x + np.sin(y / 5)
    X = np.round(x / SCALE).astype(np.int64)
    Y = np.round(y / SCALE).astype(np.int64)
    write_las(path, X, Y, np.round(z / SCALE).astype(np.int64))
    return path


@pytest.fixture(scope="module")
def clouds(tmp_path_factory):
    d = tmp_path_factory.mktemp("trim")
    return {
        "lidar": gen_cloud(d / "lidar.las", 30_000, 5),
        "voids": void_cloud(d / "voids.las", 25_000, 2),
    }


def full_mesh(gdt_bin, las, out):
    r = run(command(gdt_bin, las, out, "--reference"))
    assert r.returncode == 0, r.stderr
    return out


@pytest.fixture(scope="module")
def validated_full(gdt_bin, clouds, tmp_path_factory):
    """kind -> the untrimmed mesh of clouds[kind], checked by validate_mesh.py once
    (per test worker) and shared by the rules that trim it."""
    done = {}

    def get(kind):
        if kind not in done:
            full = full_mesh(gdt_bin, clouds[kind], tmp_path_factory.mktemp("full") / "full.ply")
            r = validate(full, clouds[kind])
            assert r.returncode == 0, r.stdout + r.stderr
            done[kind] = full
        return done[kind]
    return get


def trimmed(gdt_bin, las, out, *args):
    js = pathlib.Path(str(out) + ".json")
    cmd = command(gdt_bin, las, out, *args, "--json", js)
    r = run(cmd)
    assert r.returncode == 0, f"{shell(cmd)}\n{r.stderr}"
    return json.loads(js.read_text())


@pytest.mark.parametrize("kind,rules", [
    ("lidar", ("--max-edge", 1.5)),
    ("lidar", ("--concavity", 1.2)),
    ("voids", ("--concavity", 1.0)),
    pytest.param("voids", ("--concavity", 0.6, "--max-edge", 2.0), marks=pytest.mark.sanitize),
])
def test_trim_equals_brute_force_for_every_tiling(gdt_bin, clouds, validated_full, tmp_path,
                                                  kind, rules):
    las = clouds[kind]
    full = validated_full(kind)
    lat = PlyMesh(full).lattice
    me = dict(zip(rules[::2], rules[1::2])).get("--max-edge", 0)
    cc = dict(zip(rules[::2], rules[1::2])).get("--concavity", 0)
    ply = PlyMesh(full)
    pts = list(zip(*[np.rint((ply.vertices[c] - o) / s).astype(np.int64).tolist()
                     for c, s, o in (("x", lat.sx, lat.ox), ("y", lat.sy, lat.oy))]))
    kept, cut, peeled = trimmed_faces(ply.faces["v"], pts, lat.sx, lat.sy, me, cc)
    dropped = ply.nface - len(kept)
    assert dropped > 0 and len(kept) > 0.5 * ply.nface, (dropped, ply.nface)
    for mode in [("--reference",), ("--single-tile", "--tile", 1024)] + \
            [("--tile", t) for t in TILES]:
        out = tmp_path / f"t{'_'.join(map(str, mode))}.ply"
        js = trimmed(gdt_bin, las, out, *mode, *map(str, rules))
        code, line = check_trimmed(out, full)
        assert code == 0, f"{mode}: {line}"
        t = js["trim"]
        assert (t["faces"], t["dropped_max_edge"], t["dropped_concavity"], t["dropped"]) == \
            (ply.nface, cut, peeled, dropped), (mode, t)
        assert js["faces"] == ply.nface - dropped, mode
        assert PlyMesh(out).nvert == ply.nvert, f"{mode}: vertices were dropped"


def test_real_sample_and_validate_script(gdt_bin, data_dir, tmp_path):
    las = data_dir / "autzen_trim.las"
    if not las.exists():
        pytest.skip("autzen_trim.las not in the data folder")
    full = tmp_path / "full.ply"
    r = run(command(gdt_bin, las, full, "--tile", 256))
    assert r.returncode == 0, r.stderr
    outs = []
    for t in (256, 1024):
        out = tmp_path / f"c{t}.ply"
        trimmed(gdt_bin, las, out, "--tile", t, "--concavity", 3, "--max-edge", 10)
        outs.append(out)
    # one tiling checked by the script; the other must hold the same triangles
    assert_equal_meshes(outs[0], outs[1], "trimmed at --tile 256 and 1024")
    r = run([sys.executable, ROOT / "scripts" / "validate_mesh.py", outs[0], "--trimmed-from",
             full])
    assert r.returncode == 0 and r.stdout.startswith("OK:"), r.stdout + r.stderr
    # the check fails on a mesh trimmed by another rule
    r = run([sys.executable, ROOT / "scripts" / "validate_mesh.py", outs[0], "--trimmed-from",
             full, "--concavity", 6])
    assert r.returncode == 1 and r.stdout.startswith("FAIL:"), r.stdout + r.stderr
    # and on the untrimmed mesh passed as the trimmed one
    r = run([sys.executable, ROOT / "scripts" / "validate_mesh.py", full, "--trimmed-from", full,
             "--concavity", 3])
    assert r.returncode == 1, r.stdout + r.stderr


def test_header_comment(gdt_bin, clouds, tmp_path):
    out = tmp_path / "o.ply"
    trimmed(gdt_bin, clouds["lidar"], out, "--tile", 256, "--max-edge", "0.5",
            "--concavity", "2")
    comments = PlyMesh(out).comments
    assert "trim max-edge 0.5 concavity 2" in comments, comments
    out2 = tmp_path / "n.ply"
    trimmed(gdt_bin, clouds["lidar"], out2, "--tile", 256)
    assert not [c for c in PlyMesh(out2).comments if c.startswith("trim")]


@pytest.mark.parametrize("args,code,text", [
    (("--max-edge", "-1"), 2, "--max-edge"),
    (("--concavity", "nan"), 2, "--concavity"),
    (("--concavity", "0"), 2, "--concavity"),
    (("--max-edge", "2", "--check"), 2, "--check"),
    (("--concavity", "2", "--info"), 2, "--concavity"),
])
def test_bad_options(gdt_bin, clouds, tmp_path, args, code, text):
    out = tmp_path / "o.ply"
    r = run(command(gdt_bin, clouds["lidar"], out, *args))
    assert r.returncode == code and text in r.stderr, (r.returncode, r.stderr)
    assert not out.exists()


def test_resume_refuses_trim_options(gdt_bin, tmp_path):
    r = run([gdt_bin, "--resume", tmp_path, "--max-edge", "3"])
    assert r.returncode == 2 and "--resume" in r.stderr, r.stderr


def test_rules_enter_the_job(gdt_bin, clouds, tmp_path):
    las = clouds["voids"]
    out, job = tmp_path / "o.ply", tmp_path / "job"
    base = command(gdt_bin, las, out, "--tile", 256, "--job", job, "--keep-job")
    r = run(base + ["--concavity", "1"])
    assert r.returncode == 0, r.stderr
    first = out.read_bytes()
    r = run(base + ["--concavity", "1.5"])
    assert r.returncode == 6 and "trim" in r.stderr and "--restart" in r.stderr, r.stderr
    assert out.read_bytes() == first
    # the same rule again reuses every tile, with the same bytes
    js = tmp_path / "again.json"
    r = run(base + ["--concavity", "1", "--json", js])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == first
    again = json.loads(js.read_text())
    assert again["reused"]["tiles"] == again["tiles"] and again["redone"]["tiles"] == 0, again
    # --resume takes the rule from the job
    out.unlink()
    r = run([gdt_bin, "--resume", job, "-q"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() == first
    r = run(base + ["--concavity", "1.5", "--restart"])
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() != first


@pytest.mark.parametrize("stage,offset", [("tiles", 0.3),
                                          pytest.param("merge", 0.0, marks=pytest.mark.sanitize)])
def test_killed_run_resumes_to_the_same_bytes(gdt_bin, clouds, tmp_path, stage, offset):
    las = clouds["lidar"]
    rules = ["--concavity", "1.2", "--max-edge", "3"]
    want = tmp_path / "want.ply"
    r = run(command(gdt_bin, las, want, "--tile", 64, *rules))
    assert r.returncode == 0, r.stderr
    out = tmp_path / "o.ply"
    cmd = [gdt_bin, las, "-o", out, "--tile", 64, "--job", tmp_path / "job", *rules]
    assert ru.kill_then_rerun(cmd, out, stage, offset) == want.read_bytes()
