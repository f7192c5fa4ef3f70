"""Point-cloud I/O for the mesh scripts.

Writers (used by gen_degenerate.py): a minimal LAS 1.2 writer (point format 0,
no VLRs, fixed creation date so equal inputs give equal bytes), a PCD 0.7
binary writer (fields x y z as F8) and an XYZ text writer.

Readers (used by validate_mesh.py --input) yield the (x, y) lattice integers
of every input point, chunk by chunk, on a given lattice:
  - LAS (any version laspy reads): when the lattice equals the file's own
    scale/offset the stored X/Y integers are used as they are; when only the
    offset differs by a whole number of lattice steps they are shifted
    exactly; otherwise x = X * scale + offset is snapped:
    i = rint((x - ox) / sx), round half to even, as gdt-tile snaps floats.
  - PCD (ascii, binary, binary_compressed; x/y any case, F4/F8 or integer
    types; a pure-Python LZF decoder for binary_compressed) and XYZ text
    ("x y z" per line): snapped the same way.
Geographic (lon/lat) input is not supported by the readers: gdt-tile
projects it first, which these scripts do not reproduce (CloudUnsupported).
"""
import math
import os
import struct

import numpy as np

from .ply import INT_LIMIT


class CloudError(Exception):
    """The point cloud cannot be read (missing, malformed, non-finite points)."""


class CloudUnsupported(Exception):
    """The point cloud is readable but cannot be checked by these scripts."""


# --------------------------------------------------------------------- writers

LAS_POINT0 = np.dtype([("X", "<i4"), ("Y", "<i4"), ("Z", "<i4"), ("intensity", "<u2"),
                       ("flags", "u1"), ("classification", "u1"), ("scan_angle", "i1"),
                       ("user_data", "u1"), ("point_source_id", "<u2")])
_LAS12_HEADER_SIZE = 227
_INT32_MIN = -(1 << 31)
_INT32_MAX = (1 << 31) - 1


def write_las(path, X, Y, Z, scale=(0.001, 0.001, 0.001), offset=(0.0, 0.0, 0.0),
              chunk=1 << 20):
    """Writes LAS 1.2, point format 0, from int32-range integer arrays X, Y, Z
    (the stored record integers: coordinate = offset + scale * integer)."""
    X = np.asarray(X, dtype=np.int64)
    Y = np.asarray(Y, dtype=np.int64)
    Z = np.asarray(Z, dtype=np.int64)
    n = X.shape[0]
    if not (Y.shape[0] == n and Z.shape[0] == n):
        raise ValueError("X, Y, Z differ in length")
    if n >= 1 << 32:
        raise ValueError("LAS 1.2 holds fewer than 2^32 points")
    for name, a in (("X", X), ("Y", Y), ("Z", Z)):
        if n and (a.min() < _INT32_MIN or a.max() > _INT32_MAX):
            raise ValueError("%s integers exceed the int32 range of LAS" % name)
    sx, sy, sz = (float(v) for v in scale)
    ox, oy, oz = (float(v) for v in offset)
    if n:
        mins = [o + s * float(a.min()) for a, s, o in ((X, sx, ox), (Y, sy, oy), (Z, sz, oz))]
        maxs = [o + s * float(a.max()) for a, s, o in ((X, sx, ox), (Y, sy, oy), (Z, sz, oz))]
    else:
        mins = maxs = [0.0, 0.0, 0.0]
    hdr = b"".join([
        b"LASF",
        struct.pack("<HH", 0, 0),              # file source id, global encoding
        b"\0" * 16,                             # project GUID
        struct.pack("<BB", 1, 2),               # version 1.2
        b"gdt-tile".ljust(32, b"\0"),           # system identifier
        b"gdt-tile gen_degenerate".ljust(32, b"\0"),
        struct.pack("<HH", 1, 2024),            # creation day of year, year
        struct.pack("<HI", _LAS12_HEADER_SIZE, _LAS12_HEADER_SIZE),
        struct.pack("<I", 0),                   # VLRs
        struct.pack("<BH", 0, LAS_POINT0.itemsize),
        struct.pack("<I", n),
        struct.pack("<5I", n, 0, 0, 0, 0),      # points by return
        struct.pack("<3d", sx, sy, sz),
        struct.pack("<3d", ox, oy, oz),
        struct.pack("<6d", maxs[0], mins[0], maxs[1], mins[1], maxs[2], mins[2]),
    ])
    assert len(hdr) == _LAS12_HEADER_SIZE
    with open(path, "wb") as f:
        f.write(hdr)
        for s in range(0, n, chunk):
            e = min(n, s + chunk)
            rec = np.zeros(e - s, dtype=LAS_POINT0)
            rec["X"] = X[s:e]
            rec["Y"] = Y[s:e]
            rec["Z"] = Z[s:e]
            rec["flags"] = 0b00001001           # return 1 of 1
            rec["classification"] = 2           # ground
            f.write(rec.tobytes())


def write_pcd(path, x, y, z):
    """Writes PCD 0.7, DATA binary, fields x y z as F8 (CRS coordinates)."""
    n = len(x)
    rec = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8")])
    rec["x"] = x
    rec["y"] = y
    rec["z"] = z
    head = ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\nFIELDS x y z\n"
            "SIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH %d\nHEIGHT 1\n"
            "VIEWPOINT 0 0 0 1 0 0 0\nPOINTS %d\nDATA binary\n" % (n, n))
    with open(path, "wb") as f:
        f.write(head.encode("ascii"))
        f.write(rec.tobytes())


def _decimal_digits(scale):
    """k when scale == 10^-k exactly as a double (0 <= k <= 12), else None."""
    for k in range(13):
        if float("1e-%d" % k) == scale:
            return k
    return None


def _format_fixed(ints, k, off):
    """Exact decimal strings of off + ints * 10^-k (off a multiple of 10^-k)."""
    base = int(round(off * 10 ** k))
    out = []
    for v in (int(t) + base for t in ints):
        s = str(abs(v)).rjust(k + 1, "0")
        txt = s if k == 0 else s[:-k] + "." + s[-k:]
        out.append("-" + txt if v < 0 else txt)
    return out


def write_xyz(path, X, Y, Z, scale=(0.001, 0.001, 0.001), offset=(0.0, 0.0, 0.0)):
    """Writes "x y z" text lines.  When a scale is 10^-k and its offset a
    multiple of it, coordinates are printed as exact decimals; otherwise with
    17 significant digits (which round-trip the double)."""
    cols = []
    for a, s, o in ((X, scale[0], offset[0]), (Y, scale[1], offset[1]), (Z, scale[2], offset[2])):
        k = _decimal_digits(float(s))
        if k is not None and float(round(o * 10 ** k)) == o * 10 ** k:
            cols.append(_format_fixed(np.asarray(a), k, o))
        else:
            cols.append(["%.17g" % (o + s * float(t)) for t in np.asarray(a)])
    with open(path, "w") as f:
        for a, b, c in zip(*cols):
            f.write("%s %s %s\n" % (a, b, c))


# --------------------------------------------------------------------- readers

def _snap(x, y, lat, where):
    """rint((x - ox) / sx) etc. as int64; refuses non-finite or out-of-range points."""
    with np.errstate(invalid="ignore", over="ignore"):
        qx = np.rint((np.asarray(x, dtype=np.float64) - lat.ox) / lat.sx)
        qy = np.rint((np.asarray(y, dtype=np.float64) - lat.oy) / lat.sy)
    ok = np.isfinite(qx) & np.isfinite(qy) & (np.abs(qx) < INT_LIMIT) & (np.abs(qy) < INT_LIMIT)
    if not np.all(ok):
        k = int(np.nonzero(~ok)[0][0])
        raise CloudError("%s: point %d has a non-finite or out-of-range coordinate (%r, %r)"
                         % (where[0], where[1] + k, float(np.asarray(x)[k]), float(np.asarray(y)[k])))
    return qx.astype(np.int64), qy.astype(np.int64)


def _looks_geographic(bounds):
    xmin, xmax, ymin, ymax = bounds
    return -180.0 <= xmin <= xmax <= 180.0 and -90.0 <= ymin <= ymax <= 90.0


def _check_not_geographic(path, in_bounds, mesh_bounds):
    if (in_bounds is not None and mesh_bounds is not None and _looks_geographic(in_bounds)
            and not _looks_geographic(mesh_bounds)):
        raise CloudUnsupported("%s: coordinates look like longitude/latitude while the mesh is "
                               "projected; projected input is needed to compare point sets" % path)


def _guard_geographic(path, x, y, mesh_bounds):
    finite = np.isfinite(x) & np.isfinite(y)
    if mesh_bounds is None or not np.any(finite):
        return
    xs, ys = x[finite], y[finite]
    _check_not_geographic(path, (xs.min(), xs.max(), ys.min(), ys.max()), mesh_bounds)


def detect_format(path):
    try:
        with open(path, "rb") as f:
            magic = f.read(4)
    except OSError as e:
        raise CloudError("%s: cannot read: %s" % (path, e.strerror or e)) from None
    if magic == b"LASF":
        return "las"
    ext = os.path.splitext(path)[1].lower()
    if ext == ".pcd" or magic[:1] == b"#" or magic in (b"VERS", b"FIEL"):
        return "pcd"
    if ext in (".xyz", ".txt", ".csv"):
        return "xyz"
    raise CloudError("%s: unknown point-cloud format (LAS, PCD or XYZ text expected)" % path)


def open_cloud(path):
    fmt = detect_format(path)
    if fmt == "las":
        return LasCloud(path)
    if fmt == "pcd":
        return PcdCloud(path)
    return XyzCloud(path)


class LasCloud:
    def __init__(self, path):
        self.path = path
        try:
            import laspy
        except ImportError:
            raise CloudError("%s: reading LAS needs the laspy package" % path) from None
        self._laspy = laspy
        try:
            with laspy.open(path) as r:
                h = r.header
                self.count_hint = int(h.point_count)
                self.scale = tuple(float(v) for v in h.scales)
                self.offset = tuple(float(v) for v in h.offsets)
                self.bounds = (float(h.mins[0]), float(h.maxs[0]), float(h.mins[1]), float(h.maxs[1]))
        except Exception as e:  # laspy raises a variety of types on bad files
            raise CloudError("%s: cannot read LAS: %s" % (path, e)) from None

    def chunks(self, lat, chunk, mesh_bounds=None):
        sx, sy = self.scale[:2]
        ox, oy = self.offset[:2]
        if sx == lat.sx and sy == lat.sy:
            kx = (ox - lat.ox) / lat.sx
            ky = (oy - lat.oy) / lat.sy
            exact = (math.isfinite(kx) and math.isfinite(ky) and abs(kx - round(kx)) <= 1e-9
                     and abs(ky - round(ky)) <= 1e-9)
        else:
            exact = False
        if exact:
            kx, ky = int(round(kx)), int(round(ky))
        else:
            _check_not_geographic(self.path, self.bounds, mesh_bounds)
        seen = 0
        try:
            with self._laspy.open(self.path) as r:
                for pts in r.chunk_iterator(chunk):
                    X = np.asarray(pts.X, dtype=np.int64)
                    Y = np.asarray(pts.Y, dtype=np.int64)
                    if exact:
                        yield X + kx, Y + ky
                    else:
                        x = X.astype(np.float64) * sx + ox
                        y = Y.astype(np.float64) * sy + oy
                        yield _snap(x, y, lat, (self.path, seen))
                    seen += X.shape[0]
        except (CloudError, CloudUnsupported):
            raise
        except Exception as e:
            raise CloudError("%s: cannot read LAS points: %s" % (self.path, e)) from None
        if seen != self.count_hint:
            raise CloudError("%s: header promises %d points, %d read" % (self.path, self.count_hint, seen))


_PCD_TYPES = {("F", 4): "<f4", ("F", 8): "<f8", ("I", 1): "i1", ("I", 2): "<i2", ("I", 4): "<i4",
              ("I", 8): "<i8", ("U", 1): "u1", ("U", 2): "<u2", ("U", 4): "<u4", ("U", 8): "<u8"}


def lzf_decompress(src, out_len):
    """Decodes one LZF block (liblzf format) of known decoded length."""
    src = memoryview(src)
    out = bytearray(out_len)
    ip = op = 0
    n_in = len(src)
    while ip < n_in:
        ctrl = src[ip]
        ip += 1
        if ctrl < 32:
            run = ctrl + 1
            if ip + run > n_in or op + run > out_len:
                raise ValueError("LZF literal run overflows")
            out[op:op + run] = src[ip:ip + run]
            ip += run
            op += run
        else:
            run = ctrl >> 5
            ref = op - ((ctrl & 0x1F) << 8) - 1
            if run == 7:
                if ip >= n_in:
                    raise ValueError("LZF stream truncated")
                run += src[ip]
                ip += 1
            if ip >= n_in:
                raise ValueError("LZF stream truncated")
            ref -= src[ip]
            ip += 1
            run += 2
            if ref < 0 or op + run > out_len:
                raise ValueError("LZF back reference out of range")
            if ref + run <= op:
                out[op:op + run] = out[ref:ref + run]
            else:
                for k in range(run):
                    out[op + k] = out[ref + k]
            op += run
    if op != out_len:
        raise ValueError("LZF stream decodes to %d bytes, %d expected" % (op, out_len))
    return bytes(out)


class PcdCloud:
    def __init__(self, path):
        self.path = path
        self.bounds = None
        try:
            with open(path, "rb") as f:
                head = f.read(1 << 16)
        except OSError as e:
            raise CloudError("%s: cannot read: %s" % (path, e.strerror or e)) from None
        meta = {}
        pos = 0
        while True:
            nl = head.find(b"\n", pos)
            if nl < 0:
                raise CloudError("%s: PCD header has no DATA line" % path)
            line = head[pos:nl].decode("latin-1").strip()
            pos = nl + 1
            if not line or line.startswith("#"):
                continue
            tok = line.split()
            meta[tok[0].upper()] = tok[1:]
            if tok[0].upper() == "DATA":
                break
        self.data_offset = pos
        try:
            fields = meta["FIELDS"]
            sizes = [int(v) for v in meta["SIZE"]]
            types = [v.upper() for v in meta["TYPE"]]
            counts = [int(v) for v in meta.get("COUNT", ["1"] * len(fields))]
            if "POINTS" in meta:
                npts = int(meta["POINTS"][0])
            else:
                npts = int(meta["WIDTH"][0]) * int(meta["HEIGHT"][0])
            self.encoding = meta["DATA"][0].lower()
        except (KeyError, ValueError, IndexError):
            raise CloudError("%s: PCD header lacks or garbles FIELDS/SIZE/TYPE/COUNT/POINTS/DATA"
                             % path) from None
        if not (len(fields) == len(sizes) == len(types) == len(counts)) or npts < 0:
            raise CloudError("%s: PCD header field lists differ in length" % path)
        if self.encoding not in ("ascii", "binary", "binary_compressed"):
            raise CloudError("%s: PCD DATA '%s' not supported" % (path, self.encoding))
        low = [f.lower() for f in fields]
        if low.count("x") != 1 or low.count("y") != 1:
            raise CloudError("%s: PCD fields must contain x and y once (any case)" % path)
        self.ix_field, self.iy_field = low.index("x"), low.index("y")
        self.count_hint = npts
        self.fields, self.sizes, self.types, self.counts = fields, sizes, types, counts
        names, formats, offsets = [], [], []
        off = 0
        for i, (s, t, c) in enumerate(zip(sizes, types, counts)):
            if (t, s) not in _PCD_TYPES or c < 1:
                raise CloudError("%s: PCD field %s has unsupported TYPE %s SIZE %d COUNT %d"
                                 % (path, fields[i], t, s, c))
            names.append("f%d" % i)
            formats.append((_PCD_TYPES[(t, s)], (c,)) if c > 1 else _PCD_TYPES[(t, s)])
            offsets.append(off)
            off += s * c
        self.rec_dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets,
                                   "itemsize": off})
        for i in (self.ix_field, self.iy_field):
            if counts[i] != 1:
                raise CloudError("%s: PCD field %s has COUNT %d, 1 expected" % (path, fields[i], counts[i]))

    def _xy_columns(self, chunk):
        fx, fy = "f%d" % self.ix_field, "f%d" % self.iy_field
        n = self.count_hint
        size = os.path.getsize(self.path)
        if self.encoding == "binary":
            need = self.data_offset + n * self.rec_dtype.itemsize
            if size < need:
                raise CloudError("%s: PCD binary data truncated (%d bytes, %d needed)" % (self.path, size, need))
            if n == 0:
                return
            mm = np.memmap(self.path, dtype=self.rec_dtype, mode="r", offset=self.data_offset, shape=(n,))
            for s in range(0, n, chunk):
                yield mm[fx][s:s + chunk].astype(np.float64), mm[fy][s:s + chunk].astype(np.float64)
        elif self.encoding == "binary_compressed":
            with open(self.path, "rb") as f:
                f.seek(self.data_offset)
                sizes = f.read(8)
                if len(sizes) < 8:
                    raise CloudError("%s: PCD compressed block header truncated" % self.path)
                csize, usize = struct.unpack("<II", sizes)
                if usize != n * self.rec_dtype.itemsize:
                    raise CloudError("%s: PCD compressed block decodes to %d bytes, %d points need %d"
                                     % (self.path, usize, n, n * self.rec_dtype.itemsize))
                # An LZF back reference of 3 bytes yields at most 264 bytes: ratio <= 88.
                if usize > 88 * csize:
                    raise CloudError("%s: PCD compressed block claims %d decoded bytes from %d"
                                     % (self.path, usize, csize))
                if csize > size - self.data_offset - 8:
                    raise CloudError("%s: PCD compressed block truncated" % self.path)
                comp = f.read(csize)
            try:
                raw = lzf_decompress(comp, usize) if usize else b""
            except ValueError as e:
                raise CloudError("%s: PCD compressed data corrupt: %s" % (self.path, e)) from None
            # Field-major layout: all values of field 0, then of field 1, ...
            cols = []
            off = 0
            for i, (s, t, c) in enumerate(zip(self.sizes, self.types, self.counts)):
                if i in (self.ix_field, self.iy_field):
                    cols.append((i, np.frombuffer(raw, dtype=_PCD_TYPES[(t, s)], count=n, offset=off)))
                off += n * s * c
            col = dict(cols)
            x = col[self.ix_field].astype(np.float64)
            y = col[self.iy_field].astype(np.float64)
            for s in range(0, n, chunk):
                yield x[s:s + chunk], y[s:s + chunk]
        else:
            cx = sum(self.counts[:self.ix_field])
            cy = sum(self.counts[:self.iy_field])
            ntok = sum(self.counts)
            yield from _text_columns(self.path, self.data_offset, cx, cy, ntok, chunk)

    def chunks(self, lat, chunk, mesh_bounds=None):
        seen = 0
        for x, y in self._xy_columns(chunk):
            _guard_geographic(self.path, x, y, mesh_bounds)
            ix, iy = _snap(x, y, lat, (self.path, seen))
            seen += len(x)
            yield ix, iy
        if seen != self.count_hint:
            raise CloudError("%s: header promises %d points, %d read" % (self.path, self.count_hint, seen))


def _text_columns(path, offset, cx, cy, ntok, chunk):
    """x, y columns of whitespace (or comma) separated text lines from byte
    offset; ntok tokens per line when given (None: at least 2)."""
    try:
        with open(path, "r", encoding="latin-1") as f:
            f.seek(offset)
            bx, by = [], []
            for lineno, line in enumerate(f, start=1):
                tok = line.replace(",", " ").split()
                if not tok or tok[0].startswith("#"):
                    continue
                if (ntok is not None and len(tok) != ntok) or len(tok) <= max(cx, cy):
                    raise CloudError("%s: data line %d has %d values" % (path, lineno, len(tok)))
                bx.append(float(tok[cx]))
                by.append(float(tok[cy]))
                if len(bx) == chunk:
                    yield np.array(bx), np.array(by)
                    bx, by = [], []
            if bx:
                yield np.array(bx), np.array(by)
    except ValueError as e:
        raise CloudError("%s: bad number in text data: %s" % (path, e)) from None


class XyzCloud:
    def __init__(self, path):
        self.path = path
        self.bounds = None
        try:
            self.count_hint = max(1, os.path.getsize(path) // 24)
        except OSError as e:
            raise CloudError("%s: cannot read: %s" % (path, e.strerror or e)) from None

    def chunks(self, lat, chunk, mesh_bounds=None):
        seen = 0
        for x, y in _text_columns(self.path, 0, 0, 1, None, chunk):
            _guard_geographic(self.path, x, y, mesh_bounds)
            ix, iy = _snap(x, y, lat, (self.path, seen))
            seen += len(x)
            yield ix, iy
