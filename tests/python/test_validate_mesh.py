"""Tests of scripts/validate_mesh.py and scripts/compare_meshes.py.

Valid triangulations are built here independently of the validator:
  - brute_tdd(): the unique Dyken-Floater triangulation T_{d1,d2} of a small
    point set from its global characterisation (Thm 3.3 per Delaunay tile):
    a segment is a candidate when some circle through its ends has no point
    strictly inside; the result keeps the candidates that no lower-scoring
    candidate crosses.  This is a different characterisation from the
    validator's local test (Thm 4.1), computed with Python integers and
    Fractions.
  - hand-built grids: the square grid with (1,1) diagonals and the grid with
    basis (3,4), (-4,3) and (7,1) diagonals.
Meshes are written with plyfile (not the scripts' own reader), inputs with
laspy and with a small PCD writer here.  Planted faults must be caught.
"""
import itertools
import pathlib
import random
import re
import struct
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from conftest import build_dir

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"
sys.path.insert(0, str(SCRIPTS))

from gdtmesh import exact  # noqa: E402

LAT = (0.001, 0.001, 0.0, 0.0)


# ------------------------------------------------------------------ helpers

def run_script(name, *args):
    return subprocess.run([sys.executable, str(SCRIPTS / name)] + [str(a) for a in args],
                          capture_output=True, text=True, timeout=300)


def validate(*args):
    return run_script("validate_mesh.py", *args)


def compare(*args):
    return run_script("compare_meshes.py", *args)


def write_mesh(path, pts, faces, lattice=LAT, comments=None, coords=None):
    """PLY through plyfile: vertex x = ox + sx * X (or raw coords when given)."""
    from plyfile import PlyData, PlyElement
    sx, sy, ox, oy = lattice
    v = np.zeros(len(pts), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    if coords is not None:
        v["x"] = [c[0] for c in coords]
        v["y"] = [c[1] for c in coords]
    elif len(pts):
        P = np.array(pts, dtype=np.float64)
        v["x"] = ox + sx * P[:, 0]
        v["y"] = oy + sy * P[:, 1]
    v["z"] = np.arange(len(pts)) * 0.5
    f = np.zeros(len(faces), dtype=[("vertex_indices", "<i4", (3,))])
    if len(faces):
        f["vertex_indices"] = np.array(faces, dtype=np.int32)
    if comments is None:
        comments = ["generator test", "crs unknown", "lattice %.17g %.17g %.17g %.17g" % lattice]
    PlyData([PlyElement.describe(v, "vertex"),
             PlyElement.describe(f, "face", len_types={"vertex_indices": "u1"},
                                 val_types={"vertex_indices": "i4"})],
            text=False, byte_order="<", comments=comments).write(str(path))
    return path


def orient(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


def score_lower(e, f):
    """score(e) < score(f) in the Dyken-Floater sense (d1 = (1,0), d2 = (1,1)),
    from the cosine comparison of the paper, in Python integers."""
    for d in ((1, 0), (1, 1)):
        lhs = (e[0] * d[0] + e[1] * d[1]) ** 2 * (f[0] ** 2 + f[1] ** 2)
        rhs = (f[0] * d[0] + f[1] * d[1]) ** 2 * (e[0] ** 2 + e[1] ** 2)
        if lhs != rhs:
            return lhs > rhs
    return False


def empty_circle_exists(P, i, j):
    """Some circle through P[i], P[j] has no point strictly inside."""
    p, q = P[i], P[j]
    lo = hi = None
    for k, r in enumerate(P):
        if k in (i, j):
            continue
        o = orient(p, q, r)
        if o == 0:
            if min(p[0], q[0]) <= r[0] <= max(p[0], q[0]) and min(p[1], q[1]) <= r[1] <= max(p[1], q[1]):
                return False
            continue
        # Centre c(t) = (p + q)/2 + t n with n = perp(q - p), so n.(r - p) =
        # orient(p, q, r); r is not strictly inside iff A + B t <= 0.
        A = ((p[0] + q[0]) * (r[0] - p[0]) + (p[1] + q[1]) * (r[1] - p[1])
             - (r[0] ** 2 + r[1] ** 2 - p[0] ** 2 - p[1] ** 2))
        B = 2 * o
        bound = Fraction(-A, B)
        if B > 0:
            hi = bound if hi is None else min(hi, bound)
        else:
            lo = bound if lo is None else max(lo, bound)
    return lo is None or hi is None or lo <= hi


def crosses(a, b, c, d):
    return orient(a, b, c) * orient(a, b, d) < 0 and orient(c, d, a) * orient(c, d, b) < 0


def brute_tdd(P):
    """T_{d1,d2}(P) as a list of CCW index triples (P: distinct integer points)."""
    n = len(P)
    cand = [(i, j) for i, j in itertools.combinations(range(n), 2) if empty_circle_exists(P, i, j)]
    vec = {e: (P[e[1]][0] - P[e[0]][0], P[e[1]][1] - P[e[0]][1]) for e in cand}
    keep = set()
    for e in cand:
        if not any(crosses(P[e[0]], P[e[1]], P[f[0]], P[f[1]]) and score_lower(vec[f], vec[e])
                   for f in cand if f != e):
            keep.add(e)
    faces = []
    for i, j, k in itertools.combinations(range(n), 3):
        if (i, j) in keep and (j, k) in keep and (i, k) in keep:
            o = orient(P[i], P[j], P[k])
            if o == 0:
                continue
            t = (i, j, k) if o > 0 else (i, k, j)
            a, b, c = (P[v] for v in t)
            if not any(orient(a, b, r) > 0 and orient(b, c, r) > 0 and orient(c, a, r) > 0
                       for r in P):
                faces.append(t)
    return faces


def hull_size(P):
    """Hull vertices including collinear boundary points."""
    pts = sorted(set(P))
    if len(pts) < 3:
        return len(pts)

    def chain(seq):
        h = []
        for p in seq:
            while len(h) >= 2 and orient(h[-2], h[-1], p) < 0:
                h.pop()
            h.append(p)
        return h
    lower, upper = chain(pts), chain(pts[::-1])
    return len(lower) + len(upper) - 2


def random_points(rng, n, span):
    pts = set()
    while len(pts) < n:
        pts.add((rng.randrange(span), rng.randrange(span)))
    return sorted(pts)


def grid_mesh(k, u=(1, 0), v=(0, 1), base=(0, 0), diag="11"):
    """k x k grid base + i u + j v; diag '11' splits cells along p00-p11,
    otherwise along p10-p01.  Returns (points, CCW faces)."""
    pts = [(base[0] + i * u[0] + j * v[0], base[1] + i * u[1] + j * v[1])
           for i in range(k) for j in range(k)]
    faces = []
    for i in range(k - 1):
        for j in range(k - 1):
            p00, p10, p01, p11 = i * k + j, (i + 1) * k + j, i * k + j + 1, (i + 1) * k + j + 1
            if diag == "11":
                faces += [(p00, p10, p11), (p00, p11, p01)]
            else:
                faces += [(p00, p10, p01), (p10, p11, p01)]
    return pts, faces


def flip_edge(faces, a, b):
    """Replaces the two faces on edge a-b by the other diagonal."""
    sides = [t for t in faces if a in t and b in t]
    assert len(sides) == 2
    f1, f2 = sides
    c = next(v for v in f1 if v not in (a, b))
    d = next(v for v in f2 if v not in (a, b))
    rest = [t for t in faces if t not in sides]
    # f1 holds a->b or b->a; rebuild CCW from f1's orientation.
    i = f1.index(a)
    if f1[(i + 1) % 3] == b:      # f1 = (a, b, c) CCW, f2 = (b, a, d)
        return rest + [(a, d, c), (d, b, c)]
    return rest + [(b, d, c), (d, a, c)]


def ok_counts(out):
    assert out.returncode == 0, out.stdout + out.stderr
    line = out.stdout.strip()
    assert line.startswith("OK: ") and "\n" not in line
    w = line[4:].split()
    return int(w[0]), int(w[2]), int(w[4]), int(w[7])


def assert_fail(out, *phrases):
    assert out.returncode == 1, out.stdout + out.stderr
    line = out.stdout.strip()
    assert line.startswith("FAIL: ") and "\n" not in line, line
    for p in phrases:
        assert p in line, line
    return line


# ------------------------------------------------------------------ exact predicates

def test_exact_predicates_agree_with_python_integers():
    rng = random.Random(7)
    rows = []
    for scale in (8, 1 << 14, 1 << 16, 1 << 20, 1 << 26, 1 << 31, 1 << 44, (1 << 53) - 1):
        for _ in range(400):
            kind = rng.randrange(3)
            if kind == 0:
                q = [(rng.randrange(-scale, scale), rng.randrange(-scale, scale)) for _ in range(4)]
            elif kind == 1:           # co-circular: rotated square around a centre
                cx, cy = rng.randrange(-scale // 2, scale // 2), rng.randrange(-scale // 2, scale // 2)
                m = rng.randrange(1, max(2, scale // 40))
                a, b = 3 * m, 4 * m
                q = [(cx + a, cy + b), (cx - b, cy + a), (cx - a, cy - b), (cx + b, cy - a)]
                rng.shuffle(q)
                if rng.random() < 0.3:
                    q[3] = (q[3][0] + 1, q[3][1])
            else:                     # collinear
                ax, ay = rng.randrange(-scale // 2, scale // 2), rng.randrange(-scale // 2, scale // 2)
                dx, dy = rng.randrange(-99, 99), rng.randrange(-99, 99)
                q = [(ax + t * dx, ay + t * dy) for t in (rng.randrange(-9, 9) for _ in range(4))]
            rows.append(q)
    A = np.array(rows, dtype=np.int64)
    ins = exact.incircle_sign(*(A[:, i // 2, i % 2] for i in range(8)))
    ors = exact.orient_sign(*(A[:, i // 2, i % 2] for i in range(6)))
    e = A[:, 1] - A[:, 0]
    f = A[:, 3] - A[:, 2]
    tb = exact.tiebreak_sign(e[:, 0], e[:, 1], f[:, 0], f[:, 1])
    area = exact.orient_det_sum(*(A[:, i // 2, i % 2] for i in range(6)))

    def sgn(v):
        return (v > 0) - (v < 0)
    total = 0
    for k, q in enumerate(rows):
        q = [(int(x), int(y)) for x, y in A[k]]
        (ax, ay), (bx, by), (cx, cy), (dx, dy) = q
        det = ((ax - dx) ** 2 + (ay - dy) ** 2) * orient((bx - dx, by - dy), (cx - dx, cy - dy), (0, 0)) \
            + ((bx - dx) ** 2 + (by - dy) ** 2) * orient((cx - dx, cy - dy), (ax - dx, ay - dy), (0, 0)) \
            + ((cx - dx) ** 2 + (cy - dy) ** 2) * orient((ax - dx, ay - dy), (bx - dx, by - dy), (0, 0))
        assert ins[k] == sgn(det), q
        assert ors[k] == sgn(orient(*q[:3])), q
        total += orient(*q[:3])
        ev, fv = (bx - ax, by - ay), (dx - cx, dy - cy)
        want = 1 if score_lower(ev, fv) else (-1 if score_lower(fv, ev) else 0)
        assert tb[k] == want, (ev, fv)
    assert area == total
    # All three results must occur, or the test proves little.
    assert set(ins.tolist()) == {-1, 0, 1} and set(tb.tolist()) >= {-1, 1}


@pytest.mark.parametrize("which", [2, 4])
def test_incircle_tiers_on_near_cocircular_points(which):
    """Three consecutive lattice points of a circle of radius ~2^25.5 or ~2^30
    and a fourth point just off the circle: determinants far below the
    filter's error bound, decided by the wrap-around int64 and the
    Python-integer tiers.  Every sign must match Python integers."""
    import math
    from gdtmesh import degenerate
    _, factors = degenerate.CIRCLE_RADII[which]
    C = sorted(degenerate.circle_points(factors), key=lambda p: math.atan2(p[1], p[0]))
    rng = random.Random(which)
    rows = []
    for _ in range(1500):
        i = rng.randrange(len(C))
        p = C[rng.randrange(len(C))]
        s = rng.choice([0, 1, 2, 4, 16, 256, 4096, 1 << 16])
        rows.append([C[i], C[(i + 1) % len(C)], C[(i + 2) % len(C)],
                     (p[0] + s * rng.choice([-1, 1]), p[1])])
    A = np.array(rows, dtype=np.int64)
    st = exact.Stats()
    got = exact.incircle_sign(*(A[:, i // 2, i % 2] for i in range(8)), stats=st)
    for k, q in enumerate(rows):
        (ax, ay), (bx, by), (cx, cy), (dx, dy) = q
        a, b, c = (ax - dx, ay - dy), (bx - dx, by - dy), (cx - dx, cy - dy)
        det = ((a[0] ** 2 + a[1] ** 2) * (b[0] * c[1] - c[0] * b[1])
               + (b[0] ** 2 + b[1] ** 2) * (c[0] * a[1] - a[0] * c[1])
               + (c[0] ** 2 + c[1] ** 2) * (a[0] * b[1] - b[0] * a[1]))
        assert got[k] == (det > 0) - (det < 0), q
    assert st.incircle_filtered > 0 and st.incircle_int64 > 0 and st.incircle_bigint > 0, st
    assert set(got.tolist()) == {-1, 0, 1}


# ------------------------------------------------------------------ valid meshes pass

def test_brute_force_builder_matches_hand_built_grid(tmp_path):
    pts, faces = grid_mesh(4)
    assert sorted(tuple(sorted(t)) for t in brute_tdd(pts)) == sorted(tuple(sorted(t)) for t in faces)
    pts, faces = grid_mesh(4, u=(3, 4), v=(-4, 3), diag="other")
    assert sorted(tuple(sorted(t)) for t in brute_tdd(pts)) == sorted(tuple(sorted(t)) for t in faces)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_valid_random_triangulations_pass(tmp_path, seed):
    rng = random.Random(seed)
    P = random_points(rng, 30, 1000)
    faces = brute_tdd(P)
    h = hull_size(P)
    assert len(faces) == 2 * len(P) - h - 2
    # Shuffle vertex order, face order and the rotation of each face.
    perm = list(range(len(P)))
    rng.shuffle(perm)
    inv = {old: new for new, old in enumerate(perm)}
    pts = [P[old] for old in perm]
    fs = []
    for t in faces:
        r = rng.randrange(3)
        t = t[r:] + t[:r]
        fs.append(tuple(inv[v] for v in t))
    rng.shuffle(fs)
    mesh = write_mesh(tmp_path / "m.ply", pts, fs)
    V, F, hh, E = ok_counts(validate(mesh))
    assert (V, F, hh) == (len(P), len(faces), h)
    assert E == (3 * F - h) // 2


def cocircular_sets():
    rng = random.Random(11)
    circle = [(x, y) for x in range(-65, 66) for y in range(-65, 66) if x * x + y * y == 65 * 65]
    grid_subset = [(x, y) for x in range(7) for y in range(7) if rng.random() < 0.7]
    rot = [(3 * i - 4 * j, 4 * i + 3 * j) for i in range(4) for j in range(4)]
    rot_subset = [p for p in rot if rng.random() < 0.8]
    mixed = circle[::3] + [(0, 0), (10, 0), (0, 10), (-10, 0)]
    return {"circle": circle, "grid_subset": grid_subset, "rot_subset": rot_subset,
            "circle_and_centre": mixed}


@pytest.mark.parametrize("name", sorted(cocircular_sets()))
def test_valid_cocircular_triangulations_pass(tmp_path, name):
    P = cocircular_sets()[name]
    faces = brute_tdd(P)
    assert len(faces) == 2 * len(P) - hull_size(P) - 2
    V, F, h, _ = ok_counts(validate(write_mesh(tmp_path / "m.ply", P, faces)))
    assert (V, F, h) == (len(P), len(faces), hull_size(P))


def test_hand_built_grids_pass(tmp_path):
    pts, faces = grid_mesh(6)
    assert ok_counts(validate(write_mesh(tmp_path / "g.ply", pts, faces)))[:3] == (36, 50, 20)
    pts, faces = grid_mesh(6, u=(3, 4), v=(-4, 3), diag="other")
    assert ok_counts(validate(write_mesh(tmp_path / "r.ply", pts, faces)))[:3] == (36, 50, 20)


def test_real_world_lattice_and_padded_header(tmp_path):
    """UTM-like lattice (0.01, offsets 5e5 / 4e6) and a header written the way
    gdt-tile writes it (counts padded to 20 characters)."""
    rng = random.Random(5)
    P = random_points(rng, 25, 5000)
    faces = brute_tdd(P)
    lat = (0.01, 0.01, 500000.0, 4000000.0)
    v = np.zeros(len(P), dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    v["x"] = [lat[2] + lat[0] * p[0] for p in P]
    v["y"] = [lat[3] + lat[1] * p[1] for p in P]
    f = np.zeros(len(faces), dtype=[("n", "u1"), ("v", "<i4", (3,))])
    f["n"] = 3
    f["v"] = faces
    head = ("ply\nformat binary_little_endian 1.0\ncomment generator gdt-tile 0.1.0\n"
            "comment crs EPSG:32610\ncomment lattice 0.01 0.01 500000 4000000\n"
            "element vertex %-20d\nproperty double x\nproperty double y\nproperty double z\n"
            "element face %-20d\nproperty list uchar int vertex_indices\nend_header\n"
            % (len(P), len(faces)))
    path = tmp_path / "utm.ply"
    path.write_bytes(head.encode() + v.tobytes() + f.tobytes())
    assert ok_counts(validate(path))[:2] == (len(P), len(faces))


def test_extreme_int32_coordinates(tmp_path):
    lo, hi = -(1 << 31), (1 << 31) - 1
    rng = random.Random(3)
    P = [(lo, lo), (hi, lo), (lo, hi), (hi, hi)]
    P += [(lo + rng.randrange(50), lo + rng.randrange(50)) for _ in range(6)]
    P += [(hi - rng.randrange(50), hi - rng.randrange(50)) for _ in range(6)]
    P = sorted(set(P))
    faces = brute_tdd(P)
    assert len(faces) == 2 * len(P) - hull_size(P) - 2
    assert ok_counts(validate(write_mesh(tmp_path / "x.ply", P, faces)))[:2] == (len(P), len(faces))
    # The four corners alone: a square, whose (1,1) diagonal wins.
    sq = [(lo, lo), (hi, lo), (hi, hi), (lo, hi)]
    good = write_mesh(tmp_path / "sq.ply", sq, [(0, 1, 2), (0, 2, 3)])
    bad = write_mesh(tmp_path / "sq_bad.ply", sq, [(0, 1, 3), (1, 2, 3)])
    assert ok_counts(validate(good))[:3] == (4, 2, 4)
    assert_fail(validate(bad), "1 co-circular edges losing the tie-break")


# ------------------------------------------------------------------ planted faults

def test_wrong_diagonal_in_cocircular_square(tmp_path):
    pts, faces = grid_mesh(5)
    k = 5
    a, b = 2 * k + 2, 3 * k + 3            # the diagonal of cell (2, 2)
    faces = flip_edge(faces, a, b)
    line = assert_fail(validate(write_mesh(tmp_path / "m.ply", pts, faces)),
                       "1 co-circular edges losing the tie-break")
    assert "Delaunay" not in line and "area" not in line


def test_non_delaunay_edge(tmp_path):
    rng = random.Random(4)
    P = random_points(rng, 30, 1000)
    faces = brute_tdd(P)
    # Flip an interior edge whose quad is strictly convex.
    edges = {}
    for t in faces:
        for u, v in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
            edges.setdefault(frozenset((u, v)), []).append(t)
    for e, ts in sorted(edges.items(), key=lambda kv: sorted(kv[0])):
        if len(ts) != 2:
            continue
        a, b = sorted(e)
        c = next(v for v in ts[0] if v not in e)
        d = next(v for v in ts[1] if v not in e)
        if crosses(P[a], P[b], P[c], P[d]):
            break
    bad = flip_edge(faces, a, b)
    assert_fail(validate(write_mesh(tmp_path / "m.ply", P, bad)), "1 edges not locally Delaunay")


def test_missing_face(tmp_path):
    pts, faces = grid_mesh(5)
    faces = [t for t in faces if t != (6, 11, 12)]
    assert len(faces) == 31
    assert_fail(validate(write_mesh(tmp_path / "m.ply", pts, faces)), "boundary")


def test_duplicated_vertex(tmp_path):
    pts, faces = grid_mesh(4)
    pts = pts + [pts[5]]                   # same lattice point, unused
    assert_fail(validate(write_mesh(tmp_path / "a.ply", pts, faces)), "1 duplicate vertices")
    # The duplicate takes over vertex 5 in one face.
    k = next(n for n, t in enumerate(faces) if 5 in t)
    faces2 = list(faces)
    faces2[k] = tuple(16 if v == 5 else v for v in faces[k])
    assert_fail(validate(write_mesh(tmp_path / "b.ply", pts, faces2)), "1 duplicate vertices")


def test_inverted_face(tmp_path):
    pts, faces = grid_mesh(4)
    faces[3] = (faces[3][0], faces[3][2], faces[3][1])
    assert_fail(validate(write_mesh(tmp_path / "m.ply", pts, faces)),
                "1 faces not strictly counter-clockwise", "clockwise")


def test_non_convex_boundary(tmp_path):
    pts, faces = grid_mesh(4)
    # Corner cell (0,0): removing (p00, p10, p11) leaves a notch at p11.
    faces = [t for t in faces if t != (0, 4, 5)]
    assert_fail(validate(write_mesh(tmp_path / "m.ply", pts, faces)), "non-convex boundary turns")


def test_other_structural_faults(tmp_path):
    pts, faces = grid_mesh(4)
    assert_fail(validate(write_mesh(tmp_path / "a.ply", pts, faces + [faces[0]])),
                "edges used twice in the same direction")
    assert_fail(validate(write_mesh(tmp_path / "b.ply", pts, faces + [(0, 1, 99)])),
                "1 faces with a vertex index out of range")
    assert_fail(validate(write_mesh(tmp_path / "c.ply", pts, faces + [(0, 0, 1)])),
                "1 faces with a repeated vertex")
    assert_fail(validate(write_mesh(tmp_path / "d.ply", pts + [(100, 100)], faces)),
                "1 vertices in no face")
    # Two stacked copies of the mesh, each on its own copy of the vertices.
    n = len(pts)
    assert_fail(validate(write_mesh(tmp_path / "e.ply", pts + pts,
                                    faces + [tuple(v + n for v in t) for t in faces])),
                "duplicate vertices")


def test_off_lattice_vertex(tmp_path):
    pts, faces = grid_mesh(3)
    coords = [(0.001 * x, 0.001 * y) for x, y in pts]
    coords[4] = (coords[4][0] + 0.0004, coords[4][1])
    assert_fail(validate(write_mesh(tmp_path / "m.ply", pts, faces, coords=coords)),
                "1 vertices off the lattice", "vertex 4")


# ------------------------------------------------------------------ degenerate sets

def test_degenerate_sets(tmp_path):
    out = validate(write_mesh(tmp_path / "empty.ply", [], []))
    assert out.returncode == 0 and "0 vertices, 0 faces" in out.stdout
    for name, P in (("one", [(5, 5)]), ("two", [(0, 0), (3, 1)]),
                    ("line", [(0, 0), (7, 3), (14, 6), (-7, -3), (70, 30)])):
        out = validate(write_mesh(tmp_path / (name + ".ply"), P, []))
        assert ok_counts(out) == (len(P), 0, 0, 0)
        assert "no triangles" in out.stdout
    assert_fail(validate(write_mesh(tmp_path / "tri0.ply", [(0, 0), (5, 0), (0, 5)], [])),
                "not collinear")
    # A face on collinear points is degenerate.
    assert_fail(validate(write_mesh(tmp_path / "flat.ply", [(0, 0), (1, 1), (2, 2)], [(0, 1, 2)])),
                "degenerate")
    assert_fail(validate(write_mesh(tmp_path / "dup2.ply", [(1, 1), (1, 1)], [])),
                "1 duplicate vertices")


# ------------------------------------------------------------------ --input

def write_las(path, X, Y, scale=(0.001, 0.001), offset=(0.0, 0.0)):
    import laspy
    hdr = laspy.LasHeader(point_format=3, version="1.2")
    hdr.scales = np.array([scale[0], scale[1], 0.001])
    hdr.offsets = np.array([offset[0], offset[1], 0.0])
    las = laspy.LasData(hdr)
    las.X = np.asarray(X, dtype=np.int32)
    las.Y = np.asarray(Y, dtype=np.int32)
    las.Z = np.arange(len(X), dtype=np.int32)
    las.write(str(path))
    return path


def lzf_encode(data, window=1024):
    """A small greedy LZF encoder (literal runs and back references)."""
    out, lit = bytearray(), bytearray()

    def flush():
        for s in range(0, len(lit), 32):
            part = lit[s:s + 32]
            out.append(len(part) - 1)
            out.extend(part)
        lit.clear()
    i, n = 0, len(data)
    while i < n:
        best, off = 0, 0
        for j in range(max(0, i - window), i):
            m = 0
            while i + m < n and m < 264 and data[j + m] == data[i + m]:
                m += 1
            if m > best:
                best, off = m, i - j - 1
        if best >= 3:
            flush()
            L = best - 2
            if L < 7:
                out.append((L << 5) | (off >> 8))
            else:
                out.append((7 << 5) | (off >> 8))
                out.append(L - 7)
            out.append(off & 0xFF)
            i += best
        else:
            lit.append(data[i])
            i += 1
    flush()
    return bytes(out)


def write_pcd(path, xs, ys, encoding, names=("x", "y", "z")):
    n = len(xs)
    cols = [np.asarray(xs, "<f8"), np.asarray(ys, "<f8"), np.linspace(1.0, 2.0, n).astype("<f8")]
    head = ("VERSION 0.7\nFIELDS %s\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH %d\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA %s\n" % (" ".join(names), n, n, encoding))
    if encoding == "ascii":
        body = "".join("%.17g %.17g %.17g\n" % t for t in zip(*cols)).encode()
    elif encoding == "binary":
        body = np.stack(cols, axis=1).astype("<f8").tobytes()
    else:
        raw = b"".join(c.tobytes() for c in cols)
        comp = lzf_encode(raw)
        body = struct.pack("<II", len(comp), len(raw)) + comp
    path.write_bytes(head.encode() + body)
    return path


@pytest.fixture(scope="module")
def input_case(tmp_path_factory):
    d = tmp_path_factory.mktemp("input")
    rng = random.Random(21)
    P = random_points(rng, 30, 1000)
    mesh = write_mesh(d / "m.ply", P, brute_tdd(P))
    return d, P, mesh


def test_input_las_exact_lattice(input_case):
    d, P, mesh = input_case
    X = [p[0] for p in P] + [P[3][0]]      # a duplicate (x, y) in the input is fine
    Y = [p[1] for p in P] + [P[3][1]]
    out = validate(mesh, "--input", write_las(d / "in.las", X, Y))
    assert ok_counts(out)[0] == len(P)
    assert "input: %d points, %d distinct" % (len(P) + 1, len(P)) in out.stdout
    # One input point that is not a vertex.
    las = write_las(d / "in_extra.las", X + [999], Y + [1001])
    assert_fail(validate(mesh, "--input", las), "1 input points missing from the mesh", "(999, 1001)")
    # One vertex that is not in the input.
    las = write_las(d / "in_short.las", X[1:], Y[1:])
    assert_fail(validate(mesh, "--input", las), "1 vertices not in the input")
    # Two inputs form one cloud.
    a = write_las(d / "a.las", X[:10], Y[:10])
    b = write_las(d / "b.las", X[10:], Y[10:])
    assert ok_counts(validate(mesh, "--input", a, "--input", b))[0] == len(P)


def test_input_las_other_lattices(input_case):
    d, P, mesh = input_case
    # Offset differing by whole steps: integers shifted exactly.
    X = [p[0] - 250 for p in P]
    Y = [p[1] + 1000 for p in P]
    assert ok_counts(validate(mesh, "--input", write_las(d / "sh.las", X, Y, offset=(0.25, -1.0))))
    # Finer lattice: coordinates snapped onto the mesh lattice.
    X = [2 * p[0] - 500 for p in P]
    Y = [2 * p[1] for p in P]
    las = write_las(d / "fine.las", X, Y, scale=(0.0005, 0.0005), offset=(0.25, 0.0))
    assert ok_counts(validate(mesh, "--input", las))
    X[0] += 2                               # moves the point by one mesh step
    las = write_las(d / "fine_bad.las", X, Y, scale=(0.0005, 0.0005), offset=(0.25, 0.0))
    assert_fail(validate(mesh, "--input", las), "1 input points missing", "1 vertices not in the input")


def test_input_geographic_is_refused(tmp_path):
    """A projected mesh cannot be compared with lon/lat input (gdt-tile
    projects it first): usage error, not a false verdict."""
    lat = (0.001, 0.001, 500000.0, 4000000.0)
    mesh = write_mesh(tmp_path / "utm.ply", [(0, 0), (1000, 0), (0, 1000)], [(0, 1, 2)], lattice=lat)
    las = write_las(tmp_path / "lonlat.las", [-1230000000, -1230000100, -1230000000],
                    [440000000, 440000000, 440000100], scale=(1e-7, 1e-7))
    out = validate(mesh, "--input", las)
    assert out.returncode == 2 and "longitude/latitude" in out.stderr


@pytest.mark.parametrize("encoding", ["ascii", "binary", "binary_compressed"])
def test_input_pcd(input_case, encoding):
    d, P, mesh = input_case
    xs = [0.001 * p[0] for p in P]
    ys = [0.001 * p[1] for p in P]
    pcd = write_pcd(d / ("in_%s.pcd" % encoding), xs, ys, encoding, names=("X", "Y", "Z"))
    assert ok_counts(validate(mesh, "--input", pcd))[0] == len(P)
    pcd = write_pcd(d / ("bad_%s.pcd" % encoding), xs[:-1] + [0.5], ys[:-1] + [0.5], encoding)
    assert_fail(validate(mesh, "--input", pcd), "1 input points missing", "(500, 500)")


def test_input_unreadable(input_case, tmp_path):
    d, P, mesh = input_case
    assert validate(mesh, "--input", tmp_path / "absent.las").returncode == 3
    bad = tmp_path / "bad.pcd"
    bad.write_bytes(b"VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\n"
                    b"WIDTH 1000\nHEIGHT 1\nPOINTS 1000\nDATA binary\n" + b"\0" * 100)
    out = validate(mesh, "--input", bad)
    assert out.returncode == 3 and "truncated" in out.stderr
    lying = tmp_path / "lying.pcd"
    lying.write_bytes(b"FIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nPOINTS 5\nDATA binary_compressed\n"
                      + struct.pack("<II", 4, 5 * 24) + b"\x00abc")
    assert validate(mesh, "--input", lying).returncode == 3


# ------------------------------------------------------------------ files, usage, memory bound

def test_unreadable_meshes_and_usage(tmp_path):
    pts, faces = grid_mesh(3)
    good = write_mesh(tmp_path / "g.ply", pts, faces)
    data = good.read_bytes()
    (tmp_path / "trunc.ply").write_bytes(data[:-5])
    (tmp_path / "long.ply").write_bytes(data + b"\0")
    (tmp_path / "text.ply").write_text("hello\n")
    (tmp_path / "ascii.ply").write_bytes(data.replace(b"binary_little_endian", b"ascii", 1))
    for name in ("trunc.ply", "long.ply", "text.ply", "ascii.ply", "absent.ply"):
        out = validate(tmp_path / name)
        assert out.returncode == 3, name
        assert out.stderr.startswith("ERROR: ") and out.stdout == ""
    assert validate().returncode == 2
    assert validate(good, "--chunk", "0").returncode == 2
    assert validate(good, "--bogus").returncode == 2
    # No lattice comment: a violation, unless --quantum supplies it.
    nolat = write_mesh(tmp_path / "nolat.ply", pts, faces, comments=["crs unknown"])
    assert_fail(validate(nolat), "lattice")
    assert ok_counts(validate(nolat, "--quantum", "0.001"))
    assert validate(good, "--quantum", "0.01").returncode == 2


def test_small_chunks_spill_to_disk_with_same_verdicts(tmp_path):
    rng = random.Random(9)
    P = random_points(rng, 40, 800)
    faces = brute_tdd(P)
    good = write_mesh(tmp_path / "good.ply", P, faces)
    bad = write_mesh(tmp_path / "bad.ply", P, faces[:-1] + [(faces[-1][0], faces[-1][2], faces[-1][1])])
    spill = tmp_path / "spill"
    spill.mkdir()
    def counts_only(line):
        return re.sub(r" \(e\.g\. [^;]*\)", "", line)
    for mesh in (good, bad):
        ref = validate(mesh)
        small = validate(mesh, "--chunk", "7", "--tmpdir", spill)
        assert small.returncode == ref.returncode
        assert counts_only(small.stdout) == counts_only(ref.stdout)
    assert ref.returncode == 1
    assert list(spill.iterdir()) == []


# ------------------------------------------------------------------ compare_meshes

def test_compare_meshes(tmp_path):
    pts, faces = grid_mesh(5)
    a = write_mesh(tmp_path / "a.ply", pts, faces)
    rng = random.Random(2)
    perm = list(range(len(pts)))
    rng.shuffle(perm)
    inv = {old: new for new, old in enumerate(perm)}
    fb = []
    for t in faces:
        r = rng.randrange(3)
        fb.append(tuple(inv[v] for v in t[r:] + t[:r]))
    rng.shuffle(fb)
    b = write_mesh(tmp_path / "b.ply", [pts[o] for o in perm], fb)
    out = compare(a, b)
    assert out.returncode == 0 and out.stdout.startswith("EQUAL: 32 triangles, 25 vertices")
    # One flipped diagonal: two triangles differ on each side.
    c = write_mesh(tmp_path / "c.ply", pts, flip_edge(faces, 12, 18))
    out = compare(a, c)
    assert out.returncode == 1
    assert "triangles: 2 only in A, 2 only in B" in out.stdout
    assert out.stdout.count("triangle only in A:") == 2 and out.stdout.count("triangle only in B:") == 2
    # Orientation counts: a reversed triangle is a different triangle.
    d = write_mesh(tmp_path / "d.ply", pts, [(faces[0][0], faces[0][2], faces[0][1])] + faces[1:])
    assert "1 only in A, 1 only in B" in compare(a, d).stdout
    # Same points on a lattice whose origin is shifted by whole steps.
    e = write_mesh(tmp_path / "e.ply", [(x - 100, y + 7) for x, y in pts], faces,
                   lattice=(0.001, 0.001, 0.1, -0.007))
    assert compare(a, e).returncode == 0
    # Small chunks (many buckets on disk) give the same verdict.
    out = compare(a, c, "--chunk", "3")
    assert out.returncode == 1 and "triangles: 2 only in A, 2 only in B" in out.stdout
    assert compare(a, tmp_path / "absent.ply").returncode == 3
    assert compare(a).returncode == 2


# ------------------------------------------------------------------ gdt-tile output

def _gdt_tile():
    exe = build_dir() / "tiler" / "gdt-tile"
    if not exe.exists():
        pytest.skip("gdt-tile not built at %s" % exe)
    return exe


@pytest.mark.sanitize
def test_reference_mesh_of_real_data_validates(tmp_path, data_dir):
    exe = _gdt_tile()
    src = data_dir / "100-points.las"
    out = tmp_path / "p100.ply"
    r = subprocess.run([str(exe), str(src), "--reference", "-q", "-o", str(out)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    res = validate(out, "--input", src)
    assert res.returncode == 0, res.stdout + res.stderr


@pytest.mark.parametrize("kind", ["grid", "rotgrid", "circle", "clusters", "duplicates", "collinear"])
def test_reference_mesh_of_degenerate_sets_validates(tmp_path, kind):
    exe = _gdt_tile()
    cloud = tmp_path / (kind + ".las")
    g = run_script("gen_degenerate.py", kind, cloud, "--n", "400", "--seed", "5")
    assert g.returncode == 0, g.stderr
    out = tmp_path / (kind + ".ply")
    r = subprocess.run([str(exe), str(cloud), "--reference", "-q", "-o", str(out)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    res = validate(out, "--input", cloud)
    assert res.returncode == 0, res.stdout + res.stderr
