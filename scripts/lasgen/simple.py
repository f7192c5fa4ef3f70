"""Grid, uniform and gridded-DEM sections.

Each section covers a region (x0, y0, w, h) in local coordinates and yields
exactly `count` points; point i is a pure function of i.  Heights follow the
shared Terrain so neighbouring sections of a mixed cloud join smoothly.
"""
import math

import numpy as np

from .las import Batch
from .rng import derive_key, hash_indices, unit16


def _lattice_box(region, sc):
    x0, y0, w, h = region
    X0 = math.ceil(x0 / sc)
    Y0 = math.ceil(y0 / sc)
    X1 = max(X0, math.floor((x0 + w) / sc))
    Y1 = max(Y0, math.floor((y0 + h) / sc))
    return X0, Y0, X1, Y1



def patch_nodes(patches, cum, i):
    """Lattice integers (X, Y), int64 arrays, of the global indices i over
    rotated-grid patches.  Patch k holds the indices cum[k] <= i < cum[k + 1]
    row by row, "cols" nodes a row, from "origin" along e1 = (a, b) and
    e2 = (-b, a)."""
    k = np.searchsorted(cum, i, side="right") - 1
    li = i - cum[k]
    cols = np.array([p["cols"] for p in patches], dtype=np.int64)[k]
    ox = np.array([p["origin"][0] for p in patches], dtype=np.int64)[k]
    oy = np.array([p["origin"][1] for p in patches], dtype=np.int64)[k]
    a = np.array([p["e1"][0] for p in patches], dtype=np.int64)[k]
    b = np.array([p["e1"][1] for p in patches], dtype=np.int64)[k]
    ix = li % cols
    iy = li // cols
    return ox + ix * a - iy * b, oy + ix * b + iy * a


class _Section:
    def __init__(self, seed, index, region, count, scale, terrain):
        self.seed = seed
        self.index = index
        self.region = tuple(float(v) for v in region)
        self.count = int(count)
        self.sc = float(scale[0])
        self.scz = float(scale[2])
        self.terrain = terrain

    def _z(self, X, Y, noise=None):
        z = self.terrain(X * self.sc, Y * self.sc)
        if noise is not None:
            z += noise
        return np.rint(z * (1.0 / self.scz)).astype(np.int32)

    def batches(self, chunk):
        for i0 in range(0, self.count, chunk):
            yield self._batch(np.arange(i0, min(i0 + chunk, self.count), dtype=np.int64))

    def _base_describe(self, offset):
        x0, y0, w, h = self.region
        return {"kind": self.kind, "region": [x0 + offset[0], y0 + offset[1], w, h],
                "count": self.count}


class GridSection(_Section):
    """A square grid with an integer lattice step, filled row by row (the
    last row may be partial)."""

    kind = "grid"

    def __init__(self, seed, index, region, count, scale, terrain):
        super().__init__(seed, index, region, count, scale, terrain)
        X0, Y0, X1, Y1 = _lattice_box(self.region, self.sc)
        w, h = self.region[2], self.region[3]
        n = max(self.count, 1)
        self.cols = max(1, int(math.ceil(math.sqrt(n * w / h)))) if h > 0 else n
        self.rows = max(1, (n + self.cols - 1) // self.cols)
        sx = (X1 - X0) // max(self.cols - 1, 1)
        sy = (Y1 - Y0) // max(self.rows - 1, 1)
        self.step = max(1, min(sx, sy))
        self.origin = (X0, Y0)

    def _batch(self, i):
        ix = i % self.cols
        iy = i // self.cols
        X = self.origin[0] + ix * self.step
        Y = self.origin[1] + iy * self.step
        inten = np.full(len(i), 500, dtype=np.uint16)
        return Batch.simple(X.astype(np.int32), Y.astype(np.int32), self._z(X, Y), inten)

    def describe(self, offset):
        d = self._base_describe(offset)
        d.update({"origin": list(self.origin), "step": self.step, "cols": self.cols,
                  "rows": self.rows})
        return d


class UniformSection(_Section):
    """Independent uniform lattice points in the region's lattice box."""

    kind = "uniform"

    def __init__(self, seed, index, region, count, scale, terrain):
        super().__init__(seed, index, region, count, scale, terrain)
        self.box = _lattice_box(self.region, self.sc)
        if self.box[2] - self.box[0] >= 1 << 32 or self.box[3] - self.box[1] >= 1 << 32:
            raise ValueError("uniform region too large for the lattice")
        self.key = derive_key(seed, "uniform", index)
        self.key2 = derive_key(seed, "uniform-z", index)

    def _batch(self, i):
        X0, Y0, X1, Y1 = self.box
        h = hash_indices(i, self.key)
        lo = h & np.uint64(0xFFFFFFFF)
        hi = h >> 32
        # floor(u * span) with u = bits / 2^32: exact in uint64 as span < 2^32.
        X = X0 + ((lo * np.uint64(X1 - X0 + 1)) >> 32).astype(np.int64)
        Y = Y0 + ((hi * np.uint64(Y1 - Y0 + 1)) >> 32).astype(np.int64)
        v = unit16(hash_indices(i, self.key2))
        noise = (v[:, 0] + v[:, 1] - 1.0) * 0.07
        inten = (300.0 + 500.0 * v[:, 2]).astype(np.uint16)
        return Batch.simple(X.astype(np.int32), Y.astype(np.int32), self._z(X, Y, noise), inten)

    def describe(self, offset):
        d = self._base_describe(offset)
        d["lattice_box"] = list(self.box)
        return d


class DemSection(_Section):
    """Gridded DEM tiles: the region is split into 2x2 quadrants, each holding
    one square grid spanned by integer step vectors e1 = (a, b), e2 = (-b, a)
    (axis-aligned when b = 0, else rotated); the last row of a grid may be
    partial.  Cells are exact lattice squares, so their corners are co-circular."""

    kind = "dem"
    DIRECTIONS = [(1, 0), (4, 3), (12, 5), (1, 0)]

    def __init__(self, seed, index, region, count, scale, terrain):
        super().__init__(seed, index, region, count, scale, terrain)
        x0, y0, w, h = self.region
        per = [self.count // 4] * 4
        per[3] += self.count - sum(per)
        self.patches = []
        for k, (da, db) in enumerate(self.DIRECTIONS):
            qx = x0 + (k % 2) * 0.5 * w
            qy = y0 + (k // 2) * 0.5 * h
            QX0, QY0, QX1, QY1 = _lattice_box((qx, qy, 0.5 * w, 0.5 * h), self.sc)
            n = per[k]
            side = max(2, int(math.ceil(math.sqrt(max(n, 1)))))
            rows = max(1, (n + side - 1) // side)
            norm = math.hypot(da, db)
            ca, sa = da / norm, db / norm
            room = 0.96 * min(QX1 - QX0, QY1 - QY0)
            span = max(side - 1, 1) * ca + max(rows - 1, 0) * sa
            span_y = max(side - 1, 1) * sa + max(rows - 1, 0) * ca
            g = room / max(span, span_y, 1e-9)
            if k == 3:
                g *= 0.7   # a second axis-aligned grid with a finer step
            a = int(math.floor(g * ca))
            b = int(math.floor(g * sa))
            if a < 1:
                a, b = 1, 0
            ox = QX0 + int(0.02 * (QX1 - QX0)) + max(rows - 1, 0) * b
            oy = QY0 + int(0.02 * (QY1 - QY0))
            self.patches.append({"origin": [ox, oy], "e1": [a, b], "e2": [-b, a],
                                 "cols": side, "rows": rows, "count": n})
        self.cum = np.concatenate([[0], np.cumsum(per)]).astype(np.int64)

    def _batch(self, i):
        X, Y = patch_nodes(self.patches, self.cum, i)
        inten = np.full(len(i), 600, dtype=np.uint16)
        return Batch.simple(X.astype(np.int32), Y.astype(np.int32), self._z(X, Y), inten)

    def describe(self, offset):
        d = self._base_describe(offset)
        d["dem_patches"] = [dict(p) for p in self.patches]
        return d
