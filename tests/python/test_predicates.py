"""Exact predicates against Python big integers.

One seeded batch of 10^6 cases (random, near-collinear, co-circular on
integer circles from Gaussian-integer products, +-1 perturbations, extreme
coordinates 0 and 2^31-1, grid cells) goes through tests/tools/pred_eval in a
single process call; every sign must equal the big-integer value.  The path
bits must show the double filter escalating exactly where its proven bound
cannot decide (the bound is re-evaluated here in numpy float64, which rounds
every operation separately), and never on uniform random input.  The same
cases run through the OpenCL build of kernels/gdt_exact.clh (pred_cl_eval)
must give byte-identical output.
"""
import math
import shutil
import subprocess

import numpy as np
import pytest

L = 2**31 - 1
OP_ORIENT, OP_INCIRCLE, OP_PREFER, OP_FLIP = 0, 1, 2, 3
SEED = 20240611

# Gaussian-integer factors a + bi of primes p = a^2 + b^2 (p = 1 mod 4).
GAUSS = [(2, 1), (3, 2), (4, 1), (5, 2), (6, 1), (5, 4), (7, 2), (6, 5), (8, 3), (8, 5),
         (9, 4), (10, 1), (10, 3), (8, 7)]


def circle_points(factors, scale):
    """All lattice points on the circle of squared radius scale^2 * prod(p),
    sorted counter-clockwise by angle (exact: distinct rational directions)."""
    pts = {(1, 0)}
    for a, b in factors:
        nxt = set()
        for x, y in pts:
            nxt.add((x * a - y * b, x * b + y * a))
            nxt.add((x * a + y * b, -x * b + y * a))
        pts = nxt
    full = set()
    for x, y in pts:
        for ux, uy in ((x, y), (-y, x), (-x, -y), (y, -x)):
            full.add((ux * scale, uy * scale))
    return sorted(full, key=lambda p: math.atan2(p[1], p[0]))


def make_circles():
    """Circles of radius from ~10 to ~2^30, each with its sorted points."""
    circles = []
    subsets = [[0], [0, 1], [0, 1, 2], [0, 1, 2, 3], [1, 3, 5], [0, 2, 4, 6, 8],
               [0, 1, 2, 3, 4, 5], [0, 1, 2, 3, 4, 5, 6], [0, 1, 2, 3, 4, 5, 6, 7],
               [0, 1, 2, 3, 4, 5, 6, 7, 8], [2, 4, 6, 8, 10, 12], [0, 1, 2, 3, 4, 5, 6, 7, 8, 9],
               [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10]]
    for sub in subsets:
        fac = [GAUSS[i] for i in sub]
        n = math.prod(a * a + b * b for a, b in fac)
        r = math.isqrt(n)
        for scale in {1, max(1, (2**30 - 2) // (r + 1))}:
            if (r + 1) * scale <= 2**30 - 2:
                circles.append(np.array(circle_points(fac, scale), dtype=np.int64))
    return circles


def pad(cols, n):
    """Stacks coordinate columns into records with zero padding to 8 values."""
    out = np.zeros((n, 8), dtype=np.int64)
    for i, c in enumerate(cols):
        out[:, i] = c
    return out


def gen_cases(rng):
    recs = []  # list of (op, (n, 8) array)
    circles = make_circles()

    def uni(n, lo=0, hi=L):
        return rng.integers(lo, hi, size=n, endpoint=True, dtype=np.int64)

    def edgy(n):
        special = np.array([0, 1, 2, L - 2, L - 1, L, L // 2, L // 2 + 1], dtype=np.int64)
        return special[rng.integers(0, len(special), size=n)]

    def cocircular(n, k=4, sort=False):
        """n groups of k points on random circles, centred so they fit."""
        groups = []
        per = n // len(circles) + 1
        for c in circles:
            r = int(np.abs(c).max())
            idx = np.sort(rng.integers(0, len(c), size=(per, k)), axis=1)
            while True:  # distinct points: redraw rows with a repeated index
                dup = np.any(idx[:, 1:] == idx[:, :-1], axis=1)
                if not dup.any():
                    break
                idx[dup] = np.sort(rng.integers(0, len(c), size=(int(dup.sum()), k)), axis=1)
            if not sort:
                idx = rng.permuted(idx, axis=1)
            cx = uni(per, r, L - r)[:, None]
            cy = uni(per, r, L - r)[:, None]
            groups.append(np.stack([c[idx, 0] + cx, c[idx, 1] + cy], axis=2))
        g = np.concatenate(groups)[:n]
        return g[rng.permutation(len(g))]  # (n, k, 2)

    def perturb(g):
        """Moves one random point of each group by a random step in {-1,0,1}^2
        (clamped to the legal range)."""
        g = g.copy()
        rows = np.arange(len(g))
        which = rng.integers(0, g.shape[1], size=len(g))
        g[rows, which] += rng.integers(-1, 1, size=(len(g), 2), endpoint=True)
        np.clip(g, 0, L, out=g)
        return g

    def flat(g):
        return pad([g[:, i // 2, i % 2] for i in range(2 * g.shape[1])], len(g))

    # --- orient2d: 150k
    n = 50000
    recs.append((OP_ORIENT, pad([uni(n) for _ in range(6)], n)))
    recs.append((OP_ORIENT, pad([edgy(25000) for _ in range(6)], 25000)))
    a = np.stack([uni(n), uni(n)], 1)
    b = np.stack([uni(n), uni(n)], 1)
    t = rng.random(n)[:, None]
    c = np.clip(a + np.rint(t * (b - a)).astype(np.int64)
                + rng.integers(-1, 1, size=(n, 2), endpoint=True), 0, L)
    recs.append((OP_ORIENT, pad([a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1]], n)))
    g = cocircular(25000, 3)
    recs.append((OP_ORIENT, flat(g)))

    # --- incircle: 550k
    recs.append((OP_INCIRCLE, pad([uni(100000) for _ in range(8)], 100000)))
    recs.append((OP_INCIRCLE, pad([edgy(50000) for _ in range(8)], 50000)))
    cen = uni(50000, 5000, L - 5000)
    cols = [np.clip(cen + rng.integers(-5000, 5000, size=50000, endpoint=True), 0, L)
            for _ in range(8)]
    recs.append((OP_INCIRCLE, pad(cols, 50000)))
    g = cocircular(150000)
    recs.append((OP_INCIRCLE, flat(g)))
    recs.append((OP_INCIRCLE, flat(perturb(cocircular(150000)))))
    # Square and rectangular grid cells anywhere in the range.
    m = 50000
    sx = np.where(rng.random(m) < 0.5, uni(m, 1, 8), uni(m, 1, L // 2))
    sy = np.where(rng.random(m) < 0.5, sx, uni(m, 1, L // 2))
    x0, y0 = uni(m) % (L - sx + 1), uni(m) % (L - sy + 1)
    recs.append((OP_INCIRCLE, pad([x0, y0, x0 + sx, y0, x0 + sx, y0 + sy, x0, y0 + sy], m)))

    # --- prefer_diagonal: 150k
    n = 50000
    recs.append((OP_PREFER, pad([uni(n, -L, L) for _ in range(4)], n)))
    ex, ey = uni(n, -L, L), uni(n, -L, L)
    recs.append((OP_PREFER, pad([ex, ey, ex, -ey], n)))  # equal angle to (1, 0)
    sgn = np.array([-L, -L + 1, -1, 0, 1, L - 1, L], dtype=np.int64)
    e4 = [sgn[rng.integers(0, len(sgn), size=25000)] for _ in range(4)]
    recs.append((OP_PREFER, pad(e4, 25000)))
    ex, ey = uni(25000, -2**20, 2**20), uni(25000, -2**20, 2**20)
    k = uni(25000, -2000, 2000)
    recs.append((OP_PREFER, pad([ex, ey, ex * k, ey * k], 25000)))  # parallel

    # --- edge_needs_flip: 150k, co-circular convex quads p0..p3 (ccw)
    def flip_cases(g):
        p0, p1, p2, p3 = (g[:, i, :] for i in range(4))
        first = rng.random(len(g)) < 0.5
        # edge p0-p2 with triangles (p0,p2,p3), (p2,p0,p1); or edge p1-p3 with
        # triangles (p1,p3,p0), (p3,p1,p2)
        a = np.where(first[:, None], p0, p1)
        b = np.where(first[:, None], p2, p3)
        c = np.where(first[:, None], p3, p0)
        d = np.where(first[:, None], p1, p2)
        return pad([a[:, 0], a[:, 1], b[:, 0], b[:, 1], c[:, 0], c[:, 1], d[:, 0], d[:, 1]],
                   len(g))

    g = cocircular(100000, sort=True)
    recs.append((OP_FLIP, flip_cases(g)))
    gp = g[:50000].copy()
    gp[:, 1] = np.clip(gp[:, 1] + rng.integers(-1, 1, size=(50000, 2), endpoint=True), 0, L)
    recs.append((OP_FLIP, flip_cases(gp)))

    ops = np.concatenate([np.full(len(r), op, dtype=np.int64) for op, r in recs])
    vals = np.concatenate([r for _, r in recs])
    return np.column_stack([ops, vals])


def sgn(v):
    return (v > 0) - (v < 0)


def ref_orient(ax, ay, bx, by, cx, cy):
    return sgn((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))


def ref_incircle(ax, ay, bx, by, cx, cy, dx, dy):
    adx, ady, bdx, bdy, cdx, cdy = ax - dx, ay - dy, bx - dx, by - dy, cx - dx, cy - dy
    return sgn((adx * adx + ady * ady) * (bdx * cdy - cdx * bdy)
               + (bdx * bdx + bdy * bdy) * (cdx * ady - adx * cdy)
               + (cdx * cdx + cdy * cdy) * (adx * bdy - bdx * ady))


def ref_prefer(ex, ey, fx, fy):
    ee, ff = ex * ex + ey * ey, fx * fx + fy * fy
    c = sgn(ex * ex * ff - fx * fx * ee)
    if c:
        return c
    return sgn((ex + ey) ** 2 * ff - (fx + fy) ** 2 * ee)


def ref_flip(ax, ay, bx, by, cx, cy, dx, dy):
    ic = ref_incircle(ax, ay, bx, by, cx, cy, dx, dy)
    if ic:
        return int(ic > 0)
    if ref_orient(dx, dy, bx, by, cx, cy) <= 0 or ref_orient(cx, cy, ax, ay, dx, dy) <= 0:
        return 0
    return int(ref_prefer(dx - cx, dy - cy, bx - ax, by - ay) > 0)


def reference(cases):
    """Big-integer signs of every case (Python ints: no overflow)."""
    out = np.zeros(len(cases), dtype=np.int8)
    fns = {OP_ORIENT: (ref_orient, 6), OP_INCIRCLE: (ref_incircle, 8),
           OP_PREFER: (ref_prefer, 4), OP_FLIP: (ref_flip, 8)}
    for op, (fn, k) in fns.items():
        sel = np.nonzero(cases[:, 0] == op)[0]
        cols = [cases[sel, 1 + i].tolist() for i in range(k)]
        out[sel] = [fn(*v) for v in zip(*cols)]
    return out


def filter_undecided(cases):
    """For in-circle cases: whether the double filter of gdt_exact.clh leaves
    the case to the integer path.  numpy float64 rounds each elementwise
    operation on its own, in the same order as the C expression."""
    v = cases[:, 1:].astype(np.int64)
    d = [(v[:, i] - v[:, 6 + (i % 2)]) for i in range(6)]
    maxdiff = np.max(np.abs(np.stack(d)), axis=0)
    adx, ady, bdx, bdy, cdx, cdy = (x.astype(np.float64) for x in d)
    bdxcdy, cdxbdy = bdx * cdy, cdx * bdy
    cdxady, adxcdy = cdx * ady, adx * cdy
    adxbdy, bdxady = adx * bdy, bdx * ady
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy
    det = alift * (bdxcdy - cdxbdy) + blift * (cdxady - adxcdy) + clift * (adxbdy - bdxady)
    perm = ((np.abs(bdxcdy) + np.abs(cdxbdy)) * alift + (np.abs(cdxady) + np.abs(adxcdy)) * blift
            + (np.abs(adxbdy) + np.abs(bdxady)) * clift)
    errbound = (7.0 + 2.0**-45) * 2.0**-53
    bound = errbound * perm
    decided_sign = np.where(det > bound, 1, np.where(det < -bound, -1, 2))
    small = maxdiff < 4096
    decided_sign = np.where(small, np.sign(det).astype(np.int64), decided_sign)
    return decided_sign == 2, decided_sign, small


@pytest.fixture(scope="module")
def batch():
    rng = np.random.default_rng(SEED)
    cases = gen_cases(rng)
    assert len(cases) == 1_000_000
    assert cases[:, 1:].min() >= -L and cases[:, 1:].max() <= L
    return cases, reference(cases)


def run_tool(exe, cases, *args):
    return subprocess.run([str(exe), *args], input=np.ascontiguousarray(cases).tobytes(),
                          capture_output=True, timeout=600)


@pytest.mark.sanitize
def test_predicates_match_big_integers(batch, tool):
    cases, ref = batch
    proc = run_tool(tool("pred_eval"), cases)
    err = proc.stderr.decode()
    assert proc.returncode == 0, err
    print(err.strip())
    out = np.frombuffer(proc.stdout, dtype=np.int8).reshape(-1, 2)
    assert len(out) == len(cases)
    res, path = out[:, 0], out[:, 1].astype(np.uint8)

    bad = np.nonzero(res != ref)[0]
    assert len(bad) == 0, (f"{len(bad)} wrong signs; first: op {cases[bad[0], 0]} "
                           f"values {cases[bad[0], 1:].tolist()} got {res[bad[0]]} "
                           f"want {ref[bad[0]]}")

    ops = cases[:, 0]
    ic = ops == OP_INCIRCLE
    icases = cases[ic]
    undecided, fsign, small = filter_undecided(icases)
    iref = ref[ic]
    # The proven bound is sound: a decided filter sign is the true sign.
    wrong = np.nonzero(~undecided & (fsign != iref))[0]
    assert len(wrong) == 0, f"filter bound unsound on {icases[wrong[0], 1:].tolist()}"
    # The tool escalated exactly where the bound cannot decide.
    escalated = (path[ic] & 1) == 1
    assert np.array_equal(escalated, undecided), "escalations differ from the filter bound"
    # Exactly co-circular cases with large differences must escalate; the
    # small ones are decided by the exact double evaluation.
    zero = iref == 0
    assert np.all(escalated[zero & ~small]) and not np.any(escalated[zero & small])
    assert np.count_nonzero(zero & ~small) > 100000 and np.count_nonzero(zero & small) > 1000
    # Uniform random cases (the first 100000 in-circle cases) almost never escalate.
    assert np.count_nonzero(escalated[:100000]) < 100
    counters = dict(zip(err.split()[1::2], map(int, err.split()[2::2])))
    assert counters["incircle_exact"] >= np.count_nonzero(escalated)
    assert counters["cases"] == len(cases)

    # Flip cases: the tie-break path exactly on co-circular convex quads.
    fl = ops == OP_FLIP
    fcases = cases[fl]
    tb_ref = np.array([ref_incircle(ax, ay, bx, by, cx, cy, dx, dy) == 0
                       and ref_orient(dx, dy, bx, by, cx, cy) > 0
                       and ref_orient(cx, cy, ax, ay, dx, dy) > 0
                       for ax, ay, bx, by, cx, cy, dx, dy in fcases[:, 1:].tolist()])
    tb = (path[fl] & 2) == 2
    assert np.array_equal(tb, tb_ref)
    assert np.count_nonzero(tb) > 50000 and np.count_nonzero(res[fl] == 1) > 10000


def test_opencl_matches_host(batch, tool):
    cases, ref = batch
    host = run_tool(tool("pred_eval"), cases)
    assert host.returncode == 0, host.stderr.decode()
    host_out = np.frombuffer(host.stdout, dtype=np.int8).reshape(-1, 2)
    cl_exe = tool("pred_cl_eval")
    for args in ([], ["--no-fp64"]):
        proc = run_tool(cl_exe, cases, *args)
        if proc.returncode == 77:
            pytest.skip("no OpenCL device: " + proc.stderr.decode().strip())
        assert proc.returncode == 0, proc.stderr.decode()
        info = proc.stderr.decode().strip()
        print(info)
        out = np.frombuffer(proc.stdout, dtype=np.int8).reshape(-1, 2)
        assert len(out) == len(cases)
        bad = np.nonzero(out[:, 0] != ref)[0]
        assert len(bad) == 0, f"OpenCL {args}: {len(bad)} wrong signs, first {cases[bad[0]].tolist()}"
        ic = cases[:, 0] == OP_INCIRCLE
        if "filter on" in info:
            # Same filter, same rounding: the same cases escalate.
            assert np.array_equal(out[:, 1], host_out[:, 1])
        else:
            assert np.all(out[ic, 1] == 1)


def test_opencl_kernel_dir_with_spaces(batch, tool, root, tmp_path):
    """The OpenCL tool reads its header from a kernel folder whose path has
    spaces: it hands the header's text to the runtime, as the product does,
    not an -I option naming the folder, which such a path would split."""
    cases, ref = batch
    kdir = tmp_path / "kernel dir with spaces"
    kdir.mkdir()
    shutil.copy(root / "kernels" / "gdt_exact.clh", kdir)
    proc = run_tool(tool("pred_cl_eval"), cases[:5000], "--kernel-dir", str(kdir))
    if proc.returncode == 77:
        pytest.skip("no OpenCL device: " + proc.stderr.decode().strip())
    assert proc.returncode == 0, proc.stderr.decode()
    out = np.frombuffer(proc.stdout, dtype=np.int8).reshape(-1, 2)
    assert np.array_equal(out[:, 0], ref[:5000])
    missing = run_tool(tool("pred_cl_eval"), cases[:10], "--kernel-dir", str(tmp_path / "none"))
    assert missing.returncode != 0 and b"gdt_exact.clh" in missing.stderr


def test_pred_eval_rejects_bad_input(tool):
    exe = tool("pred_eval")
    ok = subprocess.run([str(exe), "-t"], input=b"1 0 0 10 0 0 10 3 3\n", capture_output=True)
    assert ok.returncode == 0 and ok.stdout.split() == [b"1", b"0"]
    for bad in (b"1 0 0 10 0 0 10 3 2147483648\n", b"0 -1 0 1 1 2 2 0 0\n", b"7 0 0 0 0 0 0 0 0\n",
                b"1 0 0 10\n", b"2 -2147483648 0 1 1 0 0 0 0\n"):
        proc = subprocess.run([str(exe), "-t"], input=bad, capture_output=True)
        assert proc.returncode == 3, bad
        assert b"pred_eval:" in proc.stderr
    trunc = subprocess.run([str(exe)], input=b"\0" * 75, capture_output=True)
    assert trunc.returncode == 3 and b"truncated" in trunc.stderr
