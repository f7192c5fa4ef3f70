"""LAS record layouts, header and VLR encoding, and the streaming writer.

The writer puts a provisional header and the VLRs first, appends point
records batch by batch (each batch is encoded into one structured numpy array
and written with a single write call), keeps running bounds and per-return
counts, and at close rewrites the header with the final values.  The file is
written under a temporary name and renamed into place only when complete, so
a partial file is never left under the final name.
"""
import os
import struct

import numpy as np

from .rng import derive_key

VERSIONS = {"1.1": (1, 1), "1.2": (1, 2), "1.3": (1, 3), "1.4": (1, 4)}
HEADER_SIZE = {1: 227, 2: 227, 3: 235, 4: 375}
MAX_FORMAT = {1: 1, 2: 3, 3: 5, 4: 10}
GEOGRAPHIC_EPSG = {4326, 4269, 4258, 4283, 4617, 4759, 4322, 4230, 4267, 4617, 6318, 7844}

_BASE_LEGACY = [("X", "<i4"), ("Y", "<i4"), ("Z", "<i4"), ("intensity", "<u2"),
                ("flags", "u1"), ("cls", "u1"), ("angle", "i1"), ("user", "u1"),
                ("psid", "<u2")]
_BASE_EXT = [("X", "<i4"), ("Y", "<i4"), ("Z", "<i4"), ("intensity", "<u2"),
             ("ret", "u1"), ("flags", "u1"), ("cls", "u1"), ("user", "u1"),
             ("angle", "<i2"), ("psid", "<u2"), ("gps", "<f8")]
_GPS = [("gps", "<f8")]
_RGB = [("red", "<u2"), ("green", "<u2"), ("blue", "<u2")]
_NIR = [("nir", "<u2")]
_WAVE = [("wp_index", "u1"), ("wp_offset", "<u8"), ("wp_size", "<u4"),
         ("wp_location", "<f4"), ("wp_dx", "<f4"), ("wp_dy", "<f4"), ("wp_dz", "<f4")]

_LAYOUT = {
    0: _BASE_LEGACY,
    1: _BASE_LEGACY + _GPS,
    2: _BASE_LEGACY + _RGB,
    3: _BASE_LEGACY + _GPS + _RGB,
    4: _BASE_LEGACY + _GPS + _WAVE,
    5: _BASE_LEGACY + _GPS + _RGB + _WAVE,
    6: _BASE_EXT,
    7: _BASE_EXT + _RGB,
    8: _BASE_EXT + _RGB + _NIR,
    9: _BASE_EXT + _WAVE,
    10: _BASE_EXT + _RGB + _NIR + _WAVE,
}
RECORD_LENGTH = {0: 20, 1: 28, 2: 26, 3: 34, 4: 57, 5: 63, 6: 30, 7: 36, 8: 38, 9: 59, 10: 67}


def record_dtype(fmt: int) -> np.dtype:
    dt = np.dtype(_LAYOUT[fmt])
    assert dt.itemsize == RECORD_LENGTH[fmt]
    return dt


# Colour by classification (16-bit RGB at full brightness) and near-infrared level.
_PALETTE = np.zeros((3, 256), dtype=np.uint32)
_PALETTE[:, :] = np.array([150, 140, 130], dtype=np.uint32)[:, None] * 257
for _cls, _rgb in ((2, (140, 115, 85)), (3, (110, 150, 70)), (4, (80, 140, 60)),
                   (5, (50, 110, 45)), (6, (170, 95, 80)), (7, (255, 0, 255))):
    _PALETTE[:, _cls] = np.array(_rgb, dtype=np.uint32) * 257
_NIR_LEVEL = np.full(256, 23000, dtype=np.uint32)
_NIR_LEVEL[[3, 4, 5]] = 52000
_NIR_LEVEL[6] = 20000


class Batch:
    """Points of one batch, one array per attribute (all the same length).

    X, Y, Z: int32 record integers; intensity: uint16; rn, nr: return number
    and number of returns (uint8, 1..15); cls: classification (uint8);
    angle: scan angle in degrees (float32); sflags: scan direction (bit 6)
    and edge of flight line (bit 7), uint8; psid: point source id (uint16);
    gps: GPS time (float64)."""

    __slots__ = ("X", "Y", "Z", "intensity", "rn", "nr", "cls", "angle", "sflags",
                 "psid", "gps")

    def __init__(self, X, Y, Z, intensity, rn, nr, cls, angle, sflags, psid, gps):
        self.X, self.Y, self.Z = X, Y, Z
        self.intensity, self.rn, self.nr, self.cls = intensity, rn, nr, cls
        self.angle, self.sflags, self.psid, self.gps = angle, sflags, psid, gps

    def __len__(self):
        return len(self.X)

    def head(self, n: int) -> "Batch":
        return Batch(*(getattr(self, k)[:n] for k in self.__slots__))

    @staticmethod
    def simple(X, Y, Z, intensity, cls=2, psid=0, gps=0.0) -> "Batch":
        """Single returns with constant attributes (grid/uniform/DEM points)."""
        n = len(X)
        one = np.ones(n, dtype=np.uint8)
        return Batch(X, Y, Z, intensity, one, one, np.full(n, cls, dtype=np.uint8),
                     np.zeros(n, dtype=np.float32), np.zeros(n, dtype=np.uint8),
                     np.full(n, psid, dtype=np.uint16), np.full(n, gps, dtype=np.float64))


def encode(batch: Batch, fmt: int, dtype: np.dtype) -> np.ndarray:
    n = len(batch)
    rec = np.zeros(n, dtype=dtype)
    rec["X"] = batch.X
    rec["Y"] = batch.Y
    rec["Z"] = batch.Z
    rec["intensity"] = batch.intensity
    rec["cls"] = batch.cls
    rec["psid"] = batch.psid
    if fmt < 6:
        f = batch.nr & 7
        f <<= 3
        f |= batch.rn & 7
        f |= batch.sflags
        rec["flags"] = f
        rec["angle"] = np.clip(np.rint(batch.angle), -90, 90)
        if fmt != 0 and fmt != 2:
            rec["gps"] = batch.gps
    else:
        r = batch.nr & 15
        r <<= 4
        r |= batch.rn & 15
        rec["ret"] = r
        rec["flags"] = batch.sflags
        rec["angle"] = np.clip(np.rint(batch.angle * np.float32(1.0 / 0.006)), -30000, 30000)
        rec["gps"] = batch.gps
    if fmt in (2, 3, 5, 7, 8, 10):
        # Brightness from the intensity: 5/8 .. 8/8 of the class colour.
        shade = np.minimum(batch.intensity >> 4, 95).astype(np.uint32)
        shade += 160
        cls = batch.cls
        rec["red"] = (_PALETTE[0][cls] * shade) >> 8
        rec["green"] = (_PALETTE[1][cls] * shade) >> 8
        rec["blue"] = (_PALETTE[2][cls] * shade) >> 8
        if fmt in (8, 10):
            rec["nir"] = (_NIR_LEVEL[cls] * shade) >> 8
    return rec


# ---------------------------------------------------------------- CRS records

def _utm_params(epsg: int):
    """(name, datum block, zone, south) for NAD83 and WGS 84 UTM codes, else None."""
    if 26901 <= epsg <= 26923:
        return "NAD83", epsg - 26900, False
    if 32601 <= epsg <= 32660:
        return "WGS 84", epsg - 32600, False
    if 32701 <= epsg <= 32760:
        return "WGS 84", epsg - 32700, True
    return None


def wkt_for_epsg(epsg: int):
    """OGC WKT 1 for the UTM codes of NAD83 and WGS 84; None for other codes."""
    p = _utm_params(epsg)
    if p is None:
        return None
    datum, zone, south = p
    if datum == "NAD83":
        geog = ('GEOGCS["NAD83",DATUM["North_American_Datum_1983",'
                'SPHEROID["GRS 1980",6378137,298.257222101,AUTHORITY["EPSG","7019"]],'
                'AUTHORITY["EPSG","6269"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],'
                'UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],'
                'AUTHORITY["EPSG","4269"]]')
    else:
        geog = ('GEOGCS["WGS 84",DATUM["WGS_1984",'
                'SPHEROID["WGS 84",6378137,298.257223563,AUTHORITY["EPSG","7030"]],'
                'AUTHORITY["EPSG","6326"]],PRIMEM["Greenwich",0,AUTHORITY["EPSG","8901"]],'
                'UNIT["degree",0.0174532925199433,AUTHORITY["EPSG","9122"]],'
                'AUTHORITY["EPSG","4326"]]')
    name = "%s / UTM zone %d%s" % (datum, zone, "S" if south else "N")
    cm = -183 + 6 * zone
    return ('PROJCS["%s",%s,PROJECTION["Transverse_Mercator"],'
            'PARAMETER["latitude_of_origin",0],PARAMETER["central_meridian",%d],'
            'PARAMETER["scale_factor",0.9996],PARAMETER["false_easting",500000],'
            'PARAMETER["false_northing",%d],UNIT["metre",1,AUTHORITY["EPSG","9001"]],'
            'AXIS["Easting",EAST],AXIS["Northing",NORTH],AUTHORITY["EPSG","%d"]]'
            % (name, geog, cm, 10000000 if south else 0, epsg))


def _vlr(user: str, record_id: int, payload: bytes, desc: str) -> bytes:
    if len(payload) > 65535:
        raise ValueError("VLR payload too large")
    return struct.pack("<H16sHH32s", 0, user.encode(), record_id, len(payload),
                       desc.encode()[:32]) + payload


def geokeys_vlr(epsg: int) -> bytes:
    # GeoKeyDirectoryTag: header (version 1, revision 1.0, key count), then
    # (key id, tag location 0 = value inline, count 1, value), keys ascending.
    keys = [(1024, 1), (1025, 1), (3072, epsg), (3076, 9001), (4099, 9001)]
    words = [1, 1, 0, len(keys)]
    for kid, val in keys:
        words += [kid, 0, 1, val]
    return _vlr("LASF_Projection", 34735, struct.pack("<%dH" % len(words), *words),
                "GeoTiff GeoKeyDirectoryTag")


def wkt_vlr(wkt: str) -> bytes:
    return _vlr("LASF_Projection", 2112, wkt.encode("ascii") + b"\0", "OGC WKT coordinate system")


# ---------------------------------------------------------------- writer

class LasWriter:
    """Streams point batches into a LAS file.

    version: "1.1".."1.4"; fmt: point data format allowed by that version;
    scale, offset: 3-tuples; epsg: 0 for none; crs: "auto" (GeoKeys, or WKT
    for formats 6-10 as LAS 1.4 requires), "geotiff" or "wkt" (1.4 only).
    The caller must call close() (returns a summary) or abort()."""

    def __init__(self, path, version="1.2", fmt=3, scale=(0.01, 0.01, 0.01),
                 offset=(0.0, 0.0, 0.0), epsg=0, crs="auto", seed=0,
                 software="gdt-tile gen_cloud"):
        if version not in VERSIONS:
            raise ValueError("unsupported LAS version %s (1.1-1.4)" % version)
        self.major, self.minor = VERSIONS[version]
        if not 0 <= fmt <= MAX_FORMAT[self.minor]:
            raise ValueError("point format %d needs a newer LAS version than %s" % (fmt, version))
        if any(not (s > 0) for s in scale):
            raise ValueError("scale must be positive")
        self.fmt = fmt
        self.dtype = record_dtype(fmt)
        self.scale = tuple(float(s) for s in scale)
        self.offset = tuple(float(o) for o in offset)
        self.seed = seed
        self.software = software
        self.wkt_bit = False
        vlrs = []
        if epsg:
            if epsg in GEOGRAPHIC_EPSG:
                raise ValueError("EPSG:%d is geographic; the generator writes projected "
                                 "metres" % epsg)
            use_wkt = crs == "wkt" or (crs == "auto" and fmt >= 6)
            if use_wkt:
                if self.minor < 4:
                    raise ValueError("a WKT CRS needs LAS 1.4")
                wkt = wkt_for_epsg(epsg)
                if wkt is None:
                    raise ValueError("no WKT known for EPSG:%d (NAD83/WGS 84 UTM codes only); "
                                     "use --crs geotiff" % epsg)
                vlrs.append(wkt_vlr(wkt))
                self.wkt_bit = True
            else:
                vlrs.append(geokeys_vlr(epsg))
        self.vlrs = vlrs
        self.header_size = HEADER_SIZE[self.minor]
        self.data_offset = self.header_size + sum(len(v) for v in vlrs)
        self.count = 0
        self.mins = [np.iinfo(np.int32).max] * 3
        self.maxs = [np.iinfo(np.int32).min] * 3
        self.by_return = np.zeros(16, dtype=np.int64)
        self.path = os.fspath(path)
        self.tmp = self.path + ".part"
        self.f = open(self.tmp, "wb")
        self.f.write(self._header())
        for v in vlrs:
            self.f.write(v)

    def _header(self) -> bytes:
        n = self.count
        if n:
            mn = [self.mins[i] * self.scale[i] + self.offset[i] for i in range(3)]
            mx = [self.maxs[i] * self.scale[i] + self.offset[i] for i in range(3)]
        else:
            mn = [0.0, 0.0, 0.0]
            mx = [0.0, 0.0, 0.0]
        enc = 0
        if self.minor >= 2:
            enc |= 1  # GPS time is adjusted standard GPS time
        if self.wkt_bit:
            enc |= 16
        g = derive_key(self.seed, "guid")
        guid = struct.pack("<IHH8s", g & 0xFFFFFFFF, (g >> 32) & 0xFFFF, (g >> 48) & 0xFFFF,
                           derive_key(self.seed, "guid2").to_bytes(8, "little"))
        ret = [int(c) for c in self.by_return[1:16]]
        legacy_ok = self.fmt < 6 and n < 2 ** 32
        if self.minor < 4 and n >= 2 ** 32:
            raise ValueError("LAS %d.%d cannot hold %d points" % (self.major, self.minor, n))
        legacy_n = n if legacy_ok else 0
        legacy_ret = [min(c, 2 ** 32 - 1) if legacy_ok else 0 for c in ret[:5]]
        h = struct.pack("<4sHH16sBB32s32sHHHIIBHI5I3d3d6d",
                        b"LASF", 0, enc, guid, self.major, self.minor,
                        b"OTHER", self.software.encode()[:32], 1, 2020,
                        self.header_size, self.data_offset, len(self.vlrs), self.fmt,
                        self.dtype.itemsize, legacy_n, *legacy_ret,
                        *self.scale, *self.offset,
                        mx[0], mn[0], mx[1], mn[1], mx[2], mn[2])
        if self.minor >= 3:
            h += struct.pack("<Q", 0)
        if self.minor >= 4:
            h += struct.pack("<QIQ15Q", 0, 0, n, *ret)
        assert len(h) == self.header_size
        return h

    def write(self, batch: Batch):
        n = len(batch)
        if n == 0:
            return
        if self.minor < 4 and self.count + n >= 2 ** 32:
            raise ValueError("LAS %d.%d cannot hold more than 2^32-1 points"
                             % (self.major, self.minor))
        rec = encode(batch, self.fmt, self.dtype)
        self.f.write(memoryview(rec).cast("B"))
        for i, a in enumerate((batch.X, batch.Y, batch.Z)):
            lo = int(a.min())
            hi = int(a.max())
            if lo < self.mins[i]:
                self.mins[i] = lo
            if hi > self.maxs[i]:
                self.maxs[i] = hi
        self.by_return += np.bincount(batch.rn, minlength=16)[:16]
        self.count += n

    def close(self) -> dict:
        self.f.seek(0)
        self.f.write(self._header())
        self.f.flush()
        self.f.close()
        os.replace(self.tmp, self.path)

        def world(v):
            return [v[i] * self.scale[i] + self.offset[i] for i in range(3)] if self.count else None

        return {
            "points": self.count,
            "min": world(self.mins),
            "max": world(self.maxs),
            "by_return": [int(c) for c in self.by_return[1:16]],
            "bytes": self.data_offset + self.count * self.dtype.itemsize,
        }

    def abort(self):
        try:
            self.f.close()
        finally:
            if os.path.exists(self.tmp):
                os.unlink(self.tmp)
