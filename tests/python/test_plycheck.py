"""The streaming C checker (tests/tools/plycheck_run, gdt_ply_check) against
scripts/validate_mesh.py, on meshes written by `gdt-tile IN --reference`.

Clouds come from scripts/gen_cloud.py and scripts/gen_degenerate.py (seeded).
Faults are planted by rewriting the PLY with numpy (the approach of
test_validate_mesh.py, on gdt-tile's own output): a flipped convex edge, a
flipped co-circular diagonal, a missing face, a duplicated vertex, an inverted
face, an unused vertex, an index out of range, a truncated file.  Both tools
must reach the same verdict, the same kind of violation (C message number vs
the category of the Python line) and, on valid meshes, the same counts.  A run
with the smallest memory budget (64 KiB) forces every spill path of the C
checker and must change nothing but the spill statistics.
"""
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"

# C message number -> phrase of the matching validate_mesh.py category.
CATEGORY = {
    7360: "vertices off the lattice",
    7361: "duplicate vertices",
    7362: "degenerate-set violations",
    7363: "faces that are not triangles",
    7364: "faces with a vertex index out of range",
    7365: "faces with a repeated vertex",
    7366: "faces not strictly counter-clockwise",
    7367: "vertices in no face",
    7368: "edges in more than two faces",
    7369: "edges used twice in the same direction",
    7370: "edges not locally Delaunay",
    7371: "co-circular edges losing the tie-break",
    7372: "boundary",
    7373: "boundary",
    7374: "boundary",
    7375: "Euler violations",
}

FACE_DTYPE = np.dtype([("n", "u1"), ("v", "<i4", (3,))])
VERT_DTYPE = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8")])


# ------------------------------------------------------------------ tools

def run(cmd, timeout=600):
    return subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=timeout)


def script(name, *args):
    return run([sys.executable, SCRIPTS / name] + list(args))


def plycheck(tool, mesh, *args):
    return run([tool("plycheck_run"), mesh] + list(args))


def validate(mesh, *args):
    return script("validate_mesh.py", mesh, *args)


@pytest.fixture(scope="module")
def gdt_tile():
    from conftest import build_dir
    exe = build_dir() / "tiler" / "gdt-tile"
    if not exe.exists():
        pytest.fail("gdt-tile not built at %s (set GDT_BUILD_DIR)" % exe)
    return exe


def reference_mesh(gdt_tile, cloud, out):
    r = run([gdt_tile, cloud, "--reference", "-q", "-o", out])
    assert r.returncode == 0, r.stderr
    return out


def c_counts(out):
    """(V, F, h, E) from an OK line of plycheck_run."""
    assert out.returncode == 0, out.stdout + out.stderr
    m = re.match(r"OK: (\d+) vertices, (\d+) faces, (\d+) hull vertices, (\d+) interior edges "
                 r"checked; spill (\d+) bytes in (\d+) files; peak heap (\d+) of (\d+) bytes",
                 out.stdout)
    assert m, out.stdout
    v = [int(g) for g in m.groups()]
    assert v[6] <= v[7], "heap peak above the budget: " + out.stdout
    return tuple(v[:4]), v[4]


def py_counts(out):
    assert out.returncode == 0, out.stdout + out.stderr
    w = out.stdout.strip()[4:].split()
    return int(w[0]), int(w[2]), int(w[4]), int(w[7])


def c_code(out):
    assert out.returncode == 7, out.stdout + out.stderr
    m = re.match(r"FAIL: GDT-(\d+): ", out.stdout)
    assert m and "\n" not in out.stdout.strip(), out.stdout
    return int(m.group(1))


def same_verdict(tool, mesh, spill_dir=None):
    """Runs both checkers (the C one with the default and the smallest budget);
    asserts the same verdict; returns the C result of the default run."""
    c = plycheck(tool, mesh)
    args = ["--mem-budget", "64K"]
    if spill_dir is not None:
        args += ["--temp-dir", spill_dir]
    small = plycheck(tool, mesh, *args)
    py = validate(mesh)
    if py.returncode == 0:
        counts, _ = c_counts(c)
        assert counts == py_counts(py), (c.stdout, py.stdout)
        small_counts, _ = c_counts(small)
        assert small_counts == counts
    else:
        assert py.returncode == 1, py.stdout + py.stderr
        code = c_code(c)
        assert c_code(small) == code, (c.stdout, small.stdout)
        assert CATEGORY[code] in py.stdout, (c.stdout, py.stdout)
    if spill_dir is not None:
        assert list(pathlib.Path(spill_dir).iterdir()) == []
    return c


# ------------------------------------------------------------------ PLY surgery

class Ply:
    """A gdt-tile PLY held in numpy arrays (small meshes only)."""

    def __init__(self, path):
        data = pathlib.Path(path).read_bytes()
        end = data.index(b"end_header\n") + len(b"end_header\n")
        self.header = data[:end].decode("ascii")
        nv = int(re.search(r"element vertex\s+(\d+)", self.header).group(1))
        nf = int(re.search(r"element face\s+(\d+)", self.header).group(1))
        self.verts = np.frombuffer(data, VERT_DTYPE, nv, end).copy()
        self.faces = np.frombuffer(data, FACE_DTYPE, nf, end + nv * VERT_DTYPE.itemsize).copy()
        lat = re.search(r"comment lattice (\S+) (\S+) (\S+) (\S+)", self.header).groups()
        self.sx, self.sy, self.ox, self.oy = (float(t) for t in lat)

    def write(self, path):
        head = re.sub(r"element vertex\s+\d+ *", "element vertex %d" % len(self.verts), self.header)
        head = re.sub(r"element face\s+\d+ *", "element face %d" % len(self.faces), head)
        pathlib.Path(path).write_bytes(head.encode("ascii") + self.verts.tobytes()
                                       + self.faces.tobytes())
        return path

    def ints(self):
        """Lattice integers of every vertex (Python ints)."""
        ix = np.rint((self.verts["x"] - self.ox) / self.sx).astype(np.int64)
        iy = np.rint((self.verts["y"] - self.oy) / self.sy).astype(np.int64)
        return [(int(a), int(b)) for a, b in zip(ix, iy)]

    def edges(self):
        """{(lo, hi): [face ids]}"""
        e = {}
        for k, t in enumerate(self.faces["v"].tolist()):
            for i in range(3):
                a, b = t[i], t[(i + 1) % 3]
                e.setdefault((min(a, b), max(a, b)), []).append(k)
        return e


def orient(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def incircle(a, b, c, d):
    rows = [(p[0] - d[0], p[1] - d[1]) for p in (a, b, c)]
    m = [(x, y, x * x + y * y) for x, y in rows]
    return (m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]))


def flip_first(ply, want_cocircular):
    """Flips the first interior edge (in key order) whose quad is strictly
    convex and whose four points are (not) co-circular."""
    P = ply.ints()
    F = ply.faces["v"]
    for (a, b), fs in sorted(ply.edges().items()):
        if len(fs) != 2:
            continue
        t1, t2 = F[fs[0]].tolist(), F[fs[1]].tolist()
        c = next(v for v in t1 if v not in (a, b))
        d = next(v for v in t2 if v not in (a, b))
        if not (orient(P[a], P[b], P[c]) * orient(P[a], P[b], P[d]) < 0
                and orient(P[c], P[d], P[a]) * orient(P[c], P[d], P[b]) < 0):
            continue
        if (incircle(P[a], P[b], P[c], P[d]) == 0) != want_cocircular:
            continue
        i = t1.index(a)
        p, q = (a, b) if t1[(i + 1) % 3] == b else (b, a)
        # (p, q, c) and (q, p, d) counter-clockwise -> (p, d, c) and (d, q, c).
        F[fs[0]] = (p, d, c)
        F[fs[1]] = (d, q, c)
        return
    raise AssertionError("no suitable edge")


def interior_face(ply):
    """A face none of whose vertices is on the boundary."""
    on_hull = set()
    for (a, b), fs in ply.edges().items():
        if len(fs) == 1:
            on_hull.update((a, b))
    for k, t in enumerate(ply.faces["v"].tolist()):
        if not on_hull.intersection(t):
            return k
    raise AssertionError("no interior face")


# ------------------------------------------------------------------ fixtures

@pytest.fixture(scope="module")
def lidar_mesh(tmp_path_factory, gdt_tile):
    d = tmp_path_factory.mktemp("lidar")
    cloud = d / "lidar.las"
    g = script("gen_cloud.py", cloud, "--points", "6000", "--seed", "11", "--kind", "mixed",
               "--density", "4")
    assert g.returncode == 0, g.stderr
    return reference_mesh(gdt_tile, cloud, d / "lidar.ply")


@pytest.fixture(scope="module")
def grid_mesh(tmp_path_factory, gdt_tile):
    d = tmp_path_factory.mktemp("grid")
    cloud = d / "grid.las"
    g = script("gen_cloud.py", cloud, "--points", "3000", "--seed", "2", "--kind", "grid")
    assert g.returncode == 0, g.stderr
    return reference_mesh(gdt_tile, cloud, d / "grid.ply")


# ------------------------------------------------------------------ valid meshes

@pytest.mark.sanitize
def test_generated_meshes_agree_and_spill(tool, lidar_mesh, grid_mesh, tmp_path):
    spill = tmp_path / "spill"
    spill.mkdir()
    for mesh in (lidar_mesh, grid_mesh):
        c = same_verdict(tool, mesh, spill)
        assert c.returncode == 0, c.stdout + c.stderr
        # The default budget keeps these in memory; 64 KiB must spill.
        _, spilled = c_counts(c)
        assert spilled == 0
        _, spilled = c_counts(plycheck(tool, mesh, "--mem-budget", "64K", "--temp-dir", spill))
        assert spilled > 48 * Ply(mesh).faces.shape[0]


@pytest.mark.parametrize("kind", ["grid", "rotgrid", "circle", "clusters", "duplicates",
                                  "collinear", "three", "thincircle", "sparse"])
def test_degenerate_sets_agree(tool, gdt_tile, tmp_path, kind):
    cloud = tmp_path / (kind + ".las")
    g = script("gen_degenerate.py", kind, cloud, "--n", "800", "--seed", "5")
    assert g.returncode == 0, g.stderr
    mesh = reference_mesh(gdt_tile, cloud, tmp_path / (kind + ".ply"))
    c = same_verdict(tool, mesh)
    assert c.returncode == 0, c.stdout + c.stderr


def test_real_data_agrees(tool, gdt_tile, tmp_path, data_dir):
    mesh = reference_mesh(gdt_tile, data_dir / "autzen_trim.las", tmp_path / "autzen.ply")
    spill = tmp_path / "spill"
    spill.mkdir()
    c = same_verdict(tool, mesh, spill)
    assert c.returncode == 0, c.stdout + c.stderr


# ------------------------------------------------------------------ planted faults

def plant(src, dst, fault):
    ply = Ply(src)
    V = len(ply.verts)
    if fault == "non_delaunay":
        flip_first(ply, want_cocircular=False)
    elif fault == "cocircular":
        flip_first(ply, want_cocircular=True)
    elif fault == "missing_face":
        k = interior_face(ply)
        ply.faces = np.delete(ply.faces, k)
    elif fault == "dup_vertex":
        ply.verts = np.concatenate([ply.verts, ply.verts[V // 2:V // 2 + 1]])
    elif fault == "inverted":
        k = len(ply.faces) // 3
        ply.faces["v"][k] = ply.faces["v"][k][[0, 2, 1]]
    elif fault == "unused":
        extra = ply.verts[:1].copy()
        P = ply.ints()
        xmax = max(p[0] for p in P)
        extra["x"] = ply.ox + ply.sx * (xmax + 17)
        ply.verts = np.concatenate([ply.verts, extra])
    elif fault == "out_of_range":
        ply.faces["v"][len(ply.faces) - 5, 2] = V + 3
    else:
        raise ValueError(fault)
    return ply.write(dst)


@pytest.mark.parametrize("fault,mesh_name,code", [
    ("non_delaunay", "lidar", 7370),
    ("cocircular", "grid", 7371),
    ("missing_face", "lidar", 7373),
    ("dup_vertex", "lidar", 7361),
    ("inverted", "grid", 7366),
    ("unused", "lidar", 7367),
    ("out_of_range", "grid", 7364),
])
def test_planted_faults_agree(tool, lidar_mesh, grid_mesh, tmp_path, fault, mesh_name, code):
    src = lidar_mesh if mesh_name == "lidar" else grid_mesh
    bad = plant(src, tmp_path / (fault + ".ply"), fault)
    spill = tmp_path / "spill"
    spill.mkdir()
    c = same_verdict(tool, bad, spill)
    assert c_code(c) == code, c.stdout


@pytest.mark.sanitize
def test_bad_files(tool, grid_mesh, tmp_path):
    data = pathlib.Path(grid_mesh).read_bytes()
    cases = {
        "truncated.ply": (data[:-7], 3, "GDT-3364"),
        "trailing.ply": (data + b"\0", 3, "GDT-3364"),
        "text.ply": (b"hello\n", 3, "GDT-3360"),
        "ascii.ply": (data.replace(b"binary_little_endian", b"ascii", 1), 3, "GDT-3362"),
    }
    for name, (content, code, msg) in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        c = plycheck(tool, p)
        assert c.returncode == code, (name, c.stdout, c.stderr)
        assert c.stdout == "" and c.stderr.startswith("ERROR: " + msg) and str(p) in c.stderr
        assert validate(p).returncode == 3, name
    c = plycheck(tool, tmp_path / "absent.ply")
    assert c.returncode == 4 and "GDT-4360" in c.stderr
    assert plycheck(tool, grid_mesh, "--mem-budget", "lots").returncode == 2
    assert run([tool("plycheck_run")]).returncode == 2
