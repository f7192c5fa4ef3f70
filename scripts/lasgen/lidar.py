"""Airborne LiDAR survey section.

Geometry (all lengths in CRS units, coordinates local = CRS minus offset):

* Flight: parallel main strips at a common heading, adjacent strips
  overlapping, flown alternately in opposite directions, then one or two cross
  strips at right angles (tie lines).  Each strip is a sequence of scan lines
  from an oscillating mirror: line l advances along track by the line spacing,
  pulse j of m sweeps across track, every other line in the opposite sense
  (the zig-zag pattern), slowing at the swath edges.  Pulse positions carry a
  small jitter and the strips a slow lateral wobble.
* Ground: the analytic Terrain surface.
* Lakes: disks with no returns at all (water voids).
* Blocks: the region is cut into square blocks; a block holds a building (a
  rectangle with a flat or gabled roof), a forest stand (a disk of canopy),
  or open ground.  Pulses through canopy give 1-4 returns and pulses on a roof
  edge give 2: all returns of a pulse share the pulse's X and Y exactly and
  have distinct Z.
* DEM patches: rectangles where scan returns are replaced by the nodes of an
  exact lattice grid (axis-aligned or rotated by an integer step vector), so
  every grid cell is four co-circular points.
* A small fraction of pulses is recorded twice (identical records), and a very
  small fraction is noise (class 7) far above or below the ground.

Counting: the number of scan points is exactly count - dem_points.  The main
strips are thinned by a per-pulse keep test so that they yield slightly less
than that (estimated by counting all pulses, or a large sample); the cross
strips, flown last, carry the rest and are cut where the count is reached.
Should the cross strips run out, they are flown again with a shifted scan
phase.  Every pulse's output is a pure function of its index, so the stream
does not depend on how it is chunked.
"""
import math

import numpy as np

from .las import Batch
from .rng import Stream, derive_key, hash_indices, remix, unit16
from .simple import patch_nodes

FOV_HALF_DEG = 20.0
CROSS_FRACTION = 0.04
EXACT_COUNT_PULSES = 1 << 20
SAMPLE_PULSES = 1 << 18
# Bound on the relative error of the systematic line sample of the main strips.
SAMPLE_ERROR = 0.004

CLS_GROUND, CLS_LOW, CLS_MED, CLS_HIGH, CLS_BUILDING, CLS_NOISE = 2, 3, 4, 5, 6, 7
_INTENSITY_BASE = np.zeros(256, dtype=np.uint32)
_INTENSITY_BASE[[2, 3, 4, 5, 6, 7]] = [700, 300, 260, 220, 950, 100]
# 256 / (1 + 0.6 (r - 1)) for return number r.
_RETURN_GAIN = (256.0 / (1.0 + 0.6 * np.maximum(np.arange(16) - 1, 0))).astype(np.uint32)

# Block flags: low bits the block type; then "touches a lake / DEM patch".
TYPE_OPEN, TYPE_BUILDING, TYPE_FOREST = 0, 1, 2
FLAG_TYPE, FLAG_LAKE, FLAG_DEM = 3, 4, 8


def _clip_band(poly, c_lo, c_hi):
    """Clips a convex polygon [(a, c), ...] to c_lo <= c <= c_hi; returns vertices."""
    def clip(pts, keep, inter):
        out = []
        n = len(pts)
        for i in range(n):
            p, q = pts[i], pts[(i + 1) % n]
            kp, kq = keep(p), keep(q)
            if kp:
                out.append(p)
            if kp != kq:
                out.append(inter(p, q))
        return out

    def at(level):
        return lambda p, q: (p[0] + (q[0] - p[0]) * (level - p[1]) / (q[1] - p[1]), level)

    pts = clip(poly, lambda p: p[1] >= c_lo, at(c_lo))
    if pts:
        pts = clip(pts, lambda p: p[1] <= c_hi, at(c_hi))
    return pts


class LidarSection:
    """count points of an airborne survey over the region (x0, y0, w, h)."""

    kind = "lidar"

    def __init__(self, seed, index, region, count, scale, terrain,
                 dem_fraction=0.04, dup_fraction=0.002, noise_fraction=5e-5):
        self.seed = seed
        self.index = index
        self.x0, self.y0, self.w, self.h = (float(v) for v in region)
        self.count = int(count)
        self.sc = float(scale[0])
        self.scz = float(scale[2])
        self.terrain = terrain
        self.dup_fraction = float(dup_fraction)
        self.noise_fraction = float(noise_fraction)
        self.keys = [derive_key(seed, "lidar", index, k) for k in range(4)]
        self.dup_level = int(round(self.dup_fraction * 65536))
        self.noise_level = int(round(self.noise_fraction * 65536))
        self.stats = {"scan_points": 0, "multi_return_points": 0, "duplicate_points": 0,
                      "noise_points": 0, "pulses_emitted": 0}
        rs = Stream(seed, "lidar-layout", index)
        self.L = max(min(self.w, self.h), 1e-3)
        self.area = self.w * self.h
        rho = max(self.count, 1) / max(self.area, 1e-9)
        self.spacing0 = 1.0 / math.sqrt(rho)
        # Integer-lattice bounds of the region (points never leave it).
        self.Xlo = math.ceil(self.x0 / self.sc)
        self.Xhi = math.floor((self.x0 + self.w) / self.sc)
        self.Ylo = math.ceil(self.y0 / self.sc)
        self.Yhi = math.floor((self.y0 + self.h) / self.sc)
        self._place_dem(rs, dem_fraction)
        self._place_lakes(rs)
        self._place_blocks(rs)
        self._plan_flight(rs)

    # ------------------------------------------------------------ layout

    def _place_dem(self, rs, dem_fraction):
        self.patches = []
        target = int(round(self.count * dem_fraction))
        if self.count < 2000 or target < 32:
            self.dem_count = 0
            self.dem_cum = np.zeros(1, dtype=np.int64)
            return
        kinds = [0.0, 0.0, rs.uniform(20.0, 40.0)]  # rotation of each patch, degrees
        per = target // len(kinds)
        g = 1.5 * self.spacing0
        gi = max(1, int(round(g / self.sc)))
        placed = []
        for k, ang in enumerate(kinds):
            a = int(round(gi * math.cos(math.radians(ang))))
            b = int(round(gi * math.sin(math.radians(ang))))
            if a <= 0:
                a, b = gi, 0
            aspect = rs.uniform(0.6, 1.6)
            cols = max(2, int(round(math.sqrt(per * aspect))))
            rows = max(2, per // cols)
            for _attempt in range(8):
                ok = False
                glen = math.hypot(a, b) * self.sc
                # Lattice bounding box of the node set (a > 0, b >= 0).
                bw = ((cols - 1) * a + (rows - 1) * b) * self.sc
                bh = ((cols - 1) * b + (rows - 1) * a) * self.sc
                margin = 2.0 * glen
                if bw + 2 * margin < self.w and bh + 2 * margin < self.h:
                    for _t in range(60):
                        bx = self.x0 + margin + rs.uniform() * (self.w - bw - 2 * margin)
                        by = self.y0 + margin + rs.uniform() * (self.h - bh - 2 * margin)
                        box = (bx - margin, by - margin, bx + bw + margin, by + bh + margin)
                        if all(box[2] < o[0] or box[0] > o[2] or box[3] < o[1] or box[1] > o[3]
                               for o in placed):
                            ok = True
                            break
                if ok:
                    break
                cols = max(2, int(cols * 0.8))
                rows = max(2, int(rows * 0.8))
            if not ok:
                continue
            placed.append(box)
            ox = int(math.ceil(bx / self.sc)) + (rows - 1) * b
            oy = int(math.ceil(by / self.sc))
            self.patches.append({"origin": [ox, oy], "e1": [a, b], "e2": [-b, a],
                                 "cols": cols, "rows": rows, "count": cols * rows,
                                 "box": box})
        counts = [p["count"] for p in self.patches]
        self.dem_cum = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        self.dem_count = int(self.dem_cum[-1])

    def _place_lakes(self, rs):
        """Disks inside the region, clear of each other and of DEM patches by
        at least 30 % of their radius (so returns surround every lake)."""
        self.lakes = []
        if self.count < 500:
            return
        n = 1 + min(6, int(self.area / 3e6)) + (1 if rs.chance(0.5) else 0)
        for _ in range(n):
            r = min(rs.uniform(0.05, 0.1) * self.L, 300.0)
            if r < 4.0 * self.spacing0:
                continue
            margin = 3.0 * self.spacing0 + 0.3 * r
            if self.w <= 2 * (r + margin) or self.h <= 2 * (r + margin):
                continue
            for _t in range(60):
                cx = self.x0 + r + margin + rs.uniform() * (self.w - 2 * (r + margin))
                cy = self.y0 + r + margin + rs.uniform() * (self.h - 2 * (r + margin))
                clear = all(math.hypot(cx - o[0], cy - o[1]) > r + o[2] + margin + 0.3 * o[2]
                            for o in self.lakes)
                for p in self.patches:
                    bx0, by0, bx1, by1 = p["box"]
                    dx = max(bx0 - cx, 0.0, cx - bx1)
                    dy = max(by0 - cy, 0.0, cy - by1)
                    if math.hypot(dx, dy) <= r + margin:
                        clear = False
                if clear:
                    self.lakes.append((cx, cy, r))
                    break

    def _place_blocks(self, rs):
        bs = min(max(self.L / 10.0, 5.0), 60.0)
        self.bs = bs
        nbx = max(1, int(math.ceil(self.w / bs)))
        nby = max(1, int(math.ceil(self.h / bs)))
        self.nbx, self.nby = nbx, nby
        nb = nbx * nby
        ix = np.arange(nb, dtype=np.int64) % nbx
        iy = np.arange(nb, dtype=np.int64) // nbx
        bx0 = self.x0 + ix * bs
        by0 = self.y0 + iy * bs
        cx = bx0 + 0.5 * bs
        cy = by0 + 0.5 * bs

        def zone(n_centres, rmin, rmax, cap):
            f = np.zeros(nb)
            for _ in range(n_centres):
                zx = self.x0 + rs.uniform() * self.w
                zy = self.y0 + rs.uniform() * self.h
                r = min(rs.uniform(rmin, rmax) * self.L, cap)
                q = ((cx - zx) ** 2 + (cy - zy) ** 2) / (r * r)
                f = np.maximum(f, 1.0 / (1.0 + q * q))
            return f

        town = zone(1 + min(5, int(self.area / 4e6)), 0.12, 0.3, 900.0)
        forest = zone(2 + min(8, int(self.area / 3e6)), 0.08, 0.22, 900.0)
        u = unit16(hash_indices(np.arange(nb), derive_key(self.seed, "blocks", self.index)))
        btype = np.zeros(nb, dtype=np.int8)
        btype[u[:, 0] < 0.02 + 0.65 * town] = TYPE_BUILDING
        btype[(btype == TYPE_OPEN) & (u[:, 1] < 0.03 + 0.6 * forest)] = TYPE_FOREST
        for (lx, ly, lr) in self.lakes:
            near = np.hypot(cx - lx, cy - ly) < lr + bs
            btype[near] = TYPE_OPEN
        u2 = unit16(hash_indices(np.arange(nb), derive_key(self.seed, "blocks2", self.index)))
        # Buildings: footprint inside the block with margins, flat or gabled roof.
        self.b_x0 = bx0 + (0.12 + 0.18 * u[:, 2]) * bs
        self.b_x1 = bx0 + bs - (0.12 + 0.18 * u[:, 3]) * bs
        self.b_y0 = by0 + (0.12 + 0.18 * u2[:, 0]) * bs
        self.b_y1 = by0 + bs - (0.12 + 0.18 * u2[:, 1]) * bs
        height = 3.0 + 11.0 * u2[:, 2]
        self.b_roof = self.terrain(cx, cy) + height
        roof_kind = (u2[:, 3] * 3).astype(np.int8)  # 0 flat, 1 ridge along x, 2 along y
        pitch = 0.2 + 0.5 * ((u2[:, 3] * 3) % 1.0)
        self.b_pitch_x = np.where(roof_kind == 2, pitch, 0.0)  # slope across x (ridge along y)
        self.b_pitch_y = np.where(roof_kind == 1, pitch, 0.0)
        self.b_midx = 0.5 * (self.b_x0 + self.b_x1)
        self.b_midy = 0.5 * (self.b_y0 + self.b_y1)
        self.b_halfx = 0.5 * (self.b_x1 - self.b_x0)
        self.b_halfy = 0.5 * (self.b_y1 - self.b_y0)
        # Forest stands: a canopy disk per block (neighbouring disks merge).
        self.f_cx = cx + (u[:, 2] - 0.5) * 0.2 * bs
        self.f_cy = cy + (u[:, 3] - 0.5) * 0.2 * bs
        fr = (0.55 + 0.2 * u2[:, 0]) * bs
        self.f_r2 = fr * fr
        self.f_height = 6.0 + 20.0 * u2[:, 1]
        self.tree_spacing = min(max(0.25 * bs, 2.0), 6.0)
        self.n_buildings = int((btype == TYPE_BUILDING).sum())
        self.n_forest = int((btype == TYPE_FOREST).sum())
        flag = btype.astype(np.uint8)
        bx1 = bx0 + bs
        by1 = by0 + bs
        for (lx, ly, lr) in self.lakes:
            dx = np.maximum(np.maximum(bx0 - lx, lx - bx1), 0.0)
            dy = np.maximum(np.maximum(by0 - ly, ly - by1), 0.0)
            flag[dx * dx + dy * dy <= lr * lr * 1.0001 + 1e-6] |= FLAG_LAKE
        for pt in self.patches:
            px0, py0, px1, py1 = pt["box"]
            flag[(bx1 >= px0) & (bx0 <= px1) & (by1 >= py0) & (by0 <= py1)] |= FLAG_DEM
        self.bflag = flag

    def _strip_table(self, spacing, rs_values):
        """Strip geometry for a nominal pulse spacing (along and across track)."""
        heading, cross_shift, lam_frac, phases, overlap = rs_values
        cx, cy = self.x0 + 0.5 * self.w, self.y0 + 0.5 * self.h
        hw, hh = 0.5 * self.w, 0.5 * self.h
        corners = [(-hw, -hh), (hw, -hh), (hw, hh), (-hw, hh)]
        strips = []

        def frame(theta):
            ct, st = math.cos(theta), math.sin(theta)
            return ct, st, [(x * ct + y * st, -x * st + y * ct) for x, y in corners]

        ct, st, poly = frame(heading)
        c_min = min(p[1] for p in poly)
        c_max = max(p[1] for p in poly)
        span_c = c_max - c_min
        swath = min(700.0, span_c / (1.0 + 2.0 * (1.0 - overlap)))
        n_main = max(3, int(math.ceil((span_c - swath) / (swath * (1.0 - overlap)) - 1e-9)) + 1)
        step = (span_c - swath) / (n_main - 1)
        # Pulses per scan line and line spacing follow the nominal spacing.
        m = max(4, int(round(swath / spacing)))
        d = spacing
        runin = 2.0 * spacing + 0.01 * swath
        centres = [(c_min + 0.5 * swath + k * step, heading, ct, st, poly) for k in range(n_main)]
        cth, cst, cpoly = frame(heading + 0.5 * math.pi)
        ncross = 1 if n_main < 8 else 2
        if ncross == 1:
            ccs = [cross_shift * span_c]
        else:
            ccs = [(cross_shift - 0.25) * span_c, (cross_shift + 0.25) * span_c]
        centres += [(c, heading + 0.5 * math.pi, cth, cst, cpoly) for c in ccs]
        cum = [0]
        for k, (cc, th, c1, s1, pg) in enumerate(centres):
            pts = _clip_band(pg, cc - 0.5 * swath, cc + 0.5 * swath)
            if not pts:
                pts = [(0.0, cc)]
            a_lo = min(p[0] for p in pts) - runin
            a_hi = max(p[0] for p in pts) + runin
            lines = int(math.ceil((a_hi - a_lo) / d)) + 1
            forward = k % 2 == 0
            strips.append({"c": cc, "heading": th, "cos": c1, "sin": s1, "a_lo": a_lo,
                           "a_hi": a_hi, "a0": a_lo if forward else a_hi,
                           "dir": 1.0 if forward else -1.0, "lines": lines,
                           "pulses": lines * m, "cross": k >= n_main,
                           "phase": phases[k % len(phases)]})
            cum.append(cum[-1] + lines * m)
        return {"strips": strips, "cum": np.array(cum, dtype=np.int64), "m": m, "d": d,
                "swath": swath, "n_main": n_main, "centre": (cx, cy),
                "lam": max(lam_frac * span_c, 10.0 * d), "overlap": 1.0 - step / swath}

    def _plan_flight(self, rs):
        self.n_scan = self.count - self.dem_count
        heading = math.radians(rs.uniform(-12.0, 12.0)) + (0.5 * math.pi if rs.chance(0.5) else 0.0)
        rs_values = (heading, rs.uniform(-0.15, 0.15), rs.uniform(0.4, 0.9),
                     [rs.uniform() for _ in range(16)], rs.uniform(0.25, 0.35))
        spacing = self.spacing0 * 0.9
        self.thr = np.uint64(1 << 32)
        self.q = 1.0
        # Refine the pulse spacing until the main strips yield a little more
        # than their share (at most ~15 % is then thinned away).
        for it in range(10):
            self._set_plan(self._strip_table(spacing, rs_values))
            if self.n_scan <= 0:
                break
            target = self.n_scan * (1.0 - CROSS_FRACTION)
            mean, se = self._estimate_main()
            expected = mean * self.P_main
            need = target * (1.0 + 4.0 * se + 0.002)
            if expected >= need and (expected * 0.85 <= need or it >= 6):
                self.q = target / expected
                self.thr = np.uint64(int(self.q * (1 << 32)))
                break
            spacing *= 0.98 * math.sqrt(expected / need) if expected > 0 else 0.5

    def _set_plan(self, plan):
        self.plan = plan
        st = plan["strips"]
        self.m = plan["m"]
        self.d = plan["d"]
        self.cum = plan["cum"]
        self.P = int(self.cum[-1])
        self.n_main = plan["n_main"]
        self.P_main = int(self.cum[self.n_main])
        self.P_cross = self.P - self.P_main
        self.half_swath = 0.5 * plan["swath"]
        self.jitter = 0.3 * self.d
        self.wobble = 0.004 * plan["swath"]
        self.inv_lam = 1.0 / plan["lam"]
        # Scan pattern of one line: fraction of the line's duration at pulse
        # j, and the across-track position in [-1, 1] for a left-to-right
        # line (the mirror slows towards the swath edges).
        m = self.m
        self.t_tab = (np.arange(m) + 0.5) * (1.0 / m)
        tri = self.t_tab * 2.0 - 1.0
        self.u_tab = tri * (1.25 - 0.25 * tri * tri)
        # Scan direction (bit 6: set on left-to-right lines) and edge of
        # flight line (bit 7: first and last pulse of a line).
        tab = np.zeros((2, m), dtype=np.uint8)
        tab[0, :] = 64
        tab[:, 0] |= 128
        tab[:, m - 1] |= 128
        self.sflag_tab = tab
        # GPS time: 60 m/s ground speed, 90 s turns between strips.
        speed = 60.0
        t = 3.0e8 + 1.0e5 * (derive_key(self.seed, "t0", self.index) % 1000)
        for s in st:
            dur = (s["a_hi"] - s["a_lo"]) / speed
            s["t0"] = t
            s["dt"] = dur / s["pulses"]
            t += dur + 90.0
        self.cycle_time = t - st[self.n_main]["t0"] if self.P_cross else 0.0

    def _segments(self, p0, p1):
        """Splits the pulse range [p0, p1) into runs inside one strip and one
        pass: yields (strip, cycle, q0, q1, base) with global index = base + q."""
        p = p0
        while p < p1:
            if p < self.P:
                k = int(np.searchsorted(self.cum, p, side="right")) - 1
                cyc = 0
                pp = p
            else:
                if self.P_cross == 0:
                    raise RuntimeError("flight plan has no cross strips to repeat")
                over = p - self.P_main
                cyc = over // self.P_cross
                pp = self.P_main + over % self.P_cross
                k = int(np.searchsorted(self.cum, pp, side="right")) - 1
            q0 = pp - int(self.cum[k])
            n = min(p1 - p, int(self.cum[k + 1]) - pp)
            yield k, cyc, q0, q0 + n, p - q0
            p += n

    def _estimate_main(self):
        """Mean points per main-strip pulse (before thinning) and its relative standard error."""
        if self.P_main == 0:
            return 0.0, 0.0
        saved = self.thr
        self.thr = np.uint64(1 << 32)
        floor = 1.0 / math.sqrt(max(self.n_scan, 1))
        try:
            if self.P_main <= EXACT_COUNT_PULSES:
                total = sum(self._segment(*sg, full=False)
                            for sg in self._segments(0, self.P_main))
                return total / self.P_main, floor
            # Systematic sample: every step-th scan line of the main strips
            # (all pulses of a line), which samples the area evenly.
            lines_total = self.P_main // self.m
            step = max(1, lines_total * self.m // SAMPLE_PULSES)
            phase = derive_key(self.seed, "sample", self.index) % step
            total = 0
            sampled = 0
            g = 0
            for k in range(self.n_main):
                nl = self.plan["strips"][k]["lines"]
                first = (phase - g) % step
                for ln in range(first, nl, step):
                    total += self._segment(k, 0, ln * self.m, (ln + 1) * self.m,
                                           int(self.cum[k]), full=False)
                    sampled += self.m
                g += nl
            if sampled == 0 or total == 0:
                return 0.0, 1.0
            return total / sampled, SAMPLE_ERROR + floor
        finally:
            self.thr = saved

    # ------------------------------------------------------------ pulses

    def _segment(self, k, cyc, q0, q1, base, full):
        """Evaluates pulses q0..q1-1 of strip k in pass cyc.  full=False: the
        number of points they give.  full=True: a Batch of those points."""
        st = self.plan["strips"][k]
        m = self.m
        l0 = q0 // m
        l1 = (q1 - 1) // m + 1
        off = q0 - l0 * m
        n_all = q1 - q0
        lines = np.arange(l0, l1, dtype=np.int64)
        sign = (1 - 2 * (lines & 1)).astype(np.float64)
        u = np.multiply.outer(sign, self.u_tab).ravel()[off:off + n_all]
        sfl = self.sflag_tab[lines & 1].ravel()[off:off + n_all]
        # Along-track position in line spacings; a repeated pass is shifted.
        al = np.add.outer(lines + 0.37 * cyc, self.t_tab).ravel()[off:off + n_all]
        a = al * (st["dir"] * self.d)
        a += st["a0"]
        # Lateral wobble of the aircraft: a smooth periodic function of the
        # along-track position (cubic-smoothed triangle wave).
        ph = a * self.inv_lam
        ph += st["phase"]
        ph -= np.floor(ph)
        ph *= 4.0
        ph -= 2.0
        np.abs(ph, out=ph)
        ph -= 1.0
        c = ph * ph
        c *= -0.5
        c += 1.5
        c *= ph
        c *= self.wobble
        c += st["c"]
        c += u * self.half_swath
        pidx = np.arange(base + q0, base + q1, dtype=np.int64)
        h1 = hash_indices(pidx, self.keys[0])
        w1 = h1.view(np.uint16).reshape(-1, 4)
        js = self.jitter / 65536.0
        a += w1[:, 0] * js
        a -= 0.5 * self.jitter
        c += w1[:, 1] * js
        c -= 0.5 * self.jitter
        cs, sn = st["cos"], st["sin"]
        cx, cy = self.plan["centre"]
        inv = 1.0 / self.sc
        x = a * (cs * inv)
        x -= c * (sn * inv)
        x += cx * inv
        y = a * (sn * inv)
        y += c * (cs * inv)
        y += cy * inv
        X = np.rint(x, out=x)
        Y = np.rint(y, out=y)
        ok = X >= self.Xlo
        ok &= X <= self.Xhi
        ok &= Y >= self.Ylo
        ok &= Y <= self.Yhi
        if k < self.n_main and self.thr < (1 << 32):
            ok &= (h1 >> 32) < self.thr
        idx = np.flatnonzero(ok)
        X = X[idx]
        Y = Y[idx]
        xq = X * self.sc
        yq = Y * self.sc
        bxi = ((xq - self.x0) * (1.0 / self.bs)).astype(np.int64)
        np.minimum(bxi, self.nbx - 1, out=bxi)
        byi = ((yq - self.y0) * (1.0 / self.bs)).astype(np.int64)
        np.minimum(byi, self.nby - 1, out=byi)
        b = byi * self.nbx + bxi
        flag = self.bflag[b]
        # Lakes and DEM patches: exact tests only in blocks that touch them.
        chk = np.flatnonzero(flag & (FLAG_LAKE | FLAG_DEM))
        if len(chk):
            cxq = xq[chk]
            cyq = yq[chk]
            drop = np.zeros(len(chk), dtype=bool)
            for lx, ly, lr in self.lakes:
                drop |= (cxq - lx) ** 2 + (cyq - ly) ** 2 < lr * lr
            cX = X[chk]
            cY = Y[chk]
            for pt in self.patches:
                ox, oy = pt["origin"]
                a1, b1 = pt["e1"]
                g2 = a1 * a1 + b1 * b1
                dx = cX - ox
                dy = cY - oy
                # g2 * (column, row) of the point, exact in float64 (< 2^53):
                # within half a step of the node set means inside the patch.
                du = dx * a1 + dy * b1
                dv = dy * a1 - dx * b1
                drop |= ((du >= -0.5 * g2) & (du <= (pt["cols"] - 0.5) * g2)
                         & (dv >= -0.5 * g2) & (dv <= (pt["rows"] - 0.5) * g2))
            if drop.any():
                keep = np.ones(len(idx), dtype=bool)
                keep[chk[drop]] = False
                sel = np.flatnonzero(keep)
                idx = idx[sel]
                X = X[sel]
                Y = Y[sel]
                xq = xq[sel]
                yq = yq[sel]
                b = b[sel]
                flag = flag[sel]
        n = len(idx)
        typ = flag & FLAG_TYPE
        pk = pidx[idx]
        h2 = hash_indices(pk, self.keys[1])
        w2 = h2.view(np.uint16).reshape(-1, 4)
        h3 = remix(h2, self.keys[2])
        w3 = h3.view(np.uint16).reshape(-1, 4)
        nr = np.ones(n, dtype=np.int64)
        # Roofs: one return; within the edge band a second one on the ground.
        ib = np.flatnonzero(typ == TYPE_BUILDING)
        roof = ib[:0]
        if len(ib):
            bb = b[ib]
            xb = xq[ib]
            yb = yq[ib]
            dxe = np.minimum(xb - self.b_x0[bb], self.b_x1[bb] - xb)
            dye = np.minimum(yb - self.b_y0[bb], self.b_y1[bb] - yb)
            de = np.minimum(dxe, dye)
            on = de >= 0
            roof = ib[on]
            band = max(1.5 * self.d, 2.0 * self.sc)
            nr[ib[on & (de < band)]] = 2
        # Canopy: 1-4 returns.
        iff = np.flatnonzero(typ == TYPE_FOREST)
        canopy = iff[:0]
        if len(iff):
            bb = b[iff]
            dx = xq[iff] - self.f_cx[bb]
            dy = yq[iff] - self.f_cy[bb]
            canopy = iff[dx * dx + dy * dy < self.f_r2[bb]]
            w = w2[canopy, 0]
            nr[canopy] = 1 + (w >= 22938).astype(np.int64) + (w >= 45875) + (w >= 58982)
        noise = w3[:, 3] < self.noise_level
        nr[noise] = 1
        dup = (w3[:, 2] < self.dup_level).astype(np.int64)
        counts_k = nr + dup
        if not full:
            return int(counts_k.sum())
        return self._expand(st, k, cyc, q0, idx, u, sfl, X, Y, xq, yq, b, nr, counts_k,
                            roof, canopy, noise, w2, w3)

    def _expand(self, st, k, cyc, q0, idx, u, sfl, X, Y, xq, yq, b, nr, counts_k,
                roof, canopy, noise, w2, w3):
        n = len(idx)
        zg = self.terrain(xq, yq)
        zg += w3[:, 0] * (0.12 / 65536.0)
        zg -= 0.06
        is_roof = np.zeros(n, dtype=bool)
        is_roof[roof] = True
        is_can = np.zeros(n, dtype=bool)
        is_can[canopy] = True
        roof_z = np.zeros(n)
        if len(roof):
            bb = b[roof]
            rz = (self.b_roof[bb]
                  + self.b_pitch_x[bb] * (self.b_halfx[bb] - np.abs(xq[roof] - self.b_midx[bb]))
                  + self.b_pitch_y[bb] * (self.b_halfy[bb] - np.abs(yq[roof] - self.b_midy[bb])))
            # A roof stands at least 2.5 above the ground under it, even on a slope.
            roof_z[roof] = np.maximum(rz, zg[roof] + 2.5)
        can_h = np.zeros(n)
        if len(canopy):
            bb = b[canopy]
            ts = self.tree_spacing
            fx = xq[canopy] * (1.0 / ts)
            fy = yq[canopy] * (1.0 / ts)
            fx -= np.floor(fx)
            fy -= np.floor(fy)
            crown = 1.0 - 4.0 * ((fx - 0.5) ** 2 + (fy - 0.5) ** 2)
            np.maximum(crown, 0.0, out=crown)
            can_h[canopy] = self.f_height[bb] * (0.55 + 0.45 * crown)
        # Expand pulses to points: point r of a pulse is its return r+1; a
        # duplicated pulse repeats its last return.
        tot = int(counts_k.sum())
        if tot == n:
            pid = np.arange(n)
            rn = nr
            nrp = nr
        else:
            pid = np.repeat(np.arange(n), counts_k)
            first = np.cumsum(counts_k) - counts_k
            kr = np.arange(tot, dtype=np.int64) - np.take(first, pid)
            nrp = np.take(nr, pid)
            rn = np.minimum(kr + 1, nrp)
        z = np.take(zg, pid)
        cls = np.full(tot, CLS_GROUND, dtype=np.uint8)
        if len(roof):
            top = np.flatnonzero(np.take(is_roof, pid) & (rn == 1))
            z[top] = roof_z[pid[top]]
            cls[top] = CLS_BUILDING
        pc = np.flatnonzero(np.take(is_can, pid))
        if len(pc):
            pp = pid[pc]
            kk = rn[pc].astype(np.float64)
            nn = nrp[pc].astype(np.float64)
            c1 = w2[pp, 1] * (1.0 / 65536.0)
            c2 = w2[pp, 2] * (1.0 / 65536.0)
            f_top = 0.85 + 0.15 * c1
            f_last = np.where(c2 < 0.5, 0.0, 0.05 + 0.3 * (c2 - 0.5))
            single = np.where(c2 < 0.3, 0.0, f_top)
            f = np.where(nn > 1, f_top - (f_top - f_last) * (kk - 1.0) / np.maximum(nn - 1.0, 1.0),
                         single)
            hgt = can_h[pp] * f
            z[pc] += hgt
            cls[pc] = np.where(hgt <= 0.0, CLS_GROUND,
                               np.where(hgt < 2.0, CLS_LOW, np.where(hgt < 5.0, CLS_MED, CLS_HIGH)))
        pn = np.flatnonzero(np.take(noise, pid))
        if len(pn):
            w = w3[pid[pn], 3] / (self.noise_level + 1.0)
            z[pn] += np.where(w < 0.5, -5.0 - 40.0 * w, 20.0 + 60.0 * (w - 0.5))
            cls[pn] = CLS_NOISE
        z *= 1.0 / self.scz
        Z = np.rint(z).astype(np.int32)
        inten = _INTENSITY_BASE[cls]
        inten += np.take(w2[:, 3] >> 6, pid)
        if tot != n or len(canopy):
            # Later returns are weaker.
            inten *= _RETURN_GAIN[rn]
            inten >>= 8
        # Attributes of the pulse, repeated for each of its points.
        gps = (q0 + idx) * st["dt"]
        gps += st["t0"] + cyc * self.cycle_time
        sflags = sfl[idx]
        angle = u[idx]
        angle *= FOV_HALF_DEG
        psid = k + 1 + cyc * (len(self.plan["strips"]) - self.n_main)
        if tot != n:
            X = np.take(X, pid)
            Y = np.take(Y, pid)
            gps = np.take(gps, pid)
            sflags = np.take(sflags, pid)
            angle = np.take(angle, pid)
        return Batch(X.astype(np.int32), Y.astype(np.int32), Z, inten.astype(np.uint16),
                     rn.astype(np.uint8), nrp.astype(np.uint8), cls, angle.astype(np.float32),
                     sflags, np.full(tot, psid & 0xFFFF, dtype=np.uint16), gps)

    # ------------------------------------------------------------ output

    def _dem_batch(self, i0, i1):
        i = np.arange(i0, i1, dtype=np.int64)
        X, Y = patch_nodes(self.patches, self.dem_cum, i)
        z = self.terrain(X * self.sc, Y * self.sc)
        Z = np.rint(z * (1.0 / self.scz)).astype(np.int32)
        inten = np.full(len(i), 600, dtype=np.uint16)
        return Batch.simple(X.astype(np.int32), Y.astype(np.int32), Z, inten,
                            cls=CLS_GROUND, psid=0, gps=0.0)

    def _count(self, bt):
        """Adds the points of an emitted batch to the statistics."""
        if not len(bt):
            return
        same = ((bt.X[1:] == bt.X[:-1]) & (bt.Y[1:] == bt.Y[:-1]) & (bt.Z[1:] == bt.Z[:-1])
                & (bt.rn[1:] == bt.rn[:-1]) & (bt.gps[1:] == bt.gps[:-1]))
        dups = int(same.sum())
        st = self.stats
        st["duplicate_points"] += dups
        st["multi_return_points"] += int((bt.nr > 1).sum())
        st["noise_points"] += int((bt.cls == CLS_NOISE).sum())
        st["pulses_emitted"] += int((bt.rn == 1).sum()) - int((same & (bt.rn[1:] == 1)).sum())

    def batches(self, chunk):
        """Yields the section's points: scan points (exactly n_scan), then DEM nodes."""
        emitted = 0
        p0 = 0
        while emitted < self.n_scan:
            for sg in self._segments(p0, p0 + chunk):
                bt = self._segment(*sg, full=True)
                room = self.n_scan - emitted
                if len(bt) > room:
                    bt = bt.head(room)
                self._count(bt)
                emitted += len(bt)
                if len(bt):
                    yield bt
                if emitted >= self.n_scan:
                    break
            p0 += chunk
        self.stats["scan_points"] = emitted
        for i0 in range(0, self.dem_count, chunk):
            yield self._dem_batch(i0, min(i0 + chunk, self.dem_count))

    def describe(self, offset):
        ox, oy = offset[0], offset[1]
        pl = self.plan
        return {
            "kind": "lidar",
            "region": [self.x0 + ox, self.y0 + oy, self.w, self.h],
            "count": self.count,
            "scan_points": self.n_scan,
            "dem_points": self.dem_count,
            "strips": [{"heading_deg": math.degrees(s["heading"]), "swath": pl["swath"],
                        "lines": s["lines"], "pulses": s["pulses"], "cross": s["cross"],
                        "point_source_id": k + 1}
                       for k, s in enumerate(pl["strips"])],
            "pulses_per_line": self.m,
            "line_spacing": self.d,
            "overlap": pl["overlap"],
            "main_keep_fraction": self.q,
            "lakes": [{"x": lx + ox, "y": ly + oy, "r": lr} for lx, ly, lr in self.lakes],
            "dem_patches": [{"origin": p["origin"], "e1": p["e1"], "e2": p["e2"],
                             "cols": p["cols"], "rows": p["rows"], "count": p["count"]}
                            for p in self.patches],
            "block_size": self.bs,
            "buildings": self.n_buildings,
            "forest_blocks": self.n_forest,
            "stats": dict(self.stats),
        }
