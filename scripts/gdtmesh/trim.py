"""The trimming rules of gdt-tile, by brute force, to check a trimmed mesh.

Edge length is horizontal, in CRS units: the edge of lattice vector (dx, dy)
is longer than L when (dx sx)^2 + (dy sy)^2 > L^2 in double precision, in
that order (merge/gdt_trim.h).

  --max-edge L    drops every face with an edge longer than L.
  --concavity L   peels from the outside in: a face is dropped when one of
                  its edges longer than L has no kept face on its other side
                  (a hull edge, or the face there already dropped), repeated
                  until nothing changes.
A face is kept when neither rule drops it; vertices always stay.

check_trimmed compares a trimmed mesh with the rules applied to the untrimmed
one: the same vertices (as lattice points, with z), and exactly the faces the
rules keep (as oriented triangles of lattice points).  The whole face set is
held in memory (Python sets: about 200 bytes per face), so this is a check
for test and sample sizes, not for billions of faces.
"""
from collections import deque

import numpy as np

from .ply import PlyMesh, to_lattice


def longer(dx, dy, sx, sy, length):
    x = float(dx) * sx
    y = float(dy) * sy
    return x * x + y * y > length * length


def rule_of(ply):
    """(max_edge, concavity) from the mesh's "comment trim" line; 0 = off."""
    me, cc = 0.0, 0.0
    for c in ply.comments:
        w = c.split()
        if not w or w[0] != "trim":
            continue
        for key, val in zip(w[1::2], w[2::2]):
            if key == "max-edge":
                me = float(val)
            elif key == "concavity":
                cc = float(val)
    return me, cc


def _lattice_points(ply):
    lat = ply.lattice
    v = ply.vertices
    ix, iy, bad = to_lattice(lat, np.asarray(v["x"], dtype=np.float64),
                             np.asarray(v["y"], dtype=np.float64))
    if bad.any():
        raise ValueError(f"{ply.path}: vertices off the lattice")
    z = np.asarray(v["z"], dtype=np.float64)
    return [(int(a), int(b)) for a, b in zip(ix, iy)], z


def trimmed_faces(faces, pts, sx, sy, max_edge, concavity):
    """Indices of the faces the rules keep.  faces: F x 3 vertex indices
    (counter-clockwise); pts: lattice (x, y) per vertex."""
    faces = [tuple(int(i) for i in f) for f in faces]
    n = len(faces)
    keep = [True] * n

    def is_long(a, b, length):
        return longer(pts[b][0] - pts[a][0], pts[b][1] - pts[a][1], sx, sy, length)

    if concavity > 0:
        side = {}
        for k, (a, b, c) in enumerate(faces):
            side[(a, b)] = k
            side[(b, c)] = k
            side[(c, a)] = k
        queue = deque()
        for k, f in enumerate(faces):
            for i in range(3):
                a, b = f[i], f[(i + 1) % 3]
                if (b, a) not in side and is_long(a, b, concavity):
                    queue.append(k)
                    break
        while queue:
            k = queue.popleft()
            if not keep[k]:
                continue
            keep[k] = False
            f = faces[k]
            for i in range(3):
                a, b = f[i], f[(i + 1) % 3]
                g = side.get((b, a))
                if g is not None and keep[g] and is_long(a, b, concavity):
                    queue.append(g)
    peeled = keep.count(False)
    cut = 0
    if max_edge > 0:
        for k, (a, b, c) in enumerate(faces):
            if is_long(a, b, max_edge) or is_long(b, c, max_edge) or is_long(c, a, max_edge):
                cut += 1
                keep[k] = False
    return [k for k in range(n) if keep[k]], cut, peeled


def _canonical(faces, pts):
    out = set()
    for f in faces:
        k = [pts[int(i)] for i in f]
        r = k.index(min(k))
        out.add(tuple(k[r:] + k[:r]))
    return out


def check_trimmed(trimmed_path, full_path, max_edge=None, concavity=None):
    """(code, line): 0 and "OK: ..." when the trimmed mesh is the full mesh
    with exactly the rules' faces dropped, 1 and "FAIL: ..." otherwise.
    max_edge/concavity default to the trimmed mesh's "comment trim" line."""
    t = PlyMesh(trimmed_path)
    u = PlyMesh(full_path)
    me, cc = rule_of(t)
    me = me if max_edge is None else max_edge
    cc = cc if concavity is None else concavity
    if t.lattice is None or u.lattice is None or tuple(t.lattice) != tuple(u.lattice):
        return 1, "FAIL: the two meshes are not on the same lattice"
    lat = t.lattice
    tp, tz = _lattice_points(t)
    up, uz = _lattice_points(u)
    if sorted(zip(tp, tz)) != sorted(zip(up, uz)):
        return 1, (f"FAIL: the vertices differ ({t.nvert} in {trimmed_path}, {u.nvert} in "
                   f"{full_path})")
    ufaces = u.faces["v"]
    kept, cut, peeled = trimmed_faces(ufaces, up, lat.sx, lat.sy, me, cc)
    want = _canonical((ufaces[k] for k in kept), up)
    got = _canonical(t.faces["v"], tp)
    if len(got) != t.nface:
        return 1, f"FAIL: {trimmed_path} repeats faces"
    if got != want:
        extra, missing = len(got - want), len(want - got)
        ex = next(iter(got - want), None) or next(iter(want - got))
        return 1, (f"FAIL: {extra} faces that the rules drop are kept and {missing} faces "
                   f"they keep are missing (for example {ex}); max-edge {me}, "
                   f"concavity {cc}")
    return 0, (f"OK: {t.nface} faces = the {u.nface} of the full mesh less {u.nface - t.nface} "
               f"trimmed (max-edge {me}: {cut} faces, concavity {cc}: {peeled} faces)")
