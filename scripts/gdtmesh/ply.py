"""Reading the gdt-tile output mesh and recovering its lattice integers.

The mesh is a binary little-endian PLY (see io/gdt_ply.h):
  element vertex V   with scalar properties, at least double/float x and y
  element face F     with exactly one property: list uchar int vertex_indices
and header comments "comment lattice sx sy ox oy" (x = ox + sx * i),
"comment crs ...", "comment generator ...".  Counts may be padded with
spaces.  Nothing is loaded into memory: vertices and faces are numpy.memmap
views of the file, whose size must be exactly header + V * vertex record +
F * 13 bytes.

Lattice recovery: i = rint((x - ox) / sx).  A coordinate is on the lattice
when it lies within LATTICE_TOL lattice units of ox + sx * i, or equals the
double ox + sx * i exactly (the writer's own rounding; this matters only
where one lattice unit is near the double resolution of x).  Integers must
satisfy |i| < 2^53, the precondition of gdtmesh.exact.
"""
import math
import os
import re
from collections import namedtuple

import numpy as np

LATTICE_TOL = 1e-6
INT_LIMIT = float(1 << 53)
_MAX_HEADER = 16 << 20
_END_HEADER = re.compile(rb"(?:^|\n)end_header\r?\n")

Lattice = namedtuple("Lattice", "sx sy ox oy")

_SCALARS = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
    "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}
FACE_DTYPE = np.dtype([("n", "u1"), ("v", "<i4", (3,))])


class MeshFileError(Exception):
    """The file cannot be read as a gdt-tile mesh (missing, not PLY, truncated...)."""


class PlyMesh:
    """A memory-mapped PLY mesh.

    Attributes: path, nvert, nface, header_bytes, comments (list of str),
    lattice (Lattice or None), lattice_problem (str or None: why the lattice
    comment is unusable), crs (str or None), generator (str or None),
    vertices (structured array of V records, memmap when V > 0),
    faces (structured array with fields n (uint8) and v (3 x int32)).
    """

    def __init__(self, path):
        self.path = str(path)
        try:
            size = os.path.getsize(self.path)
            with open(self.path, "rb") as f:
                head = self._read_header_bytes(f)
        except OSError as e:
            raise MeshFileError("%s: cannot read: %s" % (self.path, e.strerror or e)) from None
        self.header_bytes = len(head)
        self._parse_header(head.decode("latin-1"))
        need = self.header_bytes + self.nvert * self.vertex_dtype.itemsize + self.nface * FACE_DTYPE.itemsize
        if size != need:
            raise MeshFileError("%s: file has %d bytes, the header (%d vertices, %d faces) implies %d%s"
                                % (self.path, size, self.nvert, self.nface, need,
                                   " (truncated)" if size < need else " (trailing bytes)"))
        off = self.header_bytes
        if self.nvert:
            self.vertices = np.memmap(self.path, dtype=self.vertex_dtype, mode="r", offset=off,
                                      shape=(self.nvert,))
        else:
            self.vertices = np.zeros(0, dtype=self.vertex_dtype)
        off += self.nvert * self.vertex_dtype.itemsize
        if self.nface:
            self.faces = np.memmap(self.path, dtype=FACE_DTYPE, mode="r", offset=off,
                                   shape=(self.nface,))
        else:
            self.faces = np.zeros(0, dtype=FACE_DTYPE)

    def _read_header_bytes(self, f):
        buf = b""
        while len(buf) <= _MAX_HEADER:
            more = f.read(1 << 16)
            buf += more
            m = _END_HEADER.search(buf)
            if m:
                return buf[:m.end()]
            if not more:
                break
        if not buf.startswith(b"ply"):
            raise MeshFileError("%s: not a PLY file (no 'ply' magic)" % self.path)
        raise MeshFileError("%s: PLY header has no end_header line" % self.path)

    def _parse_header(self, text):
        lines = [ln.rstrip("\r") for ln in text.split("\n")]
        if not lines or lines[0].strip() != "ply":
            raise MeshFileError("%s: not a PLY file (no 'ply' magic)" % self.path)
        self.comments = []
        self.lattice = None
        self.lattice_problem = "no 'comment lattice' line"
        self.crs = None
        self.generator = None
        fmt = None
        elements = []  # [name, count, [props]]
        for no, ln in enumerate(lines[1:], start=2):
            tok = ln.split()
            if not tok:
                continue
            kw = tok[0]
            if kw == "format":
                fmt = " ".join(tok[1:])
            elif kw == "comment":
                body = ln.split(None, 1)[1] if len(tok) > 1 else ""
                self.comments.append(body)
                self._comment(body)
            elif kw == "obj_info":
                continue
            elif kw == "element":
                if len(tok) != 3:
                    raise MeshFileError("%s: header line %d: malformed element line" % (self.path, no))
                try:
                    count = int(tok[2])
                except ValueError:
                    raise MeshFileError("%s: header line %d: element count '%s' is not an integer"
                                        % (self.path, no, tok[2])) from None
                if count < 0:
                    raise MeshFileError("%s: header line %d: negative element count" % (self.path, no))
                elements.append([tok[1], count, []])
            elif kw == "property":
                if not elements:
                    raise MeshFileError("%s: header line %d: property before any element" % (self.path, no))
                elements[-1][2].append((no, tok[1:]))
            elif kw == "end_header":
                break
            else:
                raise MeshFileError("%s: header line %d: unknown keyword '%s'" % (self.path, no, kw))
        if fmt != "binary_little_endian 1.0":
            raise MeshFileError("%s: PLY format '%s' is not supported (binary_little_endian 1.0 only)"
                                % (self.path, fmt))
        names = [e[0] for e in elements]
        if names not in (["vertex"], ["vertex", "face"]):
            raise MeshFileError("%s: expected elements 'vertex' then 'face', found %s"
                                % (self.path, ", ".join(names) or "none"))
        self.nvert = elements[0][1]
        fields = []
        for no, p in elements[0][2]:
            if len(p) != 2 or p[0] not in _SCALARS:
                raise MeshFileError("%s: header line %d: unsupported vertex property '%s'"
                                    % (self.path, no, " ".join(p)))
            fields.append((p[1], _SCALARS[p[0]]))
        pnames = [f[0] for f in fields]
        if len(set(pnames)) != len(pnames) or "x" not in pnames or "y" not in pnames:
            raise MeshFileError("%s: vertex properties must include x and y once each" % self.path)
        self.vertex_dtype = np.dtype(fields)
        self.nface = 0
        if len(elements) == 2:
            self.nface = elements[1][1]
            props = elements[1][2]
            ok = (len(props) == 1 and len(props[0][1]) == 4 and props[0][1][0] == "list"
                  and _SCALARS.get(props[0][1][1]) == "u1"
                  and _SCALARS.get(props[0][1][2]) in ("<i4", "<u4")
                  and props[0][1][3] in ("vertex_indices", "vertex_index"))
            if not ok:
                raise MeshFileError("%s: face element must have exactly one property "
                                    "'list uchar int vertex_indices'" % self.path)
        if self.nvert > (1 << 31):
            raise MeshFileError("%s: %d vertices cannot be addressed by int indices"
                                % (self.path, self.nvert))

    def _comment(self, body):
        tok = body.split()
        if not tok:
            return
        if tok[0] == "lattice":
            if self.lattice is not None:
                self.lattice = None
                self.lattice_problem = "more than one 'comment lattice' line"
                return
            if self.lattice_problem == "more than one 'comment lattice' line":
                return
            try:
                vals = [float(t) for t in tok[1:]]
            except ValueError:
                vals = []
            if (len(vals) != 4 or not all(math.isfinite(v) for v in vals)
                    or vals[0] <= 0 or vals[1] <= 0):
                self.lattice_problem = "malformed lattice comment '%s'" % body
                return
            self.lattice = Lattice(*vals)
            self.lattice_problem = None
        elif tok[0] == "crs":
            self.crs = body[3:].strip()
        elif tok[0] == "generator":
            self.generator = body[9:].strip()

    def xy(self, idx=None):
        """x and y as float64 arrays (all vertices, a slice, or an index array)."""
        v = self.vertices if idx is None else self.vertices[idx]
        return np.asarray(v["x"], dtype=np.float64), np.asarray(v["y"], dtype=np.float64)


def to_lattice(lat, x, y):
    """Lattice integers of CRS coordinates.

    returns (ix, iy, bad): int64 arrays and a boolean mask of coordinates that
    are not finite, lie off the lattice, or are out of the |i| < 2^53 range
    (their ix, iy are 0)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    bad = np.zeros(x.shape, dtype=bool)
    out = []
    with np.errstate(invalid="ignore", over="ignore"):
        for v, s, o in ((x, lat.sx, lat.ox), (y, lat.sy, lat.oy)):
            q = (v - o) / s
            r = np.rint(q)
            ok = np.isfinite(q) & (np.abs(r) < INT_LIMIT)
            r = np.where(ok, r, 0.0)
            near = np.abs(q - r) <= LATTICE_TOL
            exact = v == (o + s * r)
            bad |= ~(ok & (near | exact))
            out.append(r.astype(np.int64))
    ix, iy = out
    ix[bad] = 0
    iy[bad] = 0
    return ix, iy, bad
