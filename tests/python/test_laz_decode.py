"""The LASzip decoder (io/private/laz_*.c) through the laz_decode tool.

Fixtures are LAZ files written at test time with lazrs (fixed chunks of 1,
7 and 50000 points, variable chunks, version 1 and 2 items, point formats
0-5 with extra bytes of several sizes, empty and one-point files) and with
LASzip (laspy's laszip back-end), from seeded random but realistic points.  Every decoded record must equal, byte
for byte, what laspy decodes with both its lazrs and its laszip back-ends
(and the records that were compressed).  Then the damaged files: a missing
table, truncated and corrupt chunks, bad VLRs.
"""
import io
import re
import struct

import numpy as np
import pytest

from conftest import run

laspy = pytest.importorskip("laspy")
lazrs = pytest.importorskip("lazrs")

LAZRS = laspy.LazBackend.Lazrs
LASZIP = laspy.LazBackend.Laszip

# extra bytes per point format: (name, laspy type) lists, sizes 0 to 10
EXTRA = {
    0: [("e3", "3u1")],
    1: [],
    2: [("e1", "u1")],
    3: [("f8", "f8"), ("i2", "i2")],
    4: [("e5", "5u1")],
    5: [("u2", "u2")],
}


def wrap_i32(v):
    return ((np.asarray(v, dtype=np.int64) + 2**31) % 2**32 - 2**31).astype(np.int32)


def make_points(pf, n, seed):
    """n records of point format pf: every field varies, mostly smoothly as
    in a scan, with jumps, repeats and a few arbitrary bytes."""
    rng = np.random.default_rng(seed)
    a = np.zeros(n, pf.dtype())
    if n == 0:
        return a
    for c, s in (("X", 40), ("Y", 40), ("Z", 8)):
        step = rng.normal(0, s, n).astype(np.int64)
        jump = rng.random(n) < 0.01
        step[jump] = rng.integers(-2**31, 2**31, jump.sum())
        a[c] = wrap_i32(np.cumsum(step) + rng.integers(-2**20, 2**20))
    a["intensity"] = np.where(rng.random(n) < 0.2, rng.integers(0, 65536, n),
                              np.clip(300 + rng.normal(0, 40, n), 0, 65535)).astype(np.uint16)
    nret = rng.integers(1, 6, n)
    ret = (rng.random(n) * nret).astype(np.int64) + 1
    bits = ret | nret << 3 | (rng.random(n) < 0.5) << 6 | (rng.random(n) < 0.05) << 7
    odd = rng.random(n) < 0.03
    bits[odd] = rng.integers(0, 256, odd.sum())
    a["bit_fields"] = bits.astype(np.uint8)
    cls = rng.choice(np.array([1, 2, 3, 5, 6, 9], np.uint8), n)
    odd = rng.random(n) < 0.05
    cls[odd] = rng.integers(0, 256, odd.sum())
    a["raw_classification"] = cls
    a["scan_angle_rank"] = np.clip(np.cumsum(rng.integers(-1, 2, n)) % 60 - 30
                                   + (rng.random(n) < 0.02) * rng.integers(-90, 90, n),
                                   -128, 127).astype(np.int8)
    a["user_data"] = np.where(rng.random(n) < 0.1, rng.integers(0, 256, n),
                              rng.integers(0, 3, n)).astype(np.uint8)
    a["point_source_id"] = (np.cumsum(rng.random(n) < 0.01) * 7 + 100).astype(np.uint16)
    names = pf.dtype().names
    if "gps_time" in names:
        t = 2.0e5 + np.cumsum(rng.choice([0.0, 0.0, 1e-5, 2.5e-5, 1e-3], n))
        # two interleaved flight lines, big jumps and arbitrary doubles
        other = rng.random(n) < 0.1
        t[other] += 5.0e4
        jump = rng.random(n) < 0.005
        t[jump] = rng.random(jump.sum()) * 1e9
        bits64 = t.view(np.uint64)
        odd = rng.random(n) < 0.003
        bits64[odd] = rng.integers(0, 2**63, odd.sum(), dtype=np.uint64)
        a["gps_time"] = bits64.view(np.float64)
    if "red" in names:
        base = np.clip(np.cumsum(rng.normal(0, 600, n)) % 65536, 0, 65535)
        for c, off in (("red", 0), ("green", 900), ("blue", -700)):
            v = np.clip(base + off + rng.normal(0, 300, n), 0, 65535).astype(np.uint16)
            eight = rng.random(n) < 0.2
            v[eight] = (v[eight] >> 8) * 257  # 8-bit colours scaled
            a[c] = v
        grey = rng.random(n) < 0.1
        a["green"][grey] = a["red"][grey]
        a["blue"][grey] = a["red"][grey]
    if "wavepacket_index" in names:
        size = rng.choice(np.array([256, 512, 512, 1024], np.uint32), n)
        off = np.cumsum(size.astype(np.uint64)) + np.uint64(60000)
        same = rng.random(n) < 0.1
        off[same] = np.roll(off, 1)[same]
        jump = rng.random(n) < 0.02
        off[jump] = rng.integers(0, 2**40, jump.sum(), dtype=np.uint64)
        a["wavepacket_index"] = rng.integers(1, 4, n).astype(np.uint8)
        a["wavepacket_offset"] = off
        a["wavepacket_size"] = size
        a["return_point_wave_location"] = rng.normal(1000, 200, n).astype(np.float32)
        for c in ("x_t", "y_t", "z_t"):
            a[c] = (rng.normal(0, 1e-4, n) + rng.choice([0.0, 3e-4], n)).astype(np.float32)
    base = laspy.PointFormat(pf.id).size
    if pf.size > base:
        raw = a.view(np.uint8).reshape(n, pf.size)[:, base:]
        runs = np.repeat(rng.integers(0, 256, (n // 16 + 1, raw.shape[1]), dtype=np.uint8), 16,
                         axis=0)[:n]
        noise = rng.random(raw.shape) < 0.3
        raw[:] = np.where(noise, rng.integers(0, 256, raw.shape, dtype=np.uint8), runs)
    return a


def build_las(fmt, n, seed, extra=True):
    hdr = laspy.LasHeader(point_format=fmt, version="1.3" if fmt >= 4 else "1.2")
    for name, typ in EXTRA[fmt] if extra else []:
        hdr.add_extra_dim(laspy.ExtraBytesParams(name=name, type=typ))
    las = laspy.LasData(hdr)
    las.points = laspy.PackedPointRecord(make_points(hdr.point_format, n, seed),
                                         hdr.point_format)
    return las


def write_laz(path, las, chunks=50000, version=2, wave_version=1):
    """Compresses las with lazrs into path.  chunks: the fixed chunk size,
    or a list of chunk point counts (variable chunks).  version: the item
    version written in the VLR (lazrs codes versions 1 and 2);
    wave_version that of WAVEPACKET13 (LASzip knows only 1, lazrs writes 2,
    both code it alike)."""
    raw = io.BytesIO()
    las.write(raw)
    b = bytearray(raw.getvalue())
    header_size, offset = struct.unpack_from("<HI", b, 94)
    (nvlr,) = struct.unpack_from("<I", b, 100)
    fmt = las.header.point_format
    variable = isinstance(chunks, list)
    vlr = lazrs.LazVlr.new_for_compression(fmt.id, fmt.num_extra_bytes, variable)
    rd = bytearray(vlr.record_data())
    if not variable:
        struct.pack_into("<I", rd, 12, chunks)
    (nitems,) = struct.unpack_from("<H", rd, 32)
    for i in range(nitems):
        (typ,) = struct.unpack_from("<H", rd, 34 + 6 * i)
        struct.pack_into("<H", rd, 34 + 6 * i + 4, wave_version if typ == 9 else version)
    vlr = lazrs.LazVlr(bytes(rd))
    vlr_rec = struct.pack("<H16sHH32s", 0, b"laszip encoded", 22204, len(rd), b"") + rd
    head = b[:offset]
    head[104] |= 0x80
    struct.pack_into("<I", head, 96, offset + len(vlr_rec))
    struct.pack_into("<I", head, 100, nvlr + 1)
    dest = io.BytesIO()
    dest.write(bytes(head) + vlr_rec)
    comp = lazrs.LasZipCompressor(dest, vlr)
    pts = np.frombuffer(las.points.array.tobytes(), np.uint8)
    if variable:
        rl = fmt.size
        start = 0
        for k, cnt in enumerate(chunks):
            comp.compress_many(pts[start * rl:(start + cnt) * rl])
            start += cnt
            if k + 1 < len(chunks):
                comp.finish_current_chunk()
    elif len(pts):
        comp.compress_many(pts)
    comp.done()
    path.write_bytes(dest.getvalue())
    return path


def decode(tool, path, *args):
    return run([str(tool("laz_decode")), *args, str(path)], text=False)


def oracle_records(path):
    """The records laspy decodes with lazrs and with laszip (they must agree)."""
    a = laspy.read(str(path), laz_backend=LAZRS).points.array.tobytes()
    b = laspy.read(str(path), laz_backend=LASZIP).points.array.tobytes()
    assert a == b, "lazrs and laszip disagree on the fixture"
    return a


def check_same(tool, path, expect):
    r = decode(tool, path)
    assert r.returncode == 0, r.stderr.decode()
    assert len(r.stdout) == len(expect)
    if r.stdout != expect:
        rl = len(expect) // max(1, laspy.read(str(path), laz_backend=LAZRS).header.point_count)
        first = next(i for i in range(len(expect)) if r.stdout[i] != expect[i])
        pytest.fail(f"record {first // rl} differs at byte {first % rl}")
    return r


def var_chunks(n, seed):
    rng = np.random.default_rng(seed)
    out, left = [], n
    while left > 0:
        c = int(min(left, rng.choice([1, 5, 17, 300, 1000])))
        out.append(c)
        left -= c
    return out


@pytest.mark.parametrize("fmt", range(6))
@pytest.mark.parametrize("chunks", [1, 7, 50000, "variable"])
def test_formats_match_laspy(tool, tmp_path, fmt, chunks):
    n = 1500
    las = build_las(fmt, n, seed=fmt * 10 + 1)
    ch = var_chunks(n, fmt) if chunks == "variable" else chunks
    path = write_laz(tmp_path / f"f{fmt}.laz", las, ch)
    expect = las.points.array.tobytes()
    assert oracle_records(path) == expect
    check_same(tool, path, expect)


@pytest.mark.parametrize("fmt", range(6))
def test_laszip_written(tool, tmp_path, fmt):
    """Files LASzip's own encoder writes (through laspy's laszip back-end)."""
    las = build_las(fmt, 3000, seed=fmt + 500)
    path = tmp_path / f"lz{fmt}.laz"
    las.write(str(path), laz_backend=LASZIP)
    expect = las.points.array.tobytes()
    assert oracle_records(path) == expect
    check_same(tool, path, expect)


# Version 1 items: lazrs's POINT10, GPSTIME11 and WAVEPACKET13 agree with
# LASzip; its RGB12 and BYTE version 1 encoders do not (LASzip and lazrs
# itself fail on their output), so no file here has those; tests/c/test_laz_v1.c
# checks them against chunks encoded as LASzip's writer defines them.
@pytest.mark.parametrize("fmt", [0, 1, 4])
def test_version1_items(tool, tmp_path, fmt):
    las = build_las(fmt, 1200, seed=fmt + 77, extra=False)
    path = write_laz(tmp_path / f"v1_{fmt}.laz", las, 100, version=1)
    expect = las.points.array.tobytes()
    assert oracle_records(path) == expect
    check_same(tool, path, expect)


@pytest.mark.parametrize("fmt", [4, 5])
def test_wavepacket_version2(tool, tmp_path, fmt):
    """lazrs's own VLR: WAVEPACKET13 version 2 (LASzip's reader refuses it)."""
    las = build_las(fmt, 800, seed=fmt + 31)
    path = write_laz(tmp_path / "w2.laz", las, 64, wave_version=2)
    expect = las.points.array.tobytes()
    assert laspy.read(str(path), laz_backend=LAZRS).points.array.tobytes() == expect
    check_same(tool, path, expect)


@pytest.mark.parametrize("n", [0, 1, 2])
def test_tiny_files(tool, tmp_path, n):
    las = build_las(3, n, seed=5)
    path = write_laz(tmp_path / "tiny.laz", las, 7)
    expect = las.points.array.tobytes()
    assert oracle_records(path) == expect
    check_same(tool, path, expect)


def test_need_is_all_for_pointwise_chunks(tool, tmp_path):
    """Pointwise chunks share one stream: every field is decoded whatever
    the fields asked for; an unknown field is a usage error."""
    las = build_las(3, 500, seed=17)
    path = write_laz(tmp_path / "p.laz", las, 100)
    for need in ("xyz", "xyz,class", "flags", "all"):
        r = decode(tool, path, "--need", need)
        assert r.returncode == 0 and r.stdout == las.points.array.tobytes(), need
    assert decode(tool, path, "--need", "colour").returncode == 2


def test_autzen_matches_las(tool, data_dir):
    laz, las = data_dir / "autzen_trim.laz", data_dir / "autzen_trim.las"
    if not laz.exists() or not las.exists():
        pytest.skip("autzen_trim.laz/.las not in the samples")
    expect = laspy.read(str(las)).points.array.tobytes()
    check_same(tool, laz, expect)


def laszip_vlr(b):
    """The offset of the LASzip VLR's payload in the file bytes b, and its length."""
    i = b.find(b"laszip encoded") - 2
    (n,) = struct.unpack_from("<H", b, i + 20)
    return i + 54, n


def chunk_table(path):
    """[(start, bytes, count)] of the chunks, read by lazrs."""
    b = path.read_bytes()
    p, n = laszip_vlr(b)
    (offset,) = struct.unpack_from("<I", b, 96)
    with open(path, "rb") as f:
        f.seek(offset)
        table = lazrs.read_chunk_table(f, lazrs.LazVlr(b[p:p + n]))
    out, pos = [], offset + 8
    for count, nbytes in table:
        out.append((pos, nbytes, count))
        pos += nbytes
    return out


def test_missing_table_scans_fixed_chunks(tool, tmp_path):
    las = build_las(1, 600, seed=3)
    path = write_laz(tmp_path / "full.laz", las, 50)
    table = chunk_table(path)
    end = table[-1][0] + table[-1][1]
    cut = tmp_path / "notable.laz"
    cut.write_bytes(path.read_bytes()[:end])
    r = check_same(tool, cut, las.points.array.tobytes())
    assert b"GDT-3911" in r.stderr


def test_missing_table_variable_chunks_fails(tool, tmp_path):
    las = build_las(0, 300, seed=4)
    path = write_laz(tmp_path / "full.laz", las, [100, 50, 150])
    table = chunk_table(path)
    cut = tmp_path / "notable.laz"
    cut.write_bytes(path.read_bytes()[:table[-1][0] + table[-1][1]])
    r = decode(tool, cut)
    assert r.returncode == 3
    assert b"GDT-3910" in r.stderr


@pytest.mark.parametrize("trailer", [True, False])
def test_table_offset_in_trailer(tool, tmp_path, trailer):
    """An offset word of -1: the table's offset is the file's last 8 bytes
    (a writer that could not seek back); without them the chunks are
    scanned."""
    las = build_las(1, 400, seed=19)
    path = write_laz(tmp_path / "full.laz", las, 50)
    b = bytearray(path.read_bytes())
    (offset,) = struct.unpack_from("<I", b, 96)
    (table,) = struct.unpack_from("<q", b, offset)
    struct.pack_into("<q", b, offset, -1)
    b += struct.pack("<q", table if trailer else 2**40)
    moved = tmp_path / "trailer.laz"
    moved.write_bytes(bytes(b))
    r = check_same(tool, moved, las.points.array.tobytes())
    assert (b"GDT-3911" in r.stderr) != trailer, r.stderr.decode()


@pytest.mark.parametrize("chunks, rc, code", [(50, 0, b"GDT-3911"), ([100, 200], 3, b"GDT-3910")])
def test_unknown_table_version(tool, tmp_path, chunks, rc, code):
    """A table of another version is no table: fixed chunks are scanned."""
    las = build_las(2, 300, seed=13)
    path = write_laz(tmp_path / "full.laz", las, chunks)
    b = bytearray(path.read_bytes())
    (offset,) = struct.unpack_from("<I", b, 96)
    (table,) = struct.unpack_from("<q", b, offset)
    struct.pack_into("<I", b, table, 1)
    bad = tmp_path / "v1table.laz"
    bad.write_bytes(bytes(b))
    r = decode(tool, bad)
    assert r.returncode == rc and code in r.stderr, r.stderr.decode()
    if rc == 0:
        assert r.stdout == las.points.array.tobytes()


@pytest.mark.parametrize("chunks, field, rc, code", [
    ([100, 200], "table", 0, b"GDT-3916"),  # 2^32 - 1 chunks claimed: the header's fill 2
    (50, "header", 3, b"GDT-3913"),         # 2^32 - 1 points claimed: cannot fit
])
def test_huge_counts_cost_nothing(tool, tmp_path, chunks, field, rc, code):
    """Counts far past the file are neither allocated for nor decoded."""
    las = build_las(0, 300, seed=14)
    path = write_laz(tmp_path / "full.laz", las, chunks)
    b = bytearray(path.read_bytes())
    (offset,) = struct.unpack_from("<I", b, 96)
    (table,) = struct.unpack_from("<q", b, offset)
    struct.pack_into("<I", b, table + 4 if field == "table" else 107, 0xFFFFFFFF)
    bad = tmp_path / "huge.laz"
    bad.write_bytes(bytes(b))
    r = run([str(tool("laz_decode")), str(bad)], text=False, timeout=20)
    assert r.returncode == rc and code in r.stderr, r.stderr.decode()
    if rc == 0:
        assert r.stdout == las.points.array.tobytes()


@pytest.mark.parametrize("chunks, count, warning", [
    (100, 650, None),            # the last chunk read in part
    (100, 550, b"GDT-3916"),     # a chunk too many in the table
    ([100, 50, 150], 200, b"GDT-3917"),  # a variable chunk cut
])
def test_header_count_wins(tool, tmp_path, chunks, count, warning):
    las = build_las(3, 700 if chunks == 100 else 300, seed=21)
    path = write_laz(tmp_path / "full.laz", las, chunks)
    b = bytearray(path.read_bytes())
    struct.pack_into("<I", b, 107, count)
    short = tmp_path / "short.laz"
    short.write_bytes(bytes(b))
    r = decode(tool, short)
    assert r.returncode == 0, r.stderr.decode()
    assert r.stdout == las.points.array.tobytes()[:count * las.header.point_format.size]
    if warning:
        assert warning in r.stderr, r.stderr.decode()


@pytest.mark.parametrize("fmt", [0, 3, 5])
def test_truncated_chunk_names_it(tool, tmp_path, fmt):
    las = build_las(fmt, 700, seed=8)
    path = write_laz(tmp_path / "full.laz", las, 100)
    table = chunk_table(path)
    k = 4
    start, nbytes, _ = table[k]
    cut = tmp_path / "cut.laz"
    cut.write_bytes(path.read_bytes()[:start + nbytes // 2])
    r = decode(tool, cut)
    assert r.returncode == 3, r.stderr.decode()
    assert re.search(rb"GDT-392[02] .*chunk %d\b" % k, r.stderr), r.stderr.decode()
    # what came out before the failure are the first k chunks, exactly
    rl = las.header.point_format.size
    assert r.stdout == las.points.array.tobytes()[:k * 100 * rl]


def test_chunk_shorter_than_its_table_entry(tool, tmp_path):
    """A chunk whose stream needs more bytes than the table gives it."""
    las = build_las(2, 400, seed=9)
    path = write_laz(tmp_path / "full.laz", las, 100)
    table = chunk_table(path)
    b = bytearray(path.read_bytes())
    # move the last half of chunk 1 elsewhere: fill it with zeros and keep
    # the table; the decoder must stop at the chunk's end, never read on
    start, nbytes, _ = table[1]
    b[start + nbytes // 2:start + nbytes] = bytes(nbytes - nbytes // 2)
    bad = tmp_path / "bad.laz"
    bad.write_bytes(bytes(b))
    r = decode(tool, bad)
    assert r.returncode == 3, r.stderr.decode()
    assert re.search(rb"chunk 1\b", r.stderr), r.stderr.decode()


def test_corrupt_chunks_never_crash(tool, tmp_path):
    las = build_las(3, 500, seed=11)
    path = write_laz(tmp_path / "full.laz", las, 60)
    table = chunk_table(path)
    good = path.read_bytes()
    rng = np.random.default_rng(12)
    failed = 0
    for i in range(40):
        b = bytearray(good)
        start, nbytes, _ = table[int(rng.integers(0, len(table)))]
        for _ in range(int(rng.integers(1, 6))):
            b[start + int(rng.integers(0, nbytes))] = int(rng.integers(0, 256))
        bad = tmp_path / f"bad{i}.laz"
        bad.write_bytes(bytes(b))
        r = decode(tool, bad)
        assert r.returncode in (0, 3), (i, r.returncode, r.stderr.decode())
        failed += r.returncode == 3
        bad.unlink()
    assert failed > 0


def patch_vlr(path, out, fn):
    b = bytearray(path.read_bytes())
    fn(b, laszip_vlr(b)[0])
    out.write_bytes(bytes(b))
    return out


@pytest.mark.parametrize("patch, code, words", [
    (lambda b, p: struct.pack_into("<H", b, p, 1), b"GDT-3901", b"re-compress"),
    (lambda b, p: struct.pack_into("<H", b, p, 5), b"GDT-3902", b"compressor 5"),
    (lambda b, p: struct.pack_into("<H", b, p + 2, 1), b"GDT-3903", b"coder 1"),
    (lambda b, p: struct.pack_into("<H", b, p + 34 + 4, 3), b"GDT-3908", b"POINT10"),
    (lambda b, p: struct.pack_into("<H", b, p + 34 + 6, 9), b"GDT-3907", b"GPSTIME11"),
    (lambda b, p: struct.pack_into("<H", b, p + 34 + 2, 21), b"GDT-3907", b"21 bytes"),
])
def test_bad_vlr(tool, tmp_path, patch, code, words):
    las = build_las(1, 50, seed=1)
    path = write_laz(tmp_path / "ok.laz", las, 10)
    bad = patch_vlr(path, tmp_path / "bad.laz", patch)
    r = decode(tool, bad)
    assert r.returncode == 3, r.stderr.decode()
    assert code in r.stderr and words in r.stderr, r.stderr.decode()
