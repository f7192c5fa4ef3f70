"""Comparison of two meshes as canonical triangle sets (compare_meshes.py).

Every triangle becomes a row of six lattice integers (x0 y0 x1 y1 x2 y2),
rotated so that it starts at its lexicographically smallest vertex (x, then
y); the cyclic order, hence the orientation, is kept.  The two meshes are
equal when their multisets of rows are equal, and their multisets of vertex
lattice points too; vertex order, face order and triangle rotation do not
matter, z does not count.  Meshes on lattices with equal steps whose origins
differ by whole steps are compared after shifting B onto A's lattice.

Memory: rows are spread over hash buckets (temporary files of about
48 * chunk bytes each when they do not fit one), so resident memory is
O(chunk); temporary disk is about 48 bytes per triangle of A and B together.
"""
import numpy as np

from .ply import Lattice, MeshFileError, PlyMesh, to_lattice
from .spill import Spill, buckets_for, hash_rows

EXIT_EQUAL, EXIT_DIFFERENT, EXIT_USAGE, EXIT_UNREADABLE = 0, 1, 2, 3
TRI_DTYPE = np.dtype([("t", "<i8", (6,))])
VERT_DTYPE = np.dtype([("t", "<i8", (2,))])
EXAMPLES = 3


class CompareError(Exception):
    def __init__(self, code, msg):
        super().__init__(msg)
        self.code = code


def _lattice(ply, quantum):
    if ply.lattice is not None:
        return ply.lattice
    if quantum is not None:
        return Lattice(quantum, quantum, 0.0, 0.0)
    raise CompareError(EXIT_UNREADABLE, "%s: %s (give --quantum to assume one)"
                       % (ply.path, ply.lattice_problem))


def _shift(la, lb):
    """Integer shift taking B's lattice integers to A's."""
    if la == lb:
        return 0, 0
    if la.sx == lb.sx and la.sy == lb.sy:
        kx = (lb.ox - la.ox) / la.sx
        ky = (lb.oy - la.oy) / la.sy
        if abs(kx - round(kx)) <= 1e-9 and abs(ky - round(ky)) <= 1e-9:
            return int(round(kx)), int(round(ky))
    raise CompareError(EXIT_USAGE, "the meshes are on different lattices: %r and %r" % (tuple(la), tuple(lb)))


def _ints(ply, lat, idx, shift):
    v = ply.vertices[idx]
    ix, iy, bad = to_lattice(lat, v["x"], v["y"])
    if np.any(bad):
        k = int(np.nonzero(bad)[0][0])
        raise CompareError(EXIT_UNREADABLE, "%s: vertex %d is off the lattice" % (ply.path, int(np.asarray(idx).ravel()[k])))
    return ix + shift[0], iy + shift[1]


def canonical(tx, ty):
    """tx, ty: (n, 3) int64 vertex coordinates of n triangles.  returns (n, 6)
    rows rotated to start at the lexicographically smallest vertex."""
    n = tx.shape[0]
    m = np.zeros(n, dtype=np.int64)
    for j in (1, 2):
        bx = tx[np.arange(n), m]
        by = ty[np.arange(n), m]
        less = (tx[:, j] < bx) | ((tx[:, j] == bx) & (ty[:, j] < by))
        m = np.where(less, j, m)
    cols = (m[:, None] + np.arange(3)[None, :]) % 3
    rx = np.take_along_axis(tx, cols, axis=1)
    ry = np.take_along_axis(ty, cols, axis=1)
    out = np.empty((n, 6), dtype=np.int64)
    out[:, 0::2] = rx
    out[:, 1::2] = ry
    return out


def _fill(ply, lat, shift, chunk, tspill, vspill):
    for s in range(0, ply.nvert, chunk):
        e = min(ply.nvert, s + chunk)
        ix, iy = _ints(ply, lat, np.arange(s, e), shift)
        rec = np.empty(e - s, dtype=VERT_DTYPE)
        rec["t"][:, 0] = ix
        rec["t"][:, 1] = iy
        vspill.add(rec, hash_rows([ix, iy], vspill.nb))
    for s in range(0, ply.nface, chunk):
        e = min(ply.nface, s + chunk)
        f = ply.faces[s:e]
        if np.any(f["n"] != 3):
            raise CompareError(EXIT_UNREADABLE, "%s: face %d is not a triangle"
                               % (ply.path, s + int(np.nonzero(f["n"] != 3)[0][0])))
        tri = np.asarray(f["v"], dtype=np.int64)
        if np.any((tri < 0) | (tri >= ply.nvert)):
            raise CompareError(EXIT_UNREADABLE, "%s: face index out of range in faces %d..%d"
                               % (ply.path, s, e - 1))
        ix, iy = _ints(ply, lat, tri.ravel(), shift)
        rows = canonical(ix.reshape(-1, 3), iy.reshape(-1, 3))
        rec = np.empty(e - s, dtype=TRI_DTYPE)
        rec["t"] = rows
        tspill.add(rec, hash_rows([rows[:, k] for k in range(6)], tspill.nb))


def _diff(spa, spb):
    """Multiset difference per bucket: returns (only_a, only_b, examples_a, examples_b)."""
    only_a = only_b = 0
    ex_a, ex_b = [], []
    for ba, bb in zip(spa, spb):
        rows = np.concatenate([ba["t"], bb["t"]])
        if rows.shape[0] == 0:
            continue
        tag = np.concatenate([np.zeros(ba.shape[0], np.int64), np.ones(bb.shape[0], np.int64)])
        order = np.lexsort([tag] + [rows[:, k] for k in range(rows.shape[1] - 1, -1, -1)])
        rows, tag = rows[order], tag[order]
        start = np.ones(rows.shape[0], dtype=bool)
        start[1:] = np.any(rows[1:] != rows[:-1], axis=1)
        st = np.nonzero(start)[0]
        nb_ = np.add.reduceat(tag, st)
        size = np.diff(np.append(st, rows.shape[0]))
        d = (size - nb_) - nb_
        only_a += int(d[d > 0].sum())
        only_b += int(-d[d < 0].sum())
        for j in st[d > 0][:EXAMPLES - len(ex_a)]:
            ex_a.append(rows[j])
        for j in st[d < 0][:EXAMPLES - len(ex_b)]:
            ex_b.append(rows[j])
    return only_a, only_b, ex_a, ex_b


def _fmt(row):
    r = [int(v) for v in row]
    return " ".join("(%d, %d)" % (r[k], r[k + 1]) for k in range(0, len(r), 2))


def compare(path_a, path_b, quantum=None, chunk=1 << 20, tmpdir=None):
    """returns (exit code, list of output lines)."""
    try:
        a = PlyMesh(path_a)
        b = PlyMesh(path_b)
        la = _lattice(a, quantum)
        lb = _lattice(b, quantum)
        shift = _shift(la, lb)
        bucket_bytes = 48 * chunk
        nbt = buckets_for((a.nface + b.nface) * TRI_DTYPE.itemsize, 1, bucket_bytes)
        nbv = buckets_for((a.nvert + b.nvert) * VERT_DTYPE.itemsize, 1, bucket_bytes)
        with Spill(TRI_DTYPE, nbt, tmpdir) as ta, Spill(TRI_DTYPE, nbt, tmpdir) as tb, \
                Spill(VERT_DTYPE, nbv, tmpdir) as va, Spill(VERT_DTYPE, nbv, tmpdir) as vb:
            _fill(a, la, (0, 0), chunk, ta, va)
            _fill(b, lb, shift, chunk, tb, vb)
            ta_only, tb_only, exa, exb = _diff(ta, tb)
            va_only, vb_only, vexa, vexb = _diff(va, vb)
    except MeshFileError as e:
        return EXIT_UNREADABLE, ["ERROR: %s" % e]
    except CompareError as e:
        return e.code, ["ERROR: %s" % e]
    if not (ta_only or tb_only or va_only or vb_only):
        return EXIT_EQUAL, ["EQUAL: %d triangles, %d vertices" % (a.nface, a.nvert)]
    lines = ["DIFFERENT: triangles: %d only in A, %d only in B (A has %d, B has %d); "
             "vertices: %d only in A, %d only in B" % (ta_only, tb_only, a.nface, b.nface,
                                                        va_only, vb_only)]
    lines += ["  triangle only in A: %s" % _fmt(r) for r in exa]
    lines += ["  triangle only in B: %s" % _fmt(r) for r in exb]
    lines += ["  vertex only in A: %s" % _fmt(r) for r in vexa]
    lines += ["  vertex only in B: %s" % _fmt(r) for r in vexb]
    return EXIT_DIFFERENT, lines
