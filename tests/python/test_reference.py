"""The reference triangulator checked from outside, with exact Python integers.

The C verifiers and the reference share the predicates module; these tests
do not.  For each point set the output of the ref_dt tool must be a
triangulation whose triangles are counter-clockwise, whose boundary is the
convex hull with collinear hull points included (computed here by a
monotone chain), whose areas add up to the hull area, with F = 2V - h - 2;
no point may lie strictly inside a circumcircle, and every interior edge
must be locally optimal under the preferred-direction rule of Dyken and
Floater (d1 = (1, 0), d2 = (1, 1)), re-implemented here from the paper.
The output must not depend on the input order, must equal CGAL's on points
in general position, and bad input must be refused with its message number.
"""
import math
import random

import pytest

M = 2**31 - 1


def orient(a, b, c):
    d = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    return (d > 0) - (d < 0)


def incircle(a, b, c, d):
    rows = []
    for p in (a, b, c):
        x, y = p[0] - d[0], p[1] - d[1]
        rows.append((x, y, x * x + y * y))
    (ax, ay, aw), (bx, by, bw), (cx, cy, cw) = rows
    det = ax * (by * cw - bw * cy) - ay * (bx * cw - bw * cx) + aw * (bx * cy - by * cx)
    return (det > 0) - (det < 0)


def prefer(e, f):
    """+1 if diagonal e has the lower score (wins), -1 if f does, 0 if parallel."""
    le, lf = e[0] ** 2 + e[1] ** 2, f[0] ** 2 + f[1] ** 2
    for de, df in ((e[0], f[0]), (e[0] + e[1], f[0] + f[1])):
        v = de * de * lf - df * df * le
        if v:
            return 1 if v > 0 else -1
    return 0


def needs_flip(a, b, c, d):
    """Edge a-b of the ccw triangles (a, b, c) and (b, a, d) must flip to c-d."""
    s = incircle(a, b, c, d)
    if s != 0:
        return s > 0
    convex = (orient(a, d, b) > 0 and orient(d, b, c) > 0 and orient(b, c, a) > 0
              and orient(c, a, d) > 0)
    if not convex:
        return False
    return prefer((c[0] - d[0], c[1] - d[1]), (b[0] - a[0], b[1] - a[1])) > 0


def hull_edges(pts):
    """Directed ccw edges of the convex hull, every collinear hull point kept."""
    idx = sorted(range(len(pts)), key=lambda i: pts[i])

    def chain(order):
        out = []
        for i in order:
            while len(out) >= 2 and orient(pts[out[-2]], pts[out[-1]], pts[i]) < 0:
                out.pop()
            out.append(i)
        return out

    lower, upper = chain(idx), chain(idx[::-1])
    cyc = lower[:-1] + upper[:-1]
    return {(cyc[k], cyc[(k + 1) % len(cyc)]) for k in range(len(cyc))}


def area2(pts, cyc):
    return sum(pts[cyc[k]][0] * pts[cyc[(k + 1) % len(cyc)]][1]
               - pts[cyc[(k + 1) % len(cyc)]][0] * pts[cyc[k]][1] for k in range(len(cyc)))


def triangulate(runner, tools_dir, tmp_path, pts, name="pts.txt", extra=()):
    f = tmp_path / name
    f.write_text("".join(f"{x} {y}\n" for x, y in pts))
    r = runner([tools_dir / "ref_dt", *extra, f])
    return r


def parse(out):
    lines = out.split("\n")
    v, nf = map(int, lines[0].split())
    tris = [tuple(map(int, ln.split())) for ln in lines[1:1 + nf]]
    assert len(tris) == nf
    return v, tris


def verify(pts, tris, brute=True):
    n = len(pts)
    collinear = n < 3 or all(orient(pts[0], pts[1], p) == 0 for p in pts[2:])
    if collinear:
        assert tris == []
        return
    directed = {}
    for t, (a, b, c) in enumerate(tris):
        assert orient(pts[a], pts[b], pts[c]) > 0, f"triangle {t} not ccw"
        for e, apex in (((a, b), c), ((b, c), a), ((c, a), b)):
            assert e not in directed, f"directed edge {e} twice"
            directed[e] = apex
    assert {v for t in tris for v in t} == set(range(n)), "unused vertex"
    boundary = {e for e in directed if (e[1], e[0]) not in directed}
    hull = hull_edges(pts)
    assert boundary == hull, "boundary is not the convex hull (collinear points included)"
    h = len(hull)
    assert len(tris) == 2 * n - h - 2
    nxt = dict(hull)
    cyc = [next(iter(nxt))]
    while nxt[cyc[-1]] != cyc[0]:
        cyc.append(nxt[cyc[-1]])
    tri_area = sum(area2(pts, t) for t in tris)
    assert tri_area == area2(pts, cyc), "triangles do not tile the hull"
    for (a, b), c in directed.items():
        if (b, a) in directed and a < b:
            d = directed[(b, a)]
            assert not needs_flip(pts[a], pts[b], pts[c], pts[d]), f"edge {a}-{b} must flip"
            assert not needs_flip(pts[b], pts[a], pts[d], pts[c]), f"edge {b}-{a} must flip"
    if brute:
        for (a, b, c) in tris:
            for v in range(n):
                if v not in (a, b, c):
                    assert incircle(pts[a], pts[b], pts[c], pts[v]) <= 0, "circumcircle not empty"


def lattice_circle(cx, cy, r):
    out = set()
    for x in range(r + 1):
        y2 = r * r - x * x
        y = int(y2 ** 0.5)
        while y * y > y2:
            y -= 1
        while (y + 1) ** 2 <= y2:
            y += 1
        if y * y == y2:
            out |= {(cx + sx * x, cy + sy * y) for sx in (1, -1) for sy in (1, -1)}
    return sorted(out)


def point_sets():
    rnd = random.Random(99)
    mid = 2**30
    sets = {
        "grid": [(3 * i, 5 + 3 * j) for i in range(11) for j in range(8)],
        "rotated grid": [(mid + 3 * i - 4 * j, mid + 4 * i + 3 * j)
                         for i in range(-5, 6) for j in range(-5, 6)],
        "circle": lattice_circle(mid, mid, 1625),
        "circle and centre": lattice_circle(5000, 5000, 1625) + [(5000, 5000)],
        "dense": sorted({(rnd.randint(0, 15), rnd.randint(0, 15)) for _ in range(150)}),
        "collinear": [(7 * k, 3 * k + 11) for k in range(30)],
        "collinear and apex": [(7 * k, 3 * k + 11) for k in range(30)] + [(0, 500)],
        "extremes": sorted({(x, y) for x in (0, 1, 2, M - 2, M - 1, M)
                            for y in (0, 1, M - 1, M)} | {(rnd.randint(0, M), 0)
                                                          for _ in range(6)}),
        "uniform": [(rnd.randint(0, M), rnd.randint(0, M)) for _ in range(120)],
        "three": [(5, 5), (5, 9), (9, 5)],
        "two": [(1, 1), (M, M)],
        "thin circle": sorted({(mid + round(10**6 * math.cos(a)) + rnd.randint(-1, 1),
                                mid + round(10**6 * math.sin(a)))
                               for a in [rnd.random() * 2 * math.pi for _ in range(150)]}),
    }
    for k, v in sets.items():
        sets[k] = list(dict.fromkeys(v))
        rnd.shuffle(sets[k])
    return sets


SETS = point_sets()


@pytest.mark.sanitize
@pytest.mark.parametrize("name", sorted(SETS))
def test_reference_exact(runner, tools_dir, tmp_path, name):
    pts = SETS[name]
    r = triangulate(runner, tools_dir, tmp_path, pts, extra=("--check",))
    assert r.returncode == 0, r.stderr
    v, tris = parse(r.stdout)
    assert v == len(pts)
    verify(pts, tris)


@pytest.mark.sanitize
@pytest.mark.parametrize("name", ["grid", "rotated grid", "circle", "dense", "extremes"])
def test_reference_order_independent(runner, tools_dir, tmp_path, name):
    pts = SETS[name]
    r = triangulate(runner, tools_dir, tmp_path, pts)
    assert r.returncode == 0, r.stderr
    base = set(parse(r.stdout)[1])
    rnd = random.Random(name)
    for k in range(3):
        perm = list(range(len(pts)))
        rnd.shuffle(perm)
        r = triangulate(runner, tools_dir, tmp_path, [pts[i] for i in perm], f"p{k}.txt")
        assert r.returncode == 0, r.stderr
        mapped = set()
        for t in parse(r.stdout)[1]:
            g = [perm[i] for i in t]
            lo = g.index(min(g))
            mapped.add(tuple(g[lo:] + g[:lo]))
        assert mapped == base


def test_reference_grid_diagonals(runner, tools_dir, tmp_path):
    pts = SETS["grid"]
    r = triangulate(runner, tools_dir, tmp_path, pts)
    assert r.returncode == 0, r.stderr
    for t in parse(r.stdout)[1]:
        diag = []
        for k in range(3):
            a, b = pts[t[k]], pts[t[(k + 1) % 3]]
            dx, dy = b[0] - a[0], b[1] - a[1]
            if dx and abs(dx) == abs(dy):
                diag.append(dx == dy)
        assert diag == [True], f"triangle {t} is not cut along (1,1)"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_reference_matches_cgal(runner, tools_dir, tmp_path, seed):
    cgal = tools_dir / "cgal_dt"
    if not cgal.exists():
        pytest.skip("cgal_dt not built (CGAL not found at configure time)")
    rnd = random.Random(seed)
    pts = list(dict.fromkeys((rnd.randint(0, M), rnd.randint(0, M)) for _ in range(3000)))
    r = triangulate(runner, tools_dir, tmp_path, pts)
    assert r.returncode == 0, r.stderr
    c = runner([cgal, tmp_path / "pts.txt"])
    assert c.returncode == 0, c.stderr
    assert r.stdout == c.stdout


@pytest.mark.sanitize
def test_reference_refuses_bad_input(runner, tools_dir, tmp_path):
    r = triangulate(runner, tools_dir, tmp_path, [(1, 2), (5, 5), (9, 1), (5, 5)])
    assert r.returncode == 7
    assert "GDT-7341" in r.stderr and "input 1 and input 3" in r.stderr
    r = triangulate(runner, tools_dir, tmp_path, [(0, 0), (5, 0), (2**31, 5)])
    assert r.returncode == 7 and "GDT-7340" in r.stderr and "point 2" in r.stderr
    r = triangulate(runner, tools_dir, tmp_path, [(0, 0), (-1, 0), (3, 5)])
    assert r.returncode == 7 and "GDT-7340" in r.stderr
    f = tmp_path / "junk.txt"
    f.write_text("1 2\nthree four\n")
    r = runner([tools_dir / "ref_dt", f])
    assert r.returncode == 3 and "line 2" in r.stderr


def test_oracle_catches_planted_faults():
    """The Python oracle itself must reject wrong triangulations."""
    sq = [(0, 0), (1, 0), (1, 1), (0, 1)]
    verify(sq, [(0, 1, 2), (0, 2, 3)])
    with pytest.raises(AssertionError, match="must flip"):
        verify(sq, [(0, 1, 3), (1, 2, 3)])
    with pytest.raises(AssertionError, match="not ccw"):
        verify(sq, [(0, 2, 1), (0, 2, 3)])
    with pytest.raises(AssertionError, match="unused vertex"):
        verify(sq, [(0, 1, 2)])
    pent = [(0, 0), (4, 0), (4, 4), (0, 4), (2, 1)]
    with pytest.raises(AssertionError, match="convex hull"):
        verify(pent, [(0, 1, 4), (1, 2, 4), (2, 3, 4)])
    quad = [(0, 0), (10, 0), (11, 5), (0, 4)]
    verdicts = []
    for tris in ([(0, 1, 2), (0, 2, 3)], [(0, 1, 3), (1, 2, 3)]):
        try:
            verify(quad, tris)
            verdicts.append(True)
        except AssertionError as e:
            assert "must flip" in str(e)
            verdicts.append(False)
    assert sorted(verdicts) == [False, True]
