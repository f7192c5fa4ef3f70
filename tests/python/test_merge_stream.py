"""The seam merge by rows of tiles (merge/gdt_seam.h), through gdt-tile.

The merge holds one band of seams at a time and emits faces as they become
final, so:
  - on a tall strip of 30+ tile rows the output equals --reference and the
    largest band (merge_max_band_vertices) is a few rows' worth of the seam
    (seam_vertices / merge_rounds per row), where merging all seams at once
    holds every seam vertex;
  - layouts whose band triangles have circumdisks over several rows (sparse
    rows, empty rows, a void wider than several rows, two far-apart point
    columns joined by slivers) still give exactly the reference;
  - the same strip (width, density) with twice the rows has about the same
    largest band: hull slivers along the cloud's west and east sides, whose
    disks reach far north but outside the cloud's x range, are emitted;
  - output bytes are the same on every run, and <job>/merge.faces holds the
    merge's faces, in the order they end the PLY.
Every run is also checked against its kept job (test_tiled.check_job).
"""
import pathlib
import struct

import numpy as np
import pytest

import tiled_util as tu
from test_tiled import tiled_vs_reference

CELL = 0.10
T = 64 * 10  # tile side in lattice steps for --tile 64 --cell 0.10
ARGS = ["--tile", "64", "--cell", f"{CELL:.2f}"]
MF_HEADER = struct.Struct("<8sQ")


def cloud_file(tmp_path, name, X, Y):
    Z = np.arange(len(X)) % 4000
    return tu.write_las(tmp_path / f"{name}.las", np.asarray(X, np.int64),
                        np.asarray(Y, np.int64), Z)


def rows_of(Y):
    return len(np.unique(np.asarray(Y) // T))


def merge_run(gdt_bin, tmp_path, X, Y, halo, name):
    """The tiled run against the reference, with the job kept and checked;
    returns the summary, the mesh and the job directory."""
    cloud = cloud_file(tmp_path, name, X, Y)
    ref = tu.run_reference(gdt_bin, cloud, tmp_path / f"{name}.ref.ply")
    s, mesh, out, cmd = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                           ARGS + ["--halo", halo], job=True, XY=(X, Y),
                                           tag=name)
    for k in ("merge_rounds", "merge_max_band_vertices", "merge_peak_bytes", "merge_flips"):
        assert isinstance(s.get(k), int), f"{cmd}: summary lacks {k}"
    # a band of more than a handful of seam points is not Delaunay as inserted
    assert s["merge_flips"] > 0 or s["seam_vertices"] < 8, f"{cmd}: no merge flips"
    assert s["merge_rounds"] == rows_of(Y), \
        f"{cmd}: {s['merge_rounds']} merge rounds for {rows_of(Y)} rows of tiles"
    assert 0 < s["merge_max_band_vertices"] <= s["seam_vertices"]
    return s, mesh, tmp_path / f"{name}.job", cmd


def read_merge_faces(job):
    data = (pathlib.Path(job) / "merge.faces").read_bytes()
    magic, n = MF_HEADER.unpack_from(data)
    assert magic == b"GDTMRG01", magic
    assert len(data) == MF_HEADER.size + 12 * n, f"merge.faces: {len(data)} bytes for {n} faces"
    return np.frombuffer(data, dtype="<u4", offset=MF_HEADER.size).reshape(n, 3).astype(np.int64)


def tall_strip(rng, cols, rows, per_tile):
    n = cols * rows * per_tile
    return rng.integers(0, cols * T, n), rng.integers(0, rows * T, n)


@pytest.mark.parametrize("halo", ["0", "2"])
def test_tall_strip_band_stays_small(gdt_bin, tmp_path, halo):
    X, Y = tall_strip(np.random.default_rng(41), 3, 34, 90)
    s, mesh, job, cmd = merge_run(gdt_bin, tmp_path, X, Y, halo, "strip")
    rounds, seam, band = s["merge_rounds"], s["seam_vertices"], s["merge_max_band_vertices"]
    assert rounds >= 30
    # a row of tiles holds seam / rounds seam vertices on average
    assert band * rounds < 3 * seam, \
        f"{cmd}: the largest band holds {band} of {seam} seam vertices ({rounds} rows)"
    assert s["merge_faces"] > 0 and s["certified_faces"] > 0
    # the merge's file: its faces end the PLY, in the same order
    mf = read_merge_faces(job)
    assert len(mf) == s["merge_faces"]
    assert np.array_equal(mesh.faces[mesh.nface - len(mf):], mf), \
        "merge.faces is not the tail of the PLY's faces"


@pytest.mark.sanitize
def test_tall_strip_small(gdt_bin, tmp_path):
    X, Y = tall_strip(np.random.default_rng(43), 2, 31, 25)
    s, *_ = merge_run(gdt_bin, tmp_path, X, Y, "1", "small")
    assert s["merge_rounds"] >= 30
    # sparse tiles: most points are seam; the band is still a small part of it
    assert 5 * s["merge_max_band_vertices"] < s["seam_vertices"]


# A fine lattice (1000 lattice steps per texel): hardly any point lies exactly
# on the cloud's west or east line, whose points would all stay in the band
# as hull vertices (a separate effect).
T_FINE = 64 * 1000
ARGS_FINE = ["--tile", "64", "--cell", "10.00"]


@pytest.mark.sanitize
def test_band_does_not_grow_with_rows(gdt_bin, tmp_path):
    bands = {}
    for rows in (40, 80):
        rng = np.random.default_rng(46)
        n = 2 * rows * 40
        X, Y = rng.integers(0, 2 * T_FINE, n), rng.integers(0, rows * T_FINE, n)
        name = f"fine{rows}"
        cloud = cloud_file(tmp_path, name, X, Y)
        ref = tu.run_reference(gdt_bin, cloud, tmp_path / f"{name}.ref.ply")
        s, _, _, cmd = tiled_vs_reference(gdt_bin, tmp_path, cloud, ref,
                                          ARGS_FINE + ["--halo", "1"], tag=name)
        assert s["merge_rounds"] == rows, f"{cmd}: {s['merge_rounds']} rounds for {rows} rows"
        bands[rows] = (s["merge_max_band_vertices"], s["seam_vertices"])
    (b1, s1), (b2, s2) = bands[40], bands[80]
    print(f"largest band: {b1} of {s1} seam vertices in 40 rows, {b2} of {s2} in 80")
    assert 0 < b1 and 10 * b2 < 13 * b1, \
        f"the largest band grows with the rows: {b1} of {s1} seam vertices in 40 rows, " \
        f"{b2} of {s2} in 80"


def layout(name, rng):
    if name == "sparse_rows":  # 1-4 points per tile, rows 3..6 empty
        xs, ys = [], []
        for j in range(14):
            if 3 <= j <= 6:
                continue
            for i in range(4):
                k = int(rng.integers(1, 5))
                xs.append(rng.integers(i * T, (i + 1) * T, k))
                ys.append(rng.integers(j * T, (j + 1) * T, k))
        return np.concatenate(xs), np.concatenate(ys)
    if name == "void_of_rows":  # a round void 6 rows across, a lone point inside
        x, y = rng.integers(0, 10 * T, 9000), rng.integers(0, 12 * T, 9000)
        keep = (x - 5 * T) ** 2 + (y - 6 * T) ** 2 > (3 * T) ** 2
        return np.append(x[keep], 5 * T + 7), np.append(y[keep], 6 * T - 5)
    if name == "two_columns":  # slivers between far-apart columns: disks span many rows
        k = 400
        y = rng.integers(0, 20 * T, 2 * k)
        x = np.concatenate([rng.integers(0, 8, k), 9 * T + rng.integers(0, 8, k)])
        return x, y
    if name == "staircase":  # one tile per row, shifted each row: hull grows sideways
        xs, ys = [], []
        for j in range(24):
            xs.append(rng.integers(j * T // 2, j * T // 2 + T, 60))
            ys.append(rng.integers(j * T, (j + 1) * T, 60))
        return np.concatenate(xs), np.concatenate(ys)
    raise ValueError(name)


LAYOUTS = ["sparse_rows", "void_of_rows", "two_columns", "staircase"]


@pytest.mark.parametrize("halo", ["0", "3"])
@pytest.mark.parametrize("name", LAYOUTS)
def test_disks_across_rows(gdt_bin, tmp_path, name, halo):
    X, Y = layout(name, np.random.default_rng(7 + LAYOUTS.index(name)))
    s, mesh, _, _ = merge_run(gdt_bin, tmp_path, X, Y, halo, name)
    assert mesh.nface > 0 and s["merge_rounds"] > 5


@pytest.mark.sanitize
def test_sparse_rows_sanitized(gdt_bin, tmp_path):
    X, Y = layout("sparse_rows", np.random.default_rng(3))
    merge_run(gdt_bin, tmp_path, X, Y, "1", "sparse")


def test_same_bytes_twice(gdt_bin, tmp_path):
    X, Y = tall_strip(np.random.default_rng(44), 2, 32, 40)
    cloud = cloud_file(tmp_path, "c", X, Y)
    a, b = tmp_path / "a.ply", tmp_path / "b.ply"
    sa, cmd = tu.run_tiled(gdt_bin, cloud, a, *ARGS, "--halo", "1")
    sb, _ = tu.run_tiled(gdt_bin, cloud, b, *ARGS, "--halo", "1", "--keep-job", "--job",
                         tmp_path / "kept")
    assert sa["merge_rounds"] >= 30
    assert a.read_bytes() == b.read_bytes(), f"two runs of {cmd} differ"
    for k in ("merge_rounds", "merge_max_band_vertices", "seam_vertices", "merge_faces"):
        assert sa[k] == sb[k], k
