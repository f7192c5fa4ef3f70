"""Exact geometric predicates on numpy int64 arrays of lattice integers.

Precondition for every function: each coordinate c satisfies |c| < 2^53, so
every coordinate difference fits in int64 (|d| < 2^54) and converts to a
double with a relative error of at most 2^-53.

Each predicate runs in up to three tiers, every one exact where it is used:
  1. plain int64 arithmetic where the differences are small enough that the
     true determinant is below 2^63 in magnitude;
  2. a double-precision filter, Shewchuk-style, with an error bound far above
     the proven one (orient2d: 1e-14 x permanent against (3 + 16 eps) eps;
     incircle: 1e-13 x permanent against (10 + 96 eps) eps, plus the rounding
     of differences >= 2^53 when converted to double);
  3. for undecided cases: when the filter proves |det| < 2^62, the int64
     result computed with wrap-around (numpy integer arrays wrap modulo 2^64)
     is the exact determinant; otherwise Python integers (object arrays).
Results are np.int8 arrays of signs (+1, 0, -1).  Counters of the tiers are
kept in a Stats object when one is passed.
"""
import numpy as np

_I64 = np.int64
_F64 = np.float64
_TWO31 = 1 << 31
_TWO15 = 1 << 15
_TWO62 = float(1 << 62)
_ORIENT_EPS = 1e-14
_INCIRCLE_EPS = 1e-13


class Stats:
    """Counts of predicate evaluations per tier (for -v output and tests)."""

    def __init__(self):
        self.orient = 0
        self.incircle = 0
        self.incircle_filtered = 0  # decided by the double filter
        self.incircle_int64 = 0     # exact in int64 (tier 1, or tier 3 with |det| < 2^62)
        self.incircle_bigint = 0    # undecided, exact in Python integers
        self.tiebreak = 0

    def __repr__(self):
        return ("Stats(orient=%d, incircle=%d, filtered=%d, int64=%d, bigint=%d, tiebreak=%d)"
                % (self.orient, self.incircle, self.incircle_filtered, self.incircle_int64,
                   self.incircle_bigint, self.tiebreak))


def _i64(a):
    return np.asarray(a, dtype=_I64)


def _sign(a):
    return np.sign(a).astype(np.int8)


def _obj_sign(det):
    return (det > 0).astype(np.int8) - (det < 0).astype(np.int8)


def _maxabs(*arrs):
    m = np.abs(arrs[0])
    for a in arrs[1:]:
        np.maximum(m, np.abs(a), out=m)
    return m


def orient_det_small(abx, aby, acx, acy):
    """abx*acy - aby*acx in int64; exact when every |input| < 2^31."""
    return abx * acy - aby * acx


def orient_sign(ax, ay, bx, by, cx, cy, stats=None):
    """Sign of orient2d(a, b, c): +1 counter-clockwise, -1 clockwise, 0 collinear."""
    ax, ay, bx, by, cx, cy = map(_i64, (ax, ay, bx, by, cx, cy))
    abx = bx - ax
    aby = by - ay
    acx = cx - ax
    acy = cy - ay
    n = abx.shape[0] if abx.ndim else 1
    if stats is not None:
        stats.orient += n
    det = orient_det_small(abx, aby, acx, acy)
    out = _sign(det)
    big = _maxabs(abx, aby, acx, acy) >= _TWO31
    if np.any(big):
        i = np.nonzero(big)[0]
        out[i] = _orient_sign_big(abx[i], aby[i], acx[i], acy[i], det[i])
    return out


def _orient_sign_big(abx, aby, acx, acy, det_wrapped):
    fa = abx.astype(_F64) * acy.astype(_F64)
    fb = aby.astype(_F64) * acx.astype(_F64)
    fdet = fa - fb
    err = _ORIENT_EPS * (np.abs(fa) + np.abs(fb))
    out = _sign(fdet)
    und = ~(np.abs(fdet) > err)
    if np.any(und):
        wrap_ok = und & (np.abs(fdet) + err < _TWO62)
        out[wrap_ok] = _sign(det_wrapped[wrap_ok])
        rest = np.nonzero(und & ~wrap_ok)[0]
        if rest.size:
            d = (abx[rest].astype(object) * acy[rest].astype(object)
                 - aby[rest].astype(object) * acx[rest].astype(object))
            out[rest] = _obj_sign(d)
    return out


def orient_det_sum(ax, ay, bx, by, cx, cy):
    """Exact sum over all elements of orient2d determinants (twice the signed
    areas) as a Python int."""
    ax, ay, bx, by, cx, cy = map(_i64, (ax, ay, bx, by, cx, cy))
    abx = bx - ax
    aby = by - ay
    acx = cx - ax
    acy = cy - ay
    big = _maxabs(abx, aby, acx, acy) >= _TWO31
    small = ~big
    total = 0
    if np.any(small):
        det = orient_det_small(abx[small], aby[small], acx[small], acy[small])
        # Split every |det| < 2^63 into 32-bit halves; blocks of 2^20 keep the
        # int64 sums of the halves below 2^52.
        hi = det >> 32
        lo = det & 0xFFFFFFFF
        for s in range(0, det.shape[0], 1 << 20):
            total += (int(hi[s:s + (1 << 20)].sum()) << 32) + int(lo[s:s + (1 << 20)].sum())
    if np.any(big):
        i = np.nonzero(big)[0]
        d = (abx[i].astype(object) * acy[i].astype(object)
             - aby[i].astype(object) * acx[i].astype(object))
        total += int(d.sum())
    return total


def _incircle_int64(adx, ady, bdx, bdy, cdx, cdy):
    """The incircle determinant in int64 with wrap-around: exact whenever the
    true value lies in (-2^63, 2^63)."""
    alift = adx * adx + ady * ady
    blift = bdx * bdx + bdy * bdy
    clift = cdx * cdx + cdy * cdy
    return (alift * (bdx * cdy - cdx * bdy) + blift * (cdx * ady - adx * cdy)
            + clift * (adx * bdy - bdx * ady))


def incircle_sign(ax, ay, bx, by, cx, cy, dx, dy, stats=None):
    """For counter-clockwise a, b, c: +1 if d is strictly inside their
    circumcircle, 0 on it, -1 outside (the sign flips for clockwise a, b, c)."""
    ax, ay, bx, by, cx, cy, dx, dy = map(_i64, (ax, ay, bx, by, cx, cy, dx, dy))
    adx = ax - dx
    ady = ay - dy
    bdx = bx - dx
    bdy = by - dy
    cdx = cx - dx
    cdy = cy - dy
    n = adx.shape[0]
    if stats is not None:
        stats.incircle += n
    out = np.zeros(n, dtype=np.int8)
    L = _maxabs(adx, ady, bdx, bdy, cdx, cdy)
    # Tier 1: L < 2^15 gives |det| <= 6 L^4 < 2^63.
    small = L < _TWO15
    if np.any(small):
        i = np.nonzero(small)[0]
        out[i] = _sign(_incircle_int64(adx[i], ady[i], bdx[i], bdy[i], cdx[i], cdy[i]))
        if stats is not None:
            stats.incircle_int64 += i.size
    big = np.nonzero(~small)[0]
    if big.size == 0:
        return out
    a_x, a_y, b_x, b_y, c_x, c_y = (v[big] for v in (adx, ady, bdx, bdy, cdx, cdy))
    fax, fay, fbx, fby, fcx, fcy = (v.astype(_F64) for v in (a_x, a_y, b_x, b_y, c_x, c_y))
    alift = fax * fax + fay * fay
    blift = fbx * fbx + fby * fby
    clift = fcx * fcx + fcy * fcy
    bc1 = fbx * fcy
    bc2 = fcx * fby
    ca1 = fcx * fay
    ca2 = fax * fcy
    ab1 = fax * fby
    ab2 = fbx * fay
    fdet = alift * (bc1 - bc2) + blift * (ca1 - ca2) + clift * (ab1 - ab2)
    perm = (alift * (np.abs(bc1) + np.abs(bc2)) + blift * (np.abs(ca1) + np.abs(ca2))
            + clift * (np.abs(ab1) + np.abs(ab2)))
    err = _INCIRCLE_EPS * perm
    res = _sign(fdet)
    und = ~(np.abs(fdet) > err)
    if stats is not None:
        stats.incircle_filtered += int(big.size - np.count_nonzero(und))
    if np.any(und):
        wrap_ok = und & (np.abs(fdet) + err < _TWO62)
        w = np.nonzero(wrap_ok)[0]
        if w.size:
            res[w] = _sign(_incircle_int64(a_x[w], a_y[w], b_x[w], b_y[w], c_x[w], c_y[w]))
        r = np.nonzero(und & ~wrap_ok)[0]
        if r.size:
            o = [v[r].astype(object) for v in (a_x, a_y, b_x, b_y, c_x, c_y)]
            res[r] = _obj_sign(_incircle_int64(*o))
        if stats is not None:
            stats.incircle_int64 += w.size
            stats.incircle_bigint += r.size
    out[big] = res
    return out


def _cross_sign(px, py, qx, qy):
    """Sign of px*qy - py*qx for int64 arrays with |values| < 2^54."""
    out = _sign(px * qy - py * qx)
    big = _maxabs(px, py, qx, qy) >= _TWO31
    if np.any(big):
        i = np.nonzero(big)[0]
        d = (px[i].astype(object) * qy[i].astype(object)
             - py[i].astype(object) * qx[i].astype(object))
        out[i] = _obj_sign(d)
    return out


def tiebreak_sign(ex, ey, fx, fy, stats=None):
    """Dyken-Floater preferred-direction rule with d1 = (1, 0), d2 = (1, 1)
    between the diagonals e and f (integer vectors): +1 if e wins, -1 if f
    wins, 0 only when e and f are parallel.

    e wins iff (e.d1)^2 |f|^2 > (f.d1)^2 |e|^2, or those are equal and
    (e.d2)^2 |f|^2 > (f.d2)^2 |e|^2.  The two differences factor as
      (e.d1)^2 |f|^2 - (f.d1)^2 |e|^2 = (ex fy)^2 - (fx ey)^2
      (e.d2)^2 |f|^2 - (f.d2)^2 |e|^2 = 2 (ey fx - ex fy) (ex fx - ey fy)
    so only signs of products of two coordinates are needed."""
    ex, ey, fx, fy = map(_i64, (ex, ey, fx, fy))
    if stats is not None:
        stats.tiebreak += ex.shape[0]
    # Signs of |ex fy| - |fx ey|, of ey fx - ex fy and of ex fx - ey fy,
    # each written as px*qy - py*qx.
    s1 = _cross_sign(np.abs(ex), np.abs(fx), np.abs(ey), np.abs(fy))
    s2a = _cross_sign(fx, fy, ex, ey)
    s2b = _cross_sign(ex, fy, ey, fx)
    s2 = (s2a * s2b).astype(np.int8)
    return np.where(s1 != 0, s1, s2).astype(np.int8)
