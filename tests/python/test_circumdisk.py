"""The certification's circumdisk bounds are sound: checked with exact
rational arithmetic on random, skinny, extreme and exactly-touching cases.

For a counter-clockwise triangle with circumcentre X and radius r, the tool
must print xmin <= X.x - r, xmax >= X.x + r (and the same in y).  With X
rational and r^2 rational, "xmin <= X.x - r" is "X.x - xmin >= 0 and
(X.x - xmin)^2 >= r^2", decided exactly with fractions.
"""
import subprocess
from fractions import Fraction

import numpy as np
import pytest

L = 2**31 - 1
SEED = 20261122


def circle(t):
    ax, ay, bx, by, cx, cy = (int(v) for v in t)
    bx, by, cx, cy = bx - ax, by - ay, cx - ax, cy - ay
    det = bx * cy - by * cx
    bb, cc = bx * bx + by * by, cx * cx + cy * cy
    ux = Fraction(cy * bb - by * cc, 2 * det)
    uy = Fraction(bx * cc - cx * bb, 2 * det)
    return ax + ux, ay + uy, ux * ux + uy * uy, det


def gen_cases(rng):
    cases = []
    # random triangles over the whole range
    cases.append(rng.integers(0, L + 1, size=(4000, 6)))
    # small triangles at the extremes of the range
    for base in (0, L - 64):
        cases.append(base + rng.integers(0, 65, size=(2000, 6)))
    # skinny: c close to the line a-b (large radius, cancellation)
    a = rng.integers(0, L + 1, size=(3000, 2))
    b = rng.integers(0, L + 1, size=(3000, 2))
    t = rng.random((3000, 1))
    c = np.clip(np.rint(a + t * (b - a)).astype(np.int64) + rng.integers(-2, 3, size=(3000, 2)),
                0, L)
    cases.append(np.hstack([a, b, c]))
    # right triangles with integer centres: the disk touches lattice lines exactly
    cx = rng.integers(1 << 20, L - (1 << 20), size=3000)
    cy = rng.integers(1 << 20, L - (1 << 20), size=3000)
    r = rng.integers(1, 1 << 19, size=3000)
    cases.append(np.stack([cx - r, cy, cx + r, cy, cx, cy + r], axis=1))
    cases.append(np.stack([cx, cy - r, cx + r, cy, cx - r, cy], axis=1))
    # 3-4-5 style triangles on a circle of radius 5k centred on lattice points
    k = rng.integers(1, 1 << 18, size=3000)
    cases.append(np.stack([cx + 3 * k, cy + 4 * k, cx - 5 * k, cy, cx + 4 * k, cy - 3 * k], axis=1))
    out = np.vstack(cases).astype(np.int64)
    assert out.min() >= 0 and out.max() <= L
    return out


def run(tool, cases):
    text = "\n".join(" ".join(str(int(v)) for v in row) for row in cases) + "\n"
    proc = subprocess.run([str(tool("disk_eval"))], input=text, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    return proc.stdout.splitlines()


def test_bounds_are_sound_and_useful(tool):
    rng = np.random.default_rng(SEED)
    cases = gen_cases(rng)
    lines = run(tool, cases)
    assert len(lines) == len(cases)
    checked = tight = 0
    for row, line in zip(cases, lines):
        ax, ay, bx, by, cx, cy = (int(v) for v in row)
        det = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
        parts = line.split()
        if det <= 0:
            assert parts == ["0"], f"{row.tolist()}: not counter-clockwise, got {line}"
            continue
        assert parts[0] == "1", f"{row.tolist()}: counter-clockwise, got {line}"
        X, Y, r2, _ = circle(row)
        xmin, ymin, xmax, ymax = (Fraction(float.fromhex(p)) for p in parts[1:])
        for lo, centre in ((xmin, X), (ymin, Y)):
            gap = centre - lo
            assert gap >= 0 and gap * gap >= r2, f"{row.tolist()}: lower bound {lo} inside the disk"
        for hi, centre in ((xmax, X), (ymax, Y)):
            gap = hi - centre
            assert gap >= 0 and gap * gap >= r2, f"{row.tolist()}: upper bound {hi} inside the disk"
        checked += 1
        # for triangles that are not skinny the slack is negligible
        r = float(r2) ** 0.5
        if r < 1e7 and float(xmax - xmin) <= 2 * r + 1e-3:
            tight += 1
    assert checked > 12000
    assert tight > 5000


def test_clockwise_and_collinear_have_no_bounds(tool):
    cases = np.array([[0, 0, 0, 10, 10, 0],      # clockwise
                      [0, 0, 5, 5, 10, 10],      # collinear
                      [L, L, 0, 0, L, L],        # repeated vertex
                      [0, 0, L, 0, 0, L]], dtype=np.int64)
    out = run(tool, cases)
    assert out[:3] == ["0", "0", "0"] and out[3].startswith("1 ")


@pytest.mark.sanitize
def test_bad_input_is_refused(tool):
    proc = subprocess.run([str(tool("disk_eval"))], input="0 0 1 1 2\n", capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 3
    proc = subprocess.run([str(tool("disk_eval"))], input=f"0 0 {L + 1} 0 0 1\n",
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 3 and "out of range" in proc.stderr
