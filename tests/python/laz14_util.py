"""Layered LAZ fixtures for the tests: point arrays whose every field
varies, written with laspy's LASzip or laz-rs back-end at any chunk size,
and byte-level access to the chunks (layer sizes, item versions) for the
corruption tests.  Used by test_laz14_decode.py.
"""
import io
import pathlib
import struct

import laspy
import lazrs
import numpy as np

DATA = pathlib.Path(__file__).resolve().parent / "data"
EXTRA = [("eb_u8", "u1"), ("eb_i32", "i4")]

def make_las(fmt, n, seed, channels=4, extra=True, channel_base=0):
    """n points of format fmt; the scanner channel runs over channel_base ..
    channel_base + channels - 1 (mod 4) in runs of 1-11 points."""
    rng = np.random.default_rng(seed)
    h = laspy.LasHeader(point_format=fmt, version="1.4")
    if extra:
        h.add_extra_dims([laspy.ExtraBytesParams(nm, t) for nm, t in EXTRA])
    h.scales = [0.01, 0.01, 0.01]
    h.offsets = [0, 0, 0]
    las = laspy.LasData(h)
    a = np.zeros(n, dtype=las.points.array.dtype)
    # scanner channel in runs, so it changes often but not at every point
    runs = rng.integers(1, 12, size=n)
    ch = (np.repeat(rng.integers(0, channels, size=n), runs)[:n] + channel_base) % 4
    a["X"] = np.cumsum(rng.integers(-50, 200, size=n)).astype(np.int32) + 100000
    a["Y"] = (np.cumsum(rng.integers(-80, 80, size=n)) + 500000).astype(np.int32)
    a["Z"] = (rng.normal(0, 300, size=n).astype(np.int64) + 2000).astype(np.int32)
    a["intensity"] = rng.integers(0, 65536, size=n)
    nret = rng.integers(1, 16, size=n)
    ret = np.minimum(rng.integers(1, 16, size=n), nret)
    a["bit_fields"] = (ret | (nret << 4)).astype(np.uint8)
    cf = rng.integers(0, 16, size=n)  # synthetic, key point, withheld, overlap
    sd = rng.integers(0, 2, size=n)
    eg = (rng.random(n) < 0.05).astype(np.int64)
    a["classification_flags"] = (cf | (ch << 4) | (sd << 6) | (eg << 7)).astype(np.uint8)
    a["classification"] = rng.choice([1, 2, 6, 9, 17, 40, 64, 200, 255], size=n)
    a["user_data"] = rng.integers(0, 256, size=n)
    a["scan_angle"] = np.cumsum(rng.integers(-30, 31, size=n)).astype(np.int16)
    a["point_source_id"] = np.repeat(rng.integers(0, 65536, size=n // 100 + 1), 100)[:n]
    # GPS time: pulses of several returns, steps of varying size, rare jumps
    # and two interleaved time lines (the coder's sequence switches)
    t = 1.0e8 + np.cumsum(rng.integers(0, 3, size=n) * rng.choice([1e-6, 1e-5, 1e-2], size=n))
    t = t + np.cumsum(rng.random(n) < 0.002) * 12345.678
    other = np.repeat(rng.random(n // 8 + 1) < 0.3, 8)[:n]
    t[other] += 98765.4321
    a["gps_time"] = t
    names = a.dtype.names
    if "red" in names:
        for c in ("red", "green", "blue"):
            a[c] = np.clip(np.cumsum(rng.integers(-300, 301, size=n)) + 30000, 0, 65535)
    if "nir" in names:
        a["nir"] = rng.integers(0, 65536, size=n)
    if "wavepacket_index" in names:
        a["wavepacket_index"] = rng.integers(0, 4, size=n)
        sizes = rng.integers(20, 400, size=n)
        a["wavepacket_size"] = sizes
        # the offset: after the last packet, the same, a 32-bit step or far
        step = np.where(rng.random(n) < 0.6, np.roll(sizes, 1), 0)
        step = np.where(rng.random(n) < 0.2, rng.integers(-5000, 5000, size=n), step)
        off = np.cumsum(step) + 10**6
        off[rng.random(n) < 0.01] += 2**40
        a["wavepacket_offset"] = off.astype(np.uint64)
        a["return_point_wave_location"] = rng.random(n).astype(np.float32) * 1000
        for c in ("x_t", "y_t", "z_t"):
            a[c] = rng.normal(0, 1, size=n).astype(np.float32)
    if extra:
        a["eb_u8"] = rng.integers(0, 256, size=n)
        a["eb_i32"] = np.cumsum(rng.integers(-1000, 1000, size=n))
    las.points = laspy.PackedPointRecord(a, h.point_format)
    return las


def _vlr_payload_at(data):
    i = data.find(b"laszip encoded")
    assert i > 0
    start = i - 2
    length = struct.unpack_from("<H", data, start + 20)[0]
    return start + 54, length


def write_laz(las, path, backend="laszip", chunks=None):
    """backend laszip or lazrs at the default 50000 chunk; chunks: an int
    (fixed chunk size, lazrs) or a list of chunk lengths (variable, lazrs)."""
    if chunks is None:
        be = laspy.LazBackend.Laszip if backend == "laszip" else laspy.LazBackend.Lazrs
        las.write(str(path), do_compress=True, laz_backend=be)
        return
    buf = io.BytesIO()
    las.write(buf, do_compress=True, laz_backend=laspy.LazBackend.Lazrs)
    data = bytearray(buf.getvalue())
    p, length = _vlr_payload_at(bytes(data))
    off = struct.unpack_from("<I", data, 96)[0]
    fmt = las.header.point_format
    variable = not isinstance(chunks, int)
    if variable:
        rec = lazrs.LazVlr.new_for_compression(fmt.id, fmt.num_extra_bytes, True).record_data()
        assert len(rec) == length
        data[p:p + length] = rec
    else:
        struct.pack_into("<I", data, p + 12, chunks)
    rec = bytes(data[p:p + length])
    dest = io.BytesIO()
    dest.write(bytes(data[:off]))
    comp = lazrs.LasZipCompressor(dest, lazrs.LazVlr(rec))
    raw = np.frombuffer(las.points.array.tobytes(), np.uint8)
    size = fmt.size
    if variable:
        start = 0
        for k, c in enumerate(chunks):
            if k:
                comp.finish_current_chunk()
            comp.compress_many(raw[start * size:(start + c) * size])
            start += c
        assert start == len(las.points)
    else:
        comp.compress_many(raw)
    comp.done()
    with open(path, "wb") as f:
        f.write(dest.getvalue())


# ---- decoding and comparing ---------------------------------------------

def decode(runner, tool, path, need):
    """The records tests/laz_decode prints for path with --need need."""
    r = runner([tool("laz_decode"), "--need", need, path], text=False)
    assert r.returncode == 0, r.stderr.decode()
    return r.stdout


def laspy_records(path):
    return laspy.read(str(path)).points.array.tobytes()


def assert_records_equal(got, exp, record_length, path):
    if got == exp:
        return
    assert len(got) == len(exp), f"{path}: {len(got)} bytes decoded, {len(exp)} expected"
    g = np.frombuffer(got, np.uint8).reshape(-1, record_length)
    e = np.frombuffer(exp, np.uint8).reshape(-1, record_length)
    rows = np.nonzero((g != e).any(axis=1))[0]
    cols = np.nonzero((g != e).any(axis=0))[0]
    raise AssertionError(f"{path}: {len(rows)} records differ, first {rows[:5].tolist()}, "
                         f"record bytes {cols.tolist()}")


GROUPS = {"xyz": ("X", "Y", "Z"), "class": ("classification",),
          "flags": ("bit_fields", "classification_flags")}


def expected_selective(las, need):
    """The records with only the fields of need (a comma list of xyz, class,
    flags) and zeros elsewhere."""
    a = las.points.array
    out = np.zeros_like(a)
    for group in need.split(","):
        for name in GROUPS[group]:
            out[name] = a[name]
    return out.tobytes()


# ---- the bytes of a layered LAZ file -------------------------------------

def _vlr_items(data):
    p, _ = _vlr_payload_at(data)
    n = struct.unpack_from("<H", data, p + 32)[0]
    return p, [struct.unpack_from("<HHH", data, p + 34 + 6 * k) for k in range(n)]


def item_versions(path):
    return [v for _, _, v in _vlr_items(path.read_bytes())[1]]


def set_item_versions(path, version):
    data = bytearray(path.read_bytes())
    p, items = _vlr_items(bytes(data))
    for k in range(len(items)):
        struct.pack_into("<H", data, p + 38 + 6 * k, version)
    path.write_bytes(bytes(data))


def _nlayers(data):
    count = {10: 9, 11: 1, 12: 2, 13: 1}
    return sum(count.get(t, s) for t, s, _ in _vlr_items(data)[1])


def table_offset(data):
    return struct.unpack_from("<q", data, struct.unpack_from("<I", data, 96)[0])[0]


def chunk_start(data, k):
    """File offset of chunk k, walked through the layer sizes."""
    rl = struct.unpack_from("<H", data, 105)[0]
    nl = _nlayers(data)
    at = struct.unpack_from("<I", data, 96)[0] + 8
    for _ in range(k):
        sizes = struct.unpack_from(f"<{nl}I", data, at + rl + 4)
        at += rl + 4 + 4 * nl + sum(sizes)
    return at


def layer_size_offset(data, chunk, layer):
    """File offset of the u32 size of layer (0-based, all items) of chunk."""
    rl = struct.unpack_from("<H", data, 105)[0]
    return chunk_start(data, chunk) + rl + 4 + 4 * layer


def layer_sizes(path, chunk):
    data = path.read_bytes()
    return list(struct.unpack_from(f"<{_nlayers(data)}I", data,
                                   layer_size_offset(data, chunk, 0)))
