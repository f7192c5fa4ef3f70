"""Seeded generators of degenerate point sets on the integer lattice.

Every generator returns (X, Y) int64 arrays of lattice integers (the LAS
record integers: coordinate = offset + scale * integer) and is a pure
function of (n, seed).  make() adds Z integers and shuffles the input order
(except for 'duplicates', whose order is the z order).

Kinds (n is the requested number of points; some kinds fix or cap it):
  grid        first n points, row by row, of a k x k square grid (step 1000)
  rotgrid     a k x k grid with the rotated basis (3,4)*200, (-4,3)*200
  circle      n points of x^2 + y^2 = r^2 (relative to a centre), r the
              smallest of CIRCLE_RADII with enough lattice points (at most 6804)
  thincircle  n points rounded from a circle of radius max(10^4, 4n):
              each within sqrt(2)/2 of the circle, almost all not on it
  collinear   n distinct points base + k (7, 3)
  duplicates  n points with one (x, y), distinct z
  clusters    Gaussian clusters (sigma 200) far apart; one point in 100 (at
              least one) repeats the (x, y) of another point
  one, two, three   exactly 1, 2, 3 points (three not collinear)
  extreme     points in the four corners of the int32 range, including the
              four corners themselves and a step-4 grid patch
  sparse      n points uniform over [-2^30, 2^30)^2
  uniform     n points uniform over [0, 10^7)^2
  mixed       grid, rotated grid, circle, clusters, collinear row,
              duplicates and uniform points in separate regions
"""
import math

import numpy as np

INT32_MIN = -(1 << 31)
INT32_MAX = (1 << 31) - 1

KINDS = ("grid", "rotgrid", "circle", "thincircle", "collinear", "duplicates", "clusters",
         "one", "two", "three", "extreme", "sparse", "uniform", "mixed")

# (radius, prime factorisation); every prime is 1 mod 4, so x^2 + y^2 = r^2
# has 4 * prod(2 e + 1) integer solutions.
CIRCLE_RADII = (
    (5 * 13 * 17 * 29, ((5, 1), (13, 1), (17, 1), (29, 1))),
    (5 * 13 * 17 * 29 * 37, ((5, 1), (13, 1), (17, 1), (29, 1), (37, 1))),
    (5 * 13 * 17 * 29 * 37 * 41, ((5, 1), (13, 1), (17, 1), (29, 1), (37, 1), (41, 1))),
    (5 ** 2 * 13 * 17 * 29 * 37 * 41, ((5, 2), (13, 1), (17, 1), (29, 1), (37, 1), (41, 1))),
    (5 ** 3 * 13 * 17 * 29 * 37 * 41, ((5, 3), (13, 1), (17, 1), (29, 1), (37, 1), (41, 1))),
)


def circle_count(factors):
    c = 4
    for _, e in factors:
        c *= 2 * e + 1
    return c


def circle_points(factors):
    """All integer (x, y) with x^2 + y^2 = r^2, r = prod p^e, via Gaussian
    integers: x + iy = unit * prod pi^k conj(pi)^(2e - k), pi = a + bi with
    a^2 + b^2 = p."""
    def mul(u, v):
        return (u[0] * v[0] - u[1] * v[1], u[0] * v[1] + u[1] * v[0])

    zs = [(1, 0)]
    for p, e in factors:
        a = next(a for a in range(1, p) if math.isqrt(p - a * a) ** 2 == p - a * a)
        pi = (a, math.isqrt(p - a * a))
        pic = (pi[0], -pi[1])
        opts = []
        for k in range(2 * e + 1):
            z = (1, 0)
            for _ in range(k):
                z = mul(z, pi)
            for _ in range(2 * e - k):
                z = mul(z, pic)
            opts.append(z)
        zs = [mul(z, o) for z in zs for o in opts]
    out = set()
    for z in zs:
        for u in ((1, 0), (0, 1), (-1, 0), (0, -1)):
            out.add(mul(z, u))
    return sorted(out)


def _grid(n, base, u, v):
    k = max(1, math.isqrt(max(0, n - 1)) + 1)
    idx = np.arange(n, dtype=np.int64)
    i, j = idx % k, idx // k
    return base[0] + i * u[0] + j * v[0], base[1] + i * u[1] + j * v[1]


def gen_grid(n, rng):
    return _grid(n, (1_000_000, 2_000_000), (1000, 0), (0, 1000))


def gen_rotgrid(n, rng):
    return _grid(n, (50_000_000, 3_000_000), (600, 800), (-800, 600))


def gen_circle(n, rng):
    for r, factors in CIRCLE_RADII:
        if circle_count(factors) >= n:
            break
    pts = np.array(circle_points(factors), dtype=np.int64)
    if n < pts.shape[0]:
        pts = pts[np.sort(rng.choice(pts.shape[0], size=n, replace=False))]
    centre = (0, 0) if r > 1 << 28 else (7_000_000, 9_000_000)
    return centre[0] + pts[:, 0], centre[1] + pts[:, 1]


def thin_radius(n):
    return max(10_000, 4 * n)


def gen_thincircle(n, rng):
    R = thin_radius(n)
    t = rng.uniform(0.0, 2.0 * math.pi, size=n)
    return (np.rint(R * np.cos(t)).astype(np.int64) + 20_000_000,
            np.rint(R * np.sin(t)).astype(np.int64) + 20_000_000)


def gen_collinear(n, rng):
    k = np.sort(rng.choice(10 * n + 10, size=n, replace=False)).astype(np.int64)
    return 3_000_000 + 7 * k, 4_000_000 + 3 * k


def gen_duplicates(n, rng):
    return np.full(n, 1_234_567, dtype=np.int64), np.full(n, 7_654_321, dtype=np.int64)


def gen_clusters(n, rng):
    c = int(min(50, max(2, n // 500)))
    centres = rng.integers(0, 50_000_000, size=(c, 2))
    which = rng.integers(0, c, size=n)
    off = np.rint(rng.normal(0.0, 200.0, size=(n, 2))).astype(np.int64)
    X = centres[which, 0] + off[:, 0]
    Y = centres[which, 1] + off[:, 1]
    # One point in 100 (at least one when n >= 2) repeats an earlier (x, y).
    ndup = max(1, n // 100) if n >= 2 else 0
    dst = rng.choice(np.arange(1, n), size=ndup, replace=False) if ndup else np.zeros(0, np.int64)
    src = (rng.random(ndup) * dst).astype(np.int64)
    X[dst] = X[src]
    Y[dst] = Y[src]
    return X, Y


def _fixed(pts, rng):
    base = rng.integers(0, 1_000_000, size=2)
    p = np.array(pts, dtype=np.int64)
    return base[0] + p[:, 0], base[1] + p[:, 1]


def gen_one(n, rng):
    return _fixed([(0, 0)], rng)


def gen_two(n, rng):
    return _fixed([(0, 0), (1234, 567)], rng)


def gen_three(n, rng):
    return _fixed([(0, 0), (1000, 0), (300, 800)], rng)


def gen_extreme(n, rng):
    corners = np.array([(INT32_MIN, INT32_MIN), (INT32_MAX, INT32_MIN), (INT32_MIN, INT32_MAX),
                        (INT32_MAX, INT32_MAX)], dtype=np.int64)
    if n <= 4:
        return corners[:n, 0], corners[:n, 1]
    m = n - 4
    w = max(64, 8 * math.isqrt(m))
    c = rng.integers(0, 4, size=m)
    # Step inward from the chosen corner.
    sx = np.array([1, -1, 1, -1], dtype=np.int64)[c]
    sy = np.array([1, 1, -1, -1], dtype=np.int64)[c]
    dx = rng.integers(0, w, size=m)
    dy = rng.integers(0, w, size=m)
    grid = rng.random(m) < 0.5          # half of them on a step-4 grid
    dx = np.where(grid, dx - dx % 4, dx)
    dy = np.where(grid, dy - dy % 4, dy)
    X = np.concatenate([corners[:, 0], corners[c, 0] + sx * dx])
    Y = np.concatenate([corners[:, 1], corners[c, 1] + sy * dy])
    return X, Y


def gen_sparse(n, rng):
    p = rng.integers(-(1 << 30), 1 << 30, size=(n, 2))
    return p[:, 0], p[:, 1]


def gen_uniform(n, rng):
    p = rng.integers(0, 10_000_000, size=(n, 2))
    return p[:, 0], p[:, 1]


def gen_mixed(n, rng):
    parts = [
        (gen_grid, max(9, n // 4)),
        (gen_rotgrid, max(9, n // 8)),
        (gen_circle, min(324, max(4, n // 8))),
        (gen_clusters, max(10, n // 8)),
        (gen_collinear, max(3, n // 16)),
        (gen_duplicates, max(2, n // 32)),
    ]
    used = sum(k for _, k in parts)
    parts.append((gen_uniform, max(0, n - used)))
    xs, ys = [], []
    for slot, (fn, k) in enumerate(parts):
        if k == 0:
            continue
        X, Y = fn(k, rng)
        X = np.asarray(X, dtype=np.int64)
        Y = np.asarray(Y, dtype=np.int64)
        # Move each part into its own 60 km x 60 km cell, side by side.
        X = X - X.min() + slot * 60_000_000
        Y = Y - Y.min()
        xs.append(X)
        ys.append(Y)
    return np.concatenate(xs), np.concatenate(ys)


GENERATORS = {k: globals()["gen_" + k] for k in KINDS}


def make(kind, n, seed, scale_z=0.001):
    """Returns (X, Y, Z) int64 arrays for a kind; Z follows a smooth terrain
    (metres / scale_z) with noise, distinct per point for 'duplicates'."""
    if kind not in GENERATORS:
        raise ValueError("unknown kind '%s'" % kind)
    if n < 1:
        raise ValueError("n must be >= 1")
    rng = np.random.default_rng(seed)
    X, Y = GENERATORS[kind](n, rng)
    X = np.asarray(X, dtype=np.int64)
    Y = np.asarray(Y, dtype=np.int64)
    m = X.shape[0]
    if kind == "duplicates":
        z = 100.0 + 0.01 * np.arange(m)
    else:
        z = (100.0 + 20.0 * np.sin(X * 1e-6) * np.cos(Y * 1.3e-6) + rng.normal(0.0, 0.05, size=m))
    Z = np.rint(z / scale_z).astype(np.int64)
    if kind != "duplicates":
        perm = rng.permutation(m)
        X, Y, Z = X[perm], Y[perm], Z[perm]
    return X, Y, Z
