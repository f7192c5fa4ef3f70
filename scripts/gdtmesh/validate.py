"""Exact checker of a gdt-tile mesh (the engine of scripts/validate_mesh.py).

What is checked, all in exact integer arithmetic on the lattice integers:
  lattice     every vertex lies on the lattice of "comment lattice sx sy ox oy"
              (see gdtmesh.ply.to_lattice); otherwise nothing else is checked
  faces       every face has 3 indices, each in [0, V), pairwise distinct, and
              is strictly counter-clockwise (orient2d > 0)
  edges       every undirected edge lies in one face (boundary) or two faces
              that use it in opposite directions
  vertices    every vertex is in a face; no two vertices share a lattice point
  boundary    the boundary edges form one closed chain that turns only left or
              straight (never back) and winds around exactly once, i.e. a
              convex polygon; collinear boundary points are chain vertices
  area        the face areas sum exactly to the area enclosed by the chain
  Euler       F = 2V - h - 2, h = number of boundary (hull) vertices
  Delaunay    for every interior edge a-b with faces (a, b, c) and (b, a, d):
              d is not strictly inside circle(a, b, c); when d is on it (the
              quad a-d-b-c is then strictly convex) a-b must win the
              Dyken-Floater tie-break (d1 = (1, 0), d2 = (1, 1)) over c-d
  --input     the distinct (x, y) lattice points of the inputs are exactly the
              vertices
Why this suffices: with all faces counter-clockwise and every interior edge
shared by two faces on opposite sides, the number of faces covering a point
changes only across boundary edges; the chain is a convex polygon P, so the
count is constant inside P and 0 outside, and the exact area equality makes it
1.  Faces therefore tile P without overlap, and no vertex can lie inside a
face or on an edge without a double cover near it.  P contains every vertex
(each is in a face), so P is the convex hull.  Local Delaunay on every
interior edge of a triangulation makes it Delaunay (Lawson), and with the
tie-break it is the unique T_{d1,d2} (Dyken-Floater Thm 4.1).

Degenerate point sets: with V <= 2, or all vertices collinear, the only valid
mesh has no faces (F = 0) and h is reported as 0.  F = 0 with vertices that are
not all collinear is a violation.

Memory: vertices and faces are read through numpy.memmap in chunks of
`chunk` records.  Half-edges (12 bytes each, 3F of them) and vertex points
(24 bytes each; input points 16 bytes each) are spread over hash buckets in
temporary files of about 48 * chunk bytes each, and one bucket is processed
at a time.  Resident (anonymous) memory is therefore O(chunk) plus V bytes
(the vertex-use map) plus some 50 bytes per boundary edge, independent of F:
measured about 0.45-0.5 GB with the default chunk of 2^20 and 0.1 GB with
2^17, for meshes of 4.5 and 18 million faces alike; 10^8 faces thus need
about 0.5 GB + V bytes.  The mapped mesh file itself is read through the page
cache.  Temporary disk is about 36 F + 24 V + 16 (input points) bytes.  Time
is about 1.5 microseconds per face.  A grossly invalid mesh in which one edge
is shared by very many faces can make one bucket larger than the others.
"""
import math
import time

import numpy as np

from . import exact
from .cloudio import CloudError, CloudUnsupported, open_cloud
from .ply import Lattice, MeshFileError, PlyMesh, to_lattice
from .spill import Spill, buckets_for, hash_keys, hash_pairs

EXIT_OK, EXIT_FAIL, EXIT_USAGE, EXIT_UNREADABLE = 0, 1, 2, 3

EDGE_DTYPE = np.dtype([("k", "<i8"), ("o", "<i4")])
POINT_DTYPE = np.dtype([("x", "<i8"), ("y", "<i8"), ("i", "<i8")])
INPUT_DTYPE = np.dtype([("x", "<i8"), ("y", "<i8")])
_LO_SHIFT = 31
_HI_MASK = (1 << 31) - 1


class UsageError(Exception):
    pass


class Findings:
    """Violation counts per category, with the first example of each."""

    LABELS = (
        ("lattice", "vertices off the lattice"),
        ("arity", "faces that are not triangles"),
        ("index", "faces with a vertex index out of range"),
        ("repeat", "faces with a repeated vertex"),
        ("orient", "faces not strictly counter-clockwise"),
        ("edge_many", "edges in more than two faces"),
        ("edge_dir", "edges used twice in the same direction"),
        ("unused", "vertices in no face"),
        ("dup", "duplicate vertices (same lattice point)"),
        ("degenerate", "degenerate-set violations"),
        ("chain", "boundary chain defects"),
        ("convex", "non-convex boundary turns"),
        ("winding", "boundary winding defects"),
        ("area", "area mismatches"),
        ("euler", "Euler violations"),
        ("delaunay", "edges not locally Delaunay"),
        ("tiebreak", "co-circular edges losing the tie-break"),
        ("missing", "input points missing from the mesh"),
        ("extra", "vertices not in the input"),
    )

    def __init__(self):
        self.count = {}
        self.example = {}

    def add(self, cat, n=1, example=None):
        n = int(n)
        if n <= 0:
            return
        self.count[cat] = self.count.get(cat, 0) + n
        if example is not None and cat not in self.example:
            self.example[cat] = example

    def __bool__(self):
        return bool(self.count)

    def line(self):
        parts = []
        for cat, label in self.LABELS:
            if cat in self.count:
                ex = self.example.get(cat)
                parts.append("%d %s%s" % (self.count[cat], label, " (e.g. %s)" % ex if ex else ""))
        return "FAIL: " + "; ".join(parts)


class _Mesh:
    """The memory-mapped mesh plus exact integer access to its vertices."""

    def __init__(self, ply, lat):
        self.ply = ply
        self.lat = lat
        self.V = ply.nvert
        self.F = ply.nface

    def ints(self, idx):
        """Lattice integers of the vertices idx (already verified on-lattice)."""
        v = self.ply.vertices[idx]
        ix, iy, _ = to_lattice(self.lat, v["x"], v["y"])
        return ix, iy


def _pt(ix, iy, k):
    return "(%d, %d)" % (int(ix[k]), int(iy[k]))


def _resolve_lattice(ply, quantum):
    if ply.lattice is not None:
        if quantum is not None and (ply.lattice.sx != quantum or ply.lattice.sy != quantum):
            raise UsageError("--quantum %r disagrees with the mesh lattice (%r, %r)"
                             % (quantum, ply.lattice.sx, ply.lattice.sy))
        return ply.lattice
    if quantum is not None:
        return Lattice(quantum, quantum, 0.0, 0.0)
    return None


def _vertex_pass(m, fnd, chunk, pspill):
    """Lattice check, bounds, vertex points into pspill."""
    bounds = [math.inf, -math.inf, math.inf, -math.inf]
    for s in range(0, m.V, chunk):
        e = min(m.V, s + chunk)
        v = m.ply.vertices[s:e]
        x = np.asarray(v["x"], dtype=np.float64)
        y = np.asarray(v["y"], dtype=np.float64)
        ix, iy, bad = to_lattice(m.lat, x, y)
        if np.any(bad):
            k = int(np.nonzero(bad)[0][0])
            fnd.add("lattice", np.count_nonzero(bad),
                    "vertex %d at (%r, %r)" % (s + k, float(x[k]), float(y[k])))
            continue
        bounds = [min(bounds[0], float(x.min())), max(bounds[1], float(x.max())),
                  min(bounds[2], float(y.min())), max(bounds[3], float(y.max()))]
        if pspill is not None:
            rec = np.empty(e - s, dtype=POINT_DTYPE)
            rec["x"] = ix
            rec["y"] = iy
            rec["i"] = np.arange(s, e, dtype=np.int64)
            pspill.add(rec, hash_pairs(ix, iy, pspill.nb))
    return tuple(bounds) if m.V else None


def _unique_rows(x, y):
    """Sorted distinct (x, y) rows."""
    if x.shape[0] == 0:
        return x, y
    order = np.lexsort((y, x))
    x, y = x[order], y[order]
    keep = np.ones(x.shape[0], dtype=bool)
    keep[1:] = (x[1:] != x[:-1]) | (y[1:] != y[:-1])
    return x[keep], y[keep]


def _input_pass(inputs, lat, chunk, ispill, mesh_bounds):
    """Input points (distinct per chunk) into ispill; returns (points read, files)."""
    total = 0
    for cloud in inputs:
        for ix, iy in cloud.chunks(lat, chunk, mesh_bounds):
            total += ix.shape[0]
            ux, uy = _unique_rows(ix, iy)
            rec = np.empty(ux.shape[0], dtype=INPUT_DTYPE)
            rec["x"] = ux
            rec["y"] = uy
            ispill.add(rec, hash_pairs(ux, uy, ispill.nb))
    return total


def _point_sets(fnd, pspill, ispill):
    """Duplicate vertices; with inputs, equality of the point sets.
    returns the number of distinct input points (0 without inputs)."""
    distinct_in = 0
    ibuckets = iter(ispill) if ispill is not None else None
    for pb in pspill:
        order = np.lexsort((pb["y"], pb["x"]))
        px, py, pi = pb["x"][order], pb["y"][order], pb["i"][order]
        if px.shape[0] > 1:
            same = (px[1:] == px[:-1]) & (py[1:] == py[:-1])
            if np.any(same):
                k = int(np.nonzero(same)[0][0])
                fnd.add("dup", np.count_nonzero(same),
                        "vertices %d and %d at lattice %s" % (int(pi[k]), int(pi[k + 1]), _pt(px, py, k)))
        if ibuckets is None:
            continue
        ib = next(ibuckets)
        ux, uy = _unique_rows(ib["x"], ib["y"])
        distinct_in += ux.shape[0]
        vx, vy = _unique_rows(px, py)
        ax = np.concatenate([vx, ux])
        ay = np.concatenate([vy, uy])
        tag = np.concatenate([np.zeros(vx.shape[0], np.int8), np.ones(ux.shape[0], np.int8)])
        if ax.shape[0] == 0:
            continue
        order = np.lexsort((tag, ay, ax))
        ax, ay, tag = ax[order], ay[order], tag[order]
        start = np.ones(ax.shape[0], dtype=bool)
        start[1:] = (ax[1:] != ax[:-1]) | (ay[1:] != ay[:-1])
        st = np.nonzero(start)[0]
        gmin = np.minimum.reduceat(tag, st)
        gmax = np.maximum.reduceat(tag, st)
        only_v = st[gmax == 0]
        only_i = st[gmin == 1]
        if only_i.size:
            fnd.add("missing", only_i.size, "lattice point %s" % _pt(ax, ay, only_i[0]))
        if only_v.size:
            fnd.add("extra", only_v.size, "lattice point %s" % _pt(ax, ay, only_v[0]))
    return distinct_in


def _face_pass(m, fnd, chunk, espill, used, st):
    """Face checks, exact area sum, vertex use, half-edges into espill.
    returns twice the total signed face area (Python int)."""
    area2 = 0
    for s in range(0, m.F, chunk):
        e = min(m.F, s + chunk)
        f = m.ply.faces[s:e]
        n = np.asarray(f["n"])
        tri = np.asarray(f["v"], dtype=np.int64)
        fid = np.arange(s, e, dtype=np.int64)
        bad = n != 3
        if np.any(bad):
            k = int(np.nonzero(bad)[0][0])
            fnd.add("arity", np.count_nonzero(bad), "face %d has %d indices" % (s + k, int(n[k])))
        oor = ~bad & np.any((tri < 0) | (tri >= m.V), axis=1)
        if np.any(oor):
            k = int(np.nonzero(oor)[0][0])
            fnd.add("index", np.count_nonzero(oor), "face %d = %s" % (s + k, tri[k].tolist()))
        rep = ~bad & ~oor & ((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 0] == tri[:, 2]))
        if np.any(rep):
            k = int(np.nonzero(rep)[0][0])
            fnd.add("repeat", np.count_nonzero(rep), "face %d = %s" % (s + k, tri[k].tolist()))
        ok = ~(bad | oor | rep)
        tri = tri[ok]
        fid = fid[ok]
        if tri.shape[0] == 0:
            continue
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ax, ay = m.ints(a)
        bx, by = m.ints(b)
        cx, cy = m.ints(c)
        sg = exact.orient_sign(ax, ay, bx, by, cx, cy, st)
        inv = sg <= 0
        if np.any(inv):
            k = int(np.nonzero(inv)[0][0])
            fnd.add("orient", np.count_nonzero(inv), "face %d = %s is %s" % (
                int(fid[k]), tri[k].tolist(), "clockwise" if sg[k] < 0 else "degenerate"))
        area2 += exact.orient_det_sum(ax, ay, bx, by, cx, cy)
        used[a] = True
        used[b] = True
        used[c] = True
        # Half-edge u->v of face (u, v, w): key (min, max), opposite vertex w,
        # stored as ~w when u > v so the direction survives.
        u = np.concatenate([a, b, c])
        v = np.concatenate([b, c, a])
        w = np.concatenate([c, a, b])
        lo = np.minimum(u, v)
        hi = np.maximum(u, v)
        rec = np.empty(u.shape[0], dtype=EDGE_DTYPE)
        rec["k"] = (lo << _LO_SHIFT) | hi
        rec["o"] = np.where(u < v, w, ~w)
        espill.add(rec, hash_keys(rec["k"], espill.nb))
    return area2


def _delaunay(m, fnd, a, b, c, d, st):
    """Local Delaunay + tie-break of interior edges a-b with CCW faces
    (a, b, c) and (b, a, d)."""
    ax, ay = m.ints(a)
    bx, by = m.ints(b)
    cx, cy = m.ints(c)
    dx, dy = m.ints(d)
    ins = exact.incircle_sign(ax, ay, bx, by, cx, cy, dx, dy, st)
    viol = ins > 0
    if np.any(viol):
        k = int(np.nonzero(viol)[0][0])
        fnd.add("delaunay", np.count_nonzero(viol),
                "edge %d-%d: vertex %d strictly inside the circle of %d, %d, %d"
                % (a[k], b[k], d[k], a[k], b[k], c[k]))
    on = np.nonzero(ins == 0)[0]
    if on.size == 0:
        return
    ax, ay, bx, by, cx, cy, dx, dy = (t[on] for t in (ax, ay, bx, by, cx, cy, dx, dy))
    # Quad a-d-b-c (counter-clockwise) strictly convex: also d-b-c and c-a-d turn left.
    convex = ((exact.orient_sign(dx, dy, bx, by, cx, cy) > 0)
              & (exact.orient_sign(cx, cy, ax, ay, dx, dy) > 0))
    q = np.nonzero(convex)[0]
    if q.size == 0:
        return
    tb = exact.tiebreak_sign(bx[q] - ax[q], by[q] - ay[q], dx[q] - cx[q], dy[q] - cy[q], st)
    lose = tb < 0
    if np.any(lose):
        k = int(on[q[np.nonzero(lose)[0][0]]])
        fnd.add("tiebreak", np.count_nonzero(lose),
                "edge %d-%d should be %d-%d (co-circular quad)" % (a[k], b[k], c[k], d[k]))


def _edge_pass(m, fnd, chunk, espill, st):
    """Edge multiplicity/direction, Delaunay on interior edges; returns
    (interior edges checked, boundary src array, boundary dst array)."""
    n_int = 0
    bsrc, bdst = [], []
    for eb in espill:
        if eb.shape[0] == 0:
            continue
        order = np.argsort(eb["k"], kind="stable")
        k = eb["k"][order]
        o = eb["o"][order].astype(np.int64)
        del eb, order
        start = np.ones(k.shape[0], dtype=bool)
        start[1:] = k[1:] != k[:-1]
        s = np.nonzero(start)[0]
        lens = np.diff(np.append(s, k.shape[0]))
        many = lens > 2
        if np.any(many):
            j = int(np.nonzero(many)[0][0])
            fnd.add("edge_many", np.count_nonzero(many), "edge %d-%d in %d faces" % (
                int(k[s[j]]) >> _LO_SHIFT, int(k[s[j]]) & _HI_MASK, int(lens[j])))
        one = s[lens == 1]
        if one.size:
            kk = k[one]
            oo = o[one]
            lo = kk >> _LO_SHIFT
            hi = kk & _HI_MASK
            fwd = oo >= 0
            bsrc.append(np.where(fwd, lo, hi))
            bdst.append(np.where(fwd, hi, lo))
        two = s[lens == 2]
        if two.size == 0:
            continue
        o1 = o[two]
        o2 = o[two + 1]
        same = (o1 >= 0) == (o2 >= 0)
        if np.any(same):
            j = int(np.nonzero(same)[0][0])
            kk = int(k[two[j]])
            fnd.add("edge_dir", np.count_nonzero(same),
                    "edge %d-%d" % (kk >> _LO_SHIFT, kk & _HI_MASK))
        good = ~same
        kk = k[two][good]
        o1 = o1[good]
        o2 = o2[good]
        lo = kk >> _LO_SHIFT
        hi = kk & _HI_MASK
        c = np.where(o1 >= 0, o1, o2)
        d = ~np.where(o1 >= 0, o2, o1)
        del k, o
        n_int += lo.shape[0]
        for t in range(0, lo.shape[0], chunk):
            sl = slice(t, t + chunk)
            _delaunay(m, fnd, lo[sl], hi[sl], c[sl], d[sl], st)
    src = np.concatenate(bsrc) if bsrc else np.zeros(0, np.int64)
    dst = np.concatenate(bdst) if bdst else np.zeros(0, np.int64)
    return n_int, src, dst


def _half(dx, dy):
    """0 for directions with angle in [0, pi), 1 for [pi, 2 pi)."""
    return np.where((dy > 0) | ((dy == 0) & (dx > 0)), 0, 1)


def _boundary(m, fnd, src, dst, st):
    """Chain, convexity and winding of the boundary; returns (h, twice the
    enclosed area) or None when the chain is broken."""
    nb = src.shape[0]
    if nb == 0:
        fnd.add("chain", 1, "no boundary edges")
        return None
    ss = np.sort(src)
    ds = np.sort(dst)
    if np.any(ss[1:] == ss[:-1]):
        k = int(ss[1:][ss[1:] == ss[:-1]][0])
        fnd.add("chain", 1, "vertex %d starts two boundary edges" % k)
        return None
    if np.any(ds[1:] == ds[:-1]):
        k = int(ds[1:][ds[1:] == ds[:-1]][0])
        fnd.add("chain", 1, "vertex %d ends two boundary edges" % k)
        return None
    if not np.array_equal(ss, ds):
        k = int(np.setdiff1d(ds, ss)[0]) if np.setdiff1d(ds, ss).size else int(np.setdiff1d(ss, ds)[0])
        fnd.add("chain", 1, "boundary is open at vertex %d" % k)
        return None
    order = np.argsort(src)
    succ = order[np.searchsorted(src[order], dst)]
    succ_l = succ.tolist()
    seq = [0]
    e = succ_l[0]
    while e != 0 and len(seq) <= nb:
        seq.append(e)
        e = succ_l[e]
    if len(seq) != nb:
        fnd.add("chain", 1, "boundary has several loops (%d of %d edges in the first)" % (len(seq), nb))
        return None
    verts = src[np.array(seq, dtype=np.int64)]
    px, py = m.ints(verts)
    nx, ny = np.roll(px, -1), np.roll(py, -1)
    # Directions of edges i (p_i -> p_i+1) and i+1.
    ex, ey = nx - px, ny - py
    fx, fy = np.roll(ex, -1), np.roll(ey, -1)
    turn = exact.orient_sign(px, py, nx, ny, np.roll(nx, -1), np.roll(ny, -1), st)
    back = (turn == 0) & ((np.sign(ex) != np.sign(fx)) | (np.sign(ey) != np.sign(fy)))
    bad = (turn < 0) | back
    if np.any(bad):
        k = int(np.nonzero(bad)[0][0])
        v = int(verts[(k + 1) % nb])
        fnd.add("convex", np.count_nonzero(bad), "at boundary vertex %d %s" % (
            v, "(turns right)" if turn[k] < 0 else "(turns back)"))
        return None
    he, hf = _half(ex, ey), _half(fx, fy)
    cross = exact.orient_sign(np.zeros_like(ex), np.zeros_like(ex), ex, ey, fx, fy)
    less = (hf < he) | ((hf == he) & (cross < 0))
    wraps = int(np.count_nonzero(less))
    if wraps != 1:
        fnd.add("winding", 1, "the boundary winds %d times around the hull" % wraps)
        return None
    zero = np.zeros(nb, dtype=np.int64)
    area2 = exact.orient_det_sum(zero + px[0], zero + py[0], px, py, nx, ny)
    return nb, area2


def _all_collinear(m, chunk):
    """True if all vertices lie on one line (or V <= 2)."""
    if m.V <= 2:
        return True
    ax, ay = m.ints(np.array([0]))
    b = None
    for s in range(0, m.V, chunk):
        e = min(m.V, s + chunk)
        ix, iy = m.ints(np.arange(s, e))
        if b is None:
            diff = np.nonzero((ix != ax[0]) | (iy != ay[0]))[0]
            if diff.size == 0:
                continue
            b = (ix[diff[0]], iy[diff[0]])
        n = ix.shape[0]
        sg = exact.orient_sign(np.full(n, ax[0]), np.full(n, ay[0]), np.full(n, b[0]),
                               np.full(n, b[1]), ix, iy)
        if np.any(sg != 0):
            return False
    return True


def validate(mesh_path, inputs=(), quantum=None, chunk=1 << 20, tmpdir=None, log=None):
    """Checks one mesh.  returns (exit code, summary line).

    Exit codes: 0 valid, 1 violation, 2 usage, 3 unreadable mesh or input.
    log: a file for progress/statistics lines (None: silent)."""
    t0 = time.time()
    chunk = int(chunk)
    if chunk < 1:
        return EXIT_USAGE, "ERROR: --chunk must be >= 1"
    bucket_bytes = 48 * chunk
    st = exact.Stats()
    fnd = Findings()

    def note(msg):
        if log is not None:
            print("validate_mesh: %.1fs: %s" % (time.time() - t0, msg), file=log)

    try:
        ply = PlyMesh(mesh_path)
    except MeshFileError as e:
        return EXIT_UNREADABLE, "ERROR: %s" % e
    try:
        lat = _resolve_lattice(ply, quantum)
    except UsageError as e:
        return EXIT_USAGE, "ERROR: %s" % e
    if lat is None:
        return EXIT_FAIL, "FAIL: %s: %s (give --quantum to assume one)" % (mesh_path, ply.lattice_problem)
    try:
        clouds = [open_cloud(p) for p in inputs]
    except CloudError as e:
        return EXIT_UNREADABLE, "ERROR: %s" % e
    m = _Mesh(ply, lat)
    note("%d vertices, %d faces, lattice %r" % (m.V, m.F, tuple(lat)))

    in_hint = sum(c.count_hint for c in clouds)
    nbp = buckets_for(m.V * POINT_DTYPE.itemsize + in_hint * INPUT_DTYPE.itemsize, 1, bucket_bytes)
    with Spill(POINT_DTYPE, nbp, tmpdir) as pspill:
        bounds = _vertex_pass(m, fnd, chunk, pspill)
        if "lattice" in fnd.count:
            return EXIT_FAIL, fnd.line()
        note("vertex pass done (%d point buckets)" % nbp)
        n_in = distinct_in = 0
        ispill = Spill(INPUT_DTYPE, nbp, tmpdir) if clouds else None
        try:
            if clouds:
                try:
                    n_in = _input_pass(clouds, lat, chunk, ispill, bounds)
                except CloudError as e:
                    return EXIT_UNREADABLE, "ERROR: %s" % e
                except CloudUnsupported as e:
                    return EXIT_USAGE, "ERROR: %s" % e
                note("input pass done (%d points)" % n_in)
            distinct_in = _point_sets(fnd, pspill, ispill)
        finally:
            if ispill is not None:
                ispill.close()
    note("point sets compared")

    h = 0
    n_int = 0
    degenerate_note = ""
    if m.F == 0:
        if m.V == 0:
            degenerate_note = " (empty mesh)"
        elif _all_collinear(m, chunk):
            degenerate_note = " (%s: no triangles)" % (
                "fewer than 3 vertices" if m.V < 3 else "all vertices collinear")
        else:
            fnd.add("degenerate", 1, "no faces although the %d vertices are not collinear" % m.V)
    else:
        used = np.zeros(m.V, dtype=bool)
        nbe = buckets_for(3 * m.F, EDGE_DTYPE.itemsize, bucket_bytes)
        with Spill(EDGE_DTYPE, nbe, tmpdir) as espill:
            area2 = _face_pass(m, fnd, chunk, espill, used, st)
            note("face pass done (%d edge buckets)" % nbe)
            unused = np.nonzero(~used)[0]
            if unused.size:
                fnd.add("unused", unused.size, "vertex %d" % int(unused[0]))
            del used
            n_int, src, dst = _edge_pass(m, fnd, chunk, espill, st)
        note("edge pass done: %d interior, %d boundary edges; %r" % (n_int, src.shape[0], st))
        bd = _boundary(m, fnd, src, dst, st)
        if bd is not None:
            h, hull2 = bd
            if hull2 != area2:
                fnd.add("area", 1, "faces cover %s, the hull %s (twice the area, lattice units)"
                        % (area2, hull2))
            if m.F != 2 * m.V - h - 2:
                fnd.add("euler", 1, "F = %d but 2V - h - 2 = %d" % (m.F, 2 * m.V - h - 2))
    if fnd:
        return EXIT_FAIL, fnd.line()
    line = "OK: %d vertices, %d faces, %d hull vertices, %d interior edges checked%s" % (
        m.V, m.F, h, n_int, degenerate_note)
    if clouds:
        line += "; input: %d points, %d distinct, all present" % (n_in, distinct_in)
    return EXIT_OK, line
