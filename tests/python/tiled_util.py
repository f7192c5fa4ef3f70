"""Helpers of test_tiled.py: running gdt-tile, its reference and the mesh
scripts, writing LAS clouds, and reading the tiled pipeline's outputs (the
PLY as lattice integers, the job's tiles/*.tri files, the --json summary).

Lattice integers are the LAS record integers: the clouds written here all
have scale 0.01 and one offset, so "comment lattice" of every mesh maps
vertex coordinates back to them exactly.
"""
import json
import pathlib
import re
import struct
import subprocess
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
if str(SCRIPTS) not in sys.path:
    sys.path.insert(0, str(SCRIPTS))

from gdtmesh.compare import canonical  # noqa: E402
from gdtmesh.ply import PlyMesh, to_lattice  # noqa: E402

SCALE = 0.01
OFFSET = (500000.0, 4000000.0)
TRI_MAGIC = b"GDTTRI02"
TRI_HEADER = struct.Struct("<8s7Q")
SEAM_DTYPE = np.dtype([("id", "<u8"), ("gx", "<i8"), ("gy", "<i8"), ("z", "<f8")])
EDGE_DTYPE = np.dtype([("a", "<u8"), ("b", "<u8")])
TRI_NAME = re.compile(r"^tile_(-?\d+)_(-?\d+)\.tri$")
SUMMARY_KEYS = ("tiles", "vertices", "faces", "certified_faces", "merge_faces",
                "certified_fraction", "seam_vertices", "barrier_edges", "halo", "cell",
                "times", "peak_rss_bytes", "device")
TIME_KEYS = ("pass1", "pass2", "tiles", "merge", "write", "total")


def run(cmd, timeout=900, **kw):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True,
                          timeout=timeout, **kw)


def script(name, *args):
    return run([sys.executable, SCRIPTS / name, *args])


# ---------------------------------------------------------------- clouds

def gen_cloud(path, points, seed, kind="lidar", *extra):
    r = script("gen_cloud.py", path, "--points", points, "--seed", seed, "--kind", kind, "-q",
               *extra)
    assert r.returncode == 0, r.stderr
    return path


def gen_degenerate(path, kind, *extra):
    r = script("gen_degenerate.py", kind, path, *extra)
    assert r.returncode == 0, r.stderr
    return path


def write_las(path, X, Y, Z=None, scale=SCALE, offset=OFFSET):
    """A LAS 1.2 format 3 file of the record integers X, Y (Z: zeros)."""
    import laspy
    X = np.asarray(X, dtype=np.int64)
    Y = np.asarray(Y, dtype=np.int64)
    assert X.shape == Y.shape and X.ndim == 1
    assert X.size == 0 or (X.min() >= -2 ** 31 and X.max() < 2 ** 31
                           and Y.min() >= -2 ** 31 and Y.max() < 2 ** 31)
    if Z is None:
        Z = np.zeros(X.size, dtype=np.int64)
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    hdr.scales = np.array([scale, scale, scale])
    hdr.offsets = np.array([offset[0], offset[1], 0.0])
    las = laspy.LasData(hdr)
    las.X = X.astype(np.int32)
    las.Y = Y.astype(np.int32)
    las.Z = np.asarray(Z, dtype=np.int64).astype(np.int32)
    las.write(str(path))
    return path


def read_las_xy(path):
    """Record integers X, Y, Z of a LAS file, in file order."""
    import laspy
    las = laspy.read(str(path))
    return (np.asarray(las.X, dtype=np.int64), np.asarray(las.Y, dtype=np.int64),
            np.asarray(las.Z, dtype=np.int64))


def permute_las(src, dst, seed, parts=1):
    """Writes the points of src in a seeded random order, split into `parts`
    files dst-0.las... when parts > 1 (several inputs form one cloud).
    returns the list of written paths.  Header (scale, offset, VLRs) kept."""
    import laspy
    las = laspy.read(str(src))
    perm = np.random.default_rng(seed).permutation(len(las.points))
    assert not np.array_equal(perm, np.arange(len(perm)))
    dst = pathlib.Path(dst)
    paths = []
    bounds = np.linspace(0, len(perm), parts + 1).astype(int)
    for k in range(parts):
        out = laspy.LasData(las.header)
        out.points = las.points[perm[bounds[k]:bounds[k + 1]]]
        p = dst if parts == 1 else dst.with_name(f"{dst.stem}-{k}{dst.suffix}")
        out.write(str(p))
        paths.append(p)
    return paths


# ---------------------------------------------------------------- runs

def tiled_args(tile, cell=None, halo=None):
    args = ["--tile", tile]
    if cell is not None:
        args += ["--cell", cell]
    if halo is not None:
        args += ["--halo", halo]
    return args


def command(gdt_bin, inputs, out, *args):
    if isinstance(inputs, (str, pathlib.Path)):
        inputs = [inputs]
    return [gdt_bin, *inputs, "-q", "-o", out, *args]


def run_tiled(gdt_bin, inputs, out, *args):
    """Runs the tiled pipeline with --json; returns (summary, command line).
    Fails the calling test, with the command line, on a non-zero exit."""
    js = pathlib.Path(str(out) + ".json")
    cmd = command(gdt_bin, inputs, out, *args, "--json", js)
    r = run(cmd)
    assert r.returncode == 0, f"exit {r.returncode}: {shell(cmd)}\n{r.stderr}"
    summary = json.loads(js.read_text())
    return summary, shell(cmd)


def run_reference(gdt_bin, inputs, out, *args):
    cmd = command(gdt_bin, inputs, out, "--reference", *args)
    r = run(cmd)
    assert r.returncode == 0, f"exit {r.returncode}: {shell(cmd)}\n{r.stderr}"
    return out


def shell(cmd):
    return " ".join(str(c) for c in cmd)


def compare(a, b):
    return script("compare_meshes.py", a, b)


def validate(mesh, inputs=None):
    args = [mesh]
    if inputs is not None:
        if isinstance(inputs, (str, pathlib.Path)):
            inputs = [inputs]
        for p in inputs:
            args += ["--input", p]
    return script("validate_mesh.py", *args)


def assert_equal_meshes(a, b, what):
    r = compare(a, b)
    assert r.returncode == 0, f"{what}: compare_meshes {a} {b} -> exit {r.returncode}\n" \
                              f"{r.stdout}{r.stderr}"


def assert_valid(mesh, inputs, what):
    r = validate(mesh, inputs)
    assert r.returncode == 0, f"{what}: validate_mesh -> exit {r.returncode}\n{r.stdout}{r.stderr}"


def tile_count(summary):
    """The summary's "tiles": a count, or a list with one entry per tile."""
    t = summary["tiles"]
    return len(t) if isinstance(t, list) else int(t)


# ---------------------------------------------------------------- meshes

class Mesh:
    """A PLY mesh as lattice integers: ix, iy (int64, per vertex), z (float64),
    faces (int64, F x 3), raw header bytes length and the lattice."""

    def __init__(self, path):
        ply = PlyMesh(path)
        assert ply.lattice is not None, f"{path}: {ply.lattice_problem}"
        self.path = str(path)
        self.lattice = ply.lattice
        self.nvert, self.nface = ply.nvert, ply.nface
        v = np.asarray(ply.vertices)
        ix, iy, bad = to_lattice(ply.lattice, v["x"], v["y"]) if ply.nvert else (
            np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, bool))
        assert not np.any(bad), f"{path}: vertices off the lattice"
        self.ix, self.iy = ix, iy
        self.z = np.asarray(v["z"], dtype=np.float64) if ply.nvert else np.zeros(0)
        f = np.asarray(ply.faces)
        assert np.all(f["n"] == 3) if ply.nface else True
        self.faces = np.asarray(f["v"], dtype=np.int64).reshape(-1, 3)
        del ply

    def rows(self, faces=None):
        """Canonical rows (x0 y0 x1 y1 x2 y2, rotated to the smallest vertex,
        orientation kept) of faces (default: all)."""
        f = self.faces if faces is None else np.asarray(faces, dtype=np.int64).reshape(-1, 3)
        if len(f) == 0:
            return np.zeros((0, 6), dtype=np.int64)
        return canonical(self.ix[f], self.iy[f])

    def row_set(self, faces=None):
        return set(map(tuple, self.rows(faces).tolist()))

    def z_by_point(self):
        return dict(zip(zip(self.ix.tolist(), self.iy.tolist()), self.z.tolist()))


def unique_face_count(faces):
    """Number of distinct faces as unordered vertex sets."""
    if len(faces) == 0:
        return 0
    return len(np.unique(np.sort(faces, axis=1), axis=0))


# ---------------------------------------------------------------- the job

class TriFile:
    """One tiles/tile_<i>_<j>.tri, parsed strictly against its header."""

    def __init__(self, path):
        data = pathlib.Path(path).read_bytes()
        self.path = str(path)
        m = TRI_NAME.match(pathlib.Path(path).name)
        assert m, f"{path}: unexpected name"
        self.i, self.j = int(m.group(1)), int(m.group(2))
        assert len(data) >= TRI_HEADER.size, f"{path}: {len(data)} bytes, shorter than the header"
        magic, base, nv, nc, ns, nb, id0, id1 = TRI_HEADER.unpack_from(data)
        assert magic == TRI_MAGIC, f"{path}: magic {magic!r}"
        self.job_id = (id0, id1)  # the job's random id (the same in every file)
        need = TRI_HEADER.size + 12 * nc + SEAM_DTYPE.itemsize * ns + EDGE_DTYPE.itemsize * nb
        assert len(data) == need, f"{path}: {len(data)} bytes, the header implies {need}"
        self.vertex_base, self.vertices = base, nv
        off = TRI_HEADER.size
        self.faces = np.frombuffer(data, dtype="<u4", count=3 * nc, offset=off).reshape(nc, 3) \
            .astype(np.int64)
        off += 12 * nc
        self.seam = np.frombuffer(data, dtype=SEAM_DTYPE, count=ns, offset=off)
        off += SEAM_DTYPE.itemsize * ns
        self.barrier = np.frombuffer(data, dtype=EDGE_DTYPE, count=nb, offset=off)


def read_job(job):
    """The .tri files of job/tiles in tile order (rows south to north, then
    west to east: sorted by (j, i))."""
    tiles = pathlib.Path(job) / "tiles"
    assert tiles.is_dir(), f"{tiles} missing (--keep-job)"
    tris = [TriFile(p) for p in tiles.iterdir() if p.name.endswith(".tri")]
    ids = {t.job_id for t in tris}
    assert len(ids) <= 1, f"{tiles}: .tri files of {len(ids)} different jobs"
    return sorted(tris, key=lambda t: (t.j, t.i))


def directed_edges(faces):
    f = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    return {(int(a), int(b)) for tri in f.tolist() for a, b in
            ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0]))}


def first_ordinals(X, Y, ix, iy):
    """For every vertex (ix[k], iy[k]), the lowest input ordinal of a point
    with that (X, Y); -1 for a vertex that is no input point."""
    def key(a, b):
        return ((np.asarray(a, np.int64) + (1 << 31)).astype(np.uint64) << np.uint64(32)) | \
            (np.asarray(b, np.int64) + (1 << 31)).astype(np.uint64)
    k_in, k_v = key(X, Y), key(ix, iy)
    if len(k_in) == 0:
        return np.full(len(k_v), -1, dtype=np.int64)
    uk, first = np.unique(k_in, return_index=True)
    pos = np.minimum(np.searchsorted(uk, k_v), len(uk) - 1)
    return np.where(uk[pos] == k_v, first[pos], -1)


def tile_plan(gdt_bin, inputs, out_json, *args):
    """The tile plan --info prints for these options (cell_steps, tiles...)."""
    if isinstance(inputs, (str, pathlib.Path)):
        inputs = [inputs]
    cmd = [gdt_bin, *inputs, "--info", "--json", out_json, *args]
    r = run(cmd)
    assert r.returncode == 0, f"{shell(cmd)}\n{r.stderr}"
    return json.loads(pathlib.Path(out_json).read_text())["tile_plan"]
