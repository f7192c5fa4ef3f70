"""Adversarial layouts and lattices: the tiled run stays exact and within a
small factor of the reference triangulator's time, and valid inputs are
never refused as I/O errors.

Layouts (each compared with --reference as a triangle set, compare_meshes.py):
  - a strip two lattice columns wide: every point is a hull point of its
    tile and of the cloud, so every point is a seam vertex and the merge's
    band keeps all of them (it used to be triangulated again for every row);
  - a thin diagonal strip, and a jittered strip five columns wide, whose
    west and east lattice lines hold many hull points;
  - a --cell below one lattice step (refused: usage) and a --cell that makes
    far more tiles than the points need (a warning naming the options).
The time bound is 10 x the reference's time plus 3 s for the tiled run's
start-up (the OpenCL core, the job directory), each the best of two runs
and a run's time the smaller of its wall and CPU times (see timed); with
the merge triangulating the whole band for every row these took about
twice that bound (9 to 11 s against 0.2 to 0.3 s), now 2 to 2.5 s.

Lattices: a lon/lat LAS of scale 1e-7 without a CRS record, LAS scales of
1e-9 and 1e-12 (the index's transform is in lattice steps, so OpenVDB's
smallest voxel does not apply), a scale whose records overflow to infinity
(bad input, with the reason), and clouds wider than 2^31 - 1 lattice steps
(refused before the tile stage with the limit and advice that works for the
lattice's kind, which is followed once to check it).
"""
import json
import re
import resource
import sys
import time

import numpy as np
import pytest

import tiled_util as tu

sys.path.insert(0, str(tu.SCRIPTS))
from gdtmesh.cloudio import write_pcd  # noqa: E402
from lasgen.las import Batch, LasWriter  # noqa: E402

FACTOR, SLACK = 10.0, 3.0


def cpu_of_children():
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def timed(cmds):
    """Runs the commands in turn (the same work, to outputs of their own);
    returns the last result and the best time, a run's time being the
    smaller of its wall time and its CPU time (user + system, all threads).
    On a shared machine the wall time also counts waiting for a CPU, on an
    idle many-core one the CPU time also counts threads running side by
    side: each bounds the run's own cost where the other is inflated."""
    best, r = None, None
    for cmd in cmds:
        t0, c0 = time.monotonic(), cpu_of_children()
        r = tu.run(cmd)
        t = min(time.monotonic() - t0, cpu_of_children() - c0)
        best = t if best is None or t < best else best
        if r.returncode != 0:
            break
    return r, best


def strip(kind, rng):
    if kind == "two_columns":  # x in {0, 1}, every y: co-circular unit squares
        k = np.arange(50000)
        return np.concatenate([0 * k, 0 * k + 1]), np.concatenate([k, k])
    if kind == "diagonal":  # three diagonal lines of points 3 steps apart
        k = np.arange(50000)
        return (np.concatenate([3 * k + 3 * d for d in range(3)]),
                np.concatenate([3 * k for _ in range(3)]))
    if kind == "jittered":  # five columns, random y
        n = 150000
        return rng.integers(0, 5, n), rng.integers(0, 10 * n, n)
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["two_columns", "diagonal", "jittered"])
def test_strip_exact_and_within_time(gdt_bin, tmp_path, kind):
    rng = np.random.default_rng(5)
    X, Y = strip(kind, rng)
    perm = rng.permutation(len(X))
    cloud = tu.write_las(tmp_path / f"{kind}.las", X[perm], Y[perm],
                         np.arange(len(X)) % 5000)
    ref, out = tmp_path / "ref.ply", tmp_path / "out.ply"
    r, t_ref = timed([tu.command(gdt_bin, cloud, p, "--reference")
                      for p in (tmp_path / "ref0.ply", ref)])
    assert r.returncode == 0, r.stderr
    js = tmp_path / "out.json"
    cmds = [tu.command(gdt_bin, cloud, p, "--tile", "256", "--json", js)
            for p in (tmp_path / "out0.ply", out)]
    cmd = cmds[-1]
    r, t_tiled = timed(cmds)
    assert r.returncode == 0, f"{tu.shell(cmd)}\n{r.stderr}"
    s = json.loads(js.read_text())
    print(f"{kind}: {len(X)} points, --reference {t_ref:.2f} s, --tile 256 {t_tiled:.2f} s "
          f"({tu.tile_count(s)} tiles, merge {s['times']['merge']:.2f} s, "
          f"{s['merge_rounds']} rounds of which {s.get('merge_deferred_rounds')} deferred, "
          f"largest band {s['merge_max_band_vertices']} of {s['seam_vertices']})")
    tu.assert_equal_meshes(ref, out, tu.shell(cmd))
    assert t_tiled <= FACTOR * t_ref + SLACK, \
        f"{tu.shell(cmd)}: {t_tiled:.2f} s, --reference {t_ref:.2f} s"
    if kind == "two_columns":  # every point is a hull point: the band keeps them all
        assert s["merge_max_band_vertices"] == s["seam_vertices"] == len(X)
        assert s["merge_deferred_rounds"] > s["merge_rounds"] // 2, s


def small_cloud(tmp_path, n=20000):
    rng = np.random.default_rng(8)
    return tu.write_las(tmp_path / "c.las", rng.integers(0, 20000, n),
                        rng.integers(0, 20000, n), np.arange(n) % 3000)


def test_cell_below_one_lattice_step_is_refused(gdt_bin, tmp_path):
    """The lattice step is 0.01: --cell 0.004 (0.4 steps) and 0.006 (0.6,
    which used to become one step silently) are usage errors naming the
    step; no job or output is made."""
    cloud = small_cloud(tmp_path)
    for cell in ("0.004", "0.006"):
        out = tmp_path / f"out{cell}.ply"
        cmd = tu.command(gdt_bin, cloud, out, "--tile", "256", "--cell", cell)
        r, t = timed([cmd])
        print(f"--cell {cell}: exit {r.returncode} in {t:.2f} s")
        assert r.returncode == 2, f"{tu.shell(cmd)}\n{r.stderr}"
        assert "GDT-2507" in r.stderr and "lattice step is 0.01" in r.stderr \
            and "smallest --cell" in r.stderr, r.stderr
        assert not out.exists()
    # one step exactly is a legal texel
    plan = tu.tile_plan(gdt_bin, cloud, tmp_path / "p.json", "--tile", "64", "--cell", "0.01")
    assert plan["cell_steps"] == 1


def test_cell_making_far_too_many_tiles_warns(gdt_bin, tmp_path):
    """20,000 points over 20,000^2 steps: --cell 0.01 makes tiles of 64 x 64
    steps, nearly one per 4 points, where the automatic cell gives about 20
    tiles of N^2/4 = 1,024."""
    cloud = small_cloud(tmp_path)
    cmd = [gdt_bin, cloud, "--info", "--tile", "64", "--cell", "0.01"]
    r = tu.run(cmd)
    assert r.returncode == 0, r.stderr
    assert "warning GDT-2508" in r.stderr and "--cell" in r.stderr and "--tile" in r.stderr, \
        f"{tu.shell(cmd)}\n{r.stderr}"
    r = tu.run([gdt_bin, cloud, "--info", "--tile", "64"])
    assert r.returncode == 0 and "GDT-2508" not in r.stderr, r.stderr


def test_thin_cloud_gets_fewer_tiles(gdt_bin, tmp_path):
    """The automatic texel of the jittered strip (150,000 points, 1.5e6 steps
    long) is doubled while that cuts the tiles and stays within the point
    spacing: the density's texel, 25 steps, made 235 tiles of 640 points."""
    X, Y = strip("jittered", np.random.default_rng(2))
    thin = tu.write_las(tmp_path / "thin.las", X, Y)
    p = tu.tile_plan(gdt_bin, thin, tmp_path / "p.json", "--tile", "256")
    half = tu.tile_plan(gdt_bin, thin, tmp_path / "h.json", "--tile", "256", "--cell",
                        f"{p['cell_steps'] // 2 * 0.01:.2f}")
    print(f"auto texel {p['cell_steps']} steps: {p['tiles']} tiles; "
          f"half that: {half['tiles']}")
    assert p["tiles"] <= 150 and 4 * p["tiles"] <= 3 * half["tiles"], (p, half)


# ------------------------------------------------------------------ lattices

def write_las(path, X, Y, scale, offset):
    w = LasWriter(path, scale=(scale, scale, 0.01), offset=(offset[0], offset[1], 0.0))
    X = np.asarray(X, np.int32)
    w.write(Batch.simple(X, np.asarray(Y, np.int32), np.zeros(len(X), np.int32),
                         np.zeros(len(X), np.uint16)))
    w.close()
    return path


LATTICES = {
    "lonlat_1e-7": (1e-7, (12.5, 41.9)),   # degrees, no CRS record
    "scale_1e-9": (1e-9, (0.0, 0.0)),
    "scale_1e-12": (1e-12, (0.0, 0.0)),
    "scale_1e3_offset_1e12": (1e3, (1e12, -1e12)),
}


@pytest.mark.parametrize("name", sorted(LATTICES))
def test_extreme_lattices_run(gdt_bin, tmp_path, name):
    scale, offset = LATTICES[name]
    rng = np.random.default_rng(4)
    X, Y = rng.integers(0, 30000, 4000), rng.integers(0, 30000, 4000)
    cloud = write_las(tmp_path / "c.las", X, Y, scale, offset)
    out, ref = tmp_path / "out.ply", tmp_path / "ref.ply"
    cmd = tu.command(gdt_bin, cloud, out, "--tile", "64", "--keep-job", "--job",
                     tmp_path / "job")
    r = tu.run(cmd)
    assert r.returncode == 0, f"{tu.shell(cmd)}\n{r.stderr}"
    assert (tmp_path / "job" / "index.vdb").is_file()
    tu.run_reference(gdt_bin, cloud, ref)
    tu.assert_equal_meshes(ref, out, tu.shell(cmd))


def test_scale_overflowing_to_infinity_is_bad_input(gdt_bin, tmp_path):
    rng = np.random.default_rng(4)
    X, Y = rng.integers(-2 ** 30, 2 ** 30, 500), rng.integers(-2 ** 30, 2 ** 30, 500)
    cloud = write_las(tmp_path / "c.las", X, Y, 1e300, (0.0, 0.0))
    out = tmp_path / "out.ply"
    r = tu.run(tu.command(gdt_bin, cloud, out, "--tile", "64"))
    assert r.returncode == 3, r.stderr
    assert "not finite" in r.stderr and "c.las" in r.stderr, r.stderr
    assert not out.exists()


def test_las_wider_than_the_lattice_limit(gdt_bin, tmp_path):
    """A LAS lattice is the file's scale: the message gives the limit in CRS
    units and a coarser LAS scale, which then runs; --quantum is no advice."""
    rng = np.random.default_rng(6)
    X = np.concatenate([[-2 ** 31 + 5, 2 ** 31 - 5], rng.integers(-2 ** 20, 2 ** 20, 300)])
    Y = rng.integers(0, 2 ** 20, X.size)
    cloud = write_las(tmp_path / "wide.las", X, Y, 0.001, (0.0, 0.0))
    for mode in (["--tile", "64"], ["--reference"]):
        out = tmp_path / "out.ply"
        r, t = timed([tu.command(gdt_bin, cloud, out, *mode)])
        assert r.returncode == 3, r.stderr
        assert "GDT-3406" in r.stderr and "2^31 - 1" in r.stderr, r.stderr
        assert "2.14748e+06" in r.stderr and "--quantum does not apply" in r.stderr, r.stderr
        assert not out.exists()
        assert t < 30, f"refused after {t:.1f} s"
        m = re.search(r"LAS scale of at least ([0-9.e+-]+) x", r.stderr)
        assert m, r.stderr
    # the advice: the same CRS coordinates on the advised lattice fit
    step = float(m.group(1))
    assert 0.002 <= step < 0.0021, step
    coarse = write_las(tmp_path / "coarse.las", np.rint(X * (0.001 / step)),
                       np.rint(Y * (0.001 / step)), step, (0.0, 0.0))
    r = tu.run(tu.command(gdt_bin, coarse, tmp_path / "c.ply", "--tile", "64"))
    assert r.returncode == 0, r.stderr


def test_pcd_wider_than_the_lattice_limit(gdt_bin, tmp_path):
    """On the --quantum lattice the advice is a coarser --quantum, which runs."""
    rng = np.random.default_rng(7)
    x, y = rng.uniform(0, 3e6, 300), rng.uniform(0, 1000, 300)
    cloud = tmp_path / "wide.pcd"
    write_pcd(cloud, x, y, np.zeros(300))
    out = tmp_path / "out.ply"
    r = tu.run(tu.command(gdt_bin, cloud, out, "--tile", "64"))
    assert r.returncode == 3, r.stderr
    assert "GDT-3406" in r.stderr and "use --quantum 0.0014 or coarser" in r.stderr, r.stderr
    assert not out.exists()
    r = tu.run(tu.command(gdt_bin, cloud, tmp_path / "b.ply", "--tile", "64", "--quantum",
                          "0.0014"))
    assert r.returncode == 0, r.stderr
