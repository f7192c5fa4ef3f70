"""Smooth analytic ground surface z(x, y).

A tilted plane, a few rational hills and hollows, and one valley along a
line.  Only +, -, *, / are used (no transcendental functions), so values are
bit-identical on every platform.  Coordinates are local (CRS minus the LAS
offset), in CRS units (metres); heights are metres above the vertical datum.
"""
import math

import numpy as np

from .rng import Stream


class Terrain:
    def __init__(self, seed: int, width: float, height: float):
        rs = Stream(seed, "terrain")
        size = max(min(width, height), 1e-6)
        span = max(width, height, 1e-6)
        # Relief grows with the extent but stays terrain-like: a 50 m patch
        # has a few metres of relief, a 10 km one a few hundred.
        relief = min(0.12 * size, 25.0 + 0.02 * size)
        self.base = rs.uniform(40.0, 400.0)
        grade = rs.uniform(0.0, 0.04)
        ang = rs.uniform(0.0, 2.0 * math.pi)
        self.gx = grade * math.cos(ang)
        self.gy = grade * math.sin(ang)
        self.cx = 0.5 * width
        self.cy = 0.5 * height
        self.hills = []
        for k in range(4):
            hx = rs.uniform(-0.1, 1.1) * width
            hy = rs.uniform(-0.1, 1.1) * height
            r = rs.uniform(0.08, 0.35) * span
            amp = rs.uniform(0.25, 1.0) * relief * (1.0 if k != 2 else -0.6)
            self.hills.append((hx, hy, 1.0 / (r * r), amp))
        # A valley: depth profile across the line a*x + b*y = c.
        va = rs.uniform(0.0, math.pi)
        self.va = math.cos(va)
        self.vb = math.sin(va)
        self.vc = self.va * rs.uniform(0.2, 0.8) * width + self.vb * rs.uniform(0.2, 0.8) * height
        w = rs.uniform(0.04, 0.1) * span
        self.vinv = 1.0 / (w * w)
        self.vdepth = -rs.uniform(0.3, 0.8) * relief

    def __call__(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Ground height at local (x, y); arrays of equal shape, float64."""
        z = (x - self.cx) * self.gx
        z += (y - self.cy) * self.gy
        z += self.base
        t = np.empty_like(z)
        u = np.empty_like(z)
        for hx, hy, inv, amp in self.hills:
            np.subtract(x, hx, out=t)
            t *= t
            np.subtract(y, hy, out=u)
            u *= u
            t += u
            t *= inv
            t += 1.0
            np.multiply(t, t, out=u)
            np.divide(amp, u, out=u)
            z += u
        np.multiply(x, self.va, out=t)
        np.multiply(y, self.vb, out=u)
        t += u
        t -= self.vc
        t *= t
        t *= self.vinv
        t += 1.0
        np.divide(self.vdepth, t, out=t)
        z += t
        return z

    def describe(self) -> dict:
        return {"base": self.base, "grade": [self.gx, self.gy], "hills": len(self.hills)}
