"""LAS reader, through the gdt_dump tool, against laspy.

Points must be equal to laspy's record integers, and x/y/z must be exactly
X * scale + offset in float64; the output must not depend on the read-buffer
or chunk size; --info must match laspy's header.  Lying, truncated and
corrupt files must give exit 3 with a message naming the file, never a crash.
"""
import math
import shutil
import struct

import laspy
import numpy as np
import pytest
from conftest import DATA
from laspy.vlrs.vlrlist import VLRList

# Versions laspy writes, with the point formats each allows (1.0 is made from
# 1.1 by patching the minor version: the layouts are identical).
FORMATS_BY_VERSION = {
    "1.1": (0, 1),
    "1.2": (0, 1, 2, 3),
    "1.3": (0, 1, 2, 3, 4, 5),
    "1.4": tuple(range(11)),
}

# Header field offsets (LAS 1.0-1.4).
OFF_VERSION_MAJOR = 24
OFF_VERSION_MINOR = 25
OFF_HEADER_SIZE = 94
OFF_POINT_OFFSET = 96
OFF_VLR_COUNT = 100
OFF_FORMAT = 104
OFF_RECORD_LENGTH = 105
OFF_LEGACY_COUNT = 107
OFF_SCALE = 131
OFF_OFFSET = 155
OFF_EVLR_START = 235
OFF_EVLR_COUNT = 243
OFF_COUNT64 = 247

WKT_UTM10 = (
    'PROJCS["NAD83 / UTM zone 10N",GEOGCS["NAD83",DATUM["North_American_Datum_1983",'
    'SPHEROID["GRS 1980",6378137,298.257222101,AUTHORITY["EPSG","7019"]],'
    'AUTHORITY["EPSG","6269"]],PRIMEM["Greenwich",0],UNIT["degree",0.0174532925199433],'
    'AUTHORITY["EPSG","4269"]],PROJECTION["Transverse_Mercator"],'
    'PARAMETER["central_meridian",-123],UNIT["metre",1],AUTHORITY["EPSG","26910"]]'
)
WKT_LOCAL = 'PROJCS["Site grid",GEOGCS["NAD83"],UNIT["metre",1]]'
WKT_WGS84 = ('GEOGCS["WGS 84",DATUM["WGS_1984"],UNIT["degree",0.0174532925199433],'
             'AUTHORITY["EPSG","4326"]]')


# ---------------------------------------------------------------- helpers


@pytest.fixture(scope="session")
def dump(tool):
    return tool("gdt_dump")


def sample(data_dir, name):
    """The real sample name in the data folder; skips the test when it is absent."""
    path = data_dir / name
    if not path.exists():
        pytest.skip(f"{name} not in the data folder")
    return path


def run_dump(runner, exe, path, *args):
    return runner([exe, *args, path])


def parse_points(text):
    vals = np.array(text.split(), dtype=np.float64)
    assert vals.size % 6 == 0
    return vals.reshape(-1, 6)


def dump_points(runner, exe, path, *args):
    r = run_dump(runner, exe, path, *args)
    assert r.returncode == 0, f"gdt_dump failed on {path}: rc={r.returncode} {r.stderr}"
    return parse_points(r.stdout), r


def dump_info(runner, exe, path):
    r = run_dump(runner, exe, path, "--info")
    assert r.returncode == 0, f"gdt_dump --info failed on {path}: {r.stderr}"
    info = {}
    for line in r.stdout.splitlines():
        key, _, value = line.partition("=")
        info[key] = value
    return info, r


def expected_points(las):
    """Record integers and X * scale + offset in float64, from laspy."""
    h = las.header
    ints = [np.asarray(las.X, dtype=np.int64), np.asarray(las.Y, dtype=np.int64),
            np.asarray(las.Z, dtype=np.int64)]
    coords = [ints[k].astype(np.float64) * np.float64(h.scales[k]) + np.float64(h.offsets[k])
              for k in range(3)]
    return np.column_stack(ints), np.column_stack(coords)


def assert_points_equal(got, las, what):
    ints, coords = expected_points(las)
    assert got.shape[0] == ints.shape[0], f"{what}: {got.shape[0]} points, laspy {ints.shape[0]}"
    got_ints = got[:, 3:6].astype(np.int64)
    assert np.array_equal(got_ints, ints), f"{what}: record integers differ"
    # Exact equality of doubles: %.17g round-trips.
    bad = np.nonzero(got[:, 0:3] != coords)
    assert bad[0].size == 0, f"{what}: first coordinate mismatch at point {bad[0][:1]}"


def assert_info_matches(info, las_or_header, path, vlrs=None):
    h = las_or_header
    assert info["format"] == "LAS"
    assert info["version"] == f"{h.version.major}.{h.version.minor}"
    assert int(info["point_count"]) == h.point_count
    assert int(info["point_format"]) == h.point_format.id
    assert info["encoding"] == f"point format {h.point_format.id}"
    assert int(info["record_length"]) == h.point_format.size
    assert int(info["extra_bytes"]) == h.point_format.num_extra_bytes
    scale = [float(v) for v in info["scale"].split()]
    offset = [float(v) for v in info["offset"].split()]
    bounds = [float(v) for v in info["bounds"].split()]
    assert scale == [float(v) for v in h.scales], path
    assert offset == [float(v) for v in h.offsets], path
    assert bounds == [float(v) for v in h.mins] + [float(v) for v in h.maxs], path
    assert int(info["vlrs"]) == (len(h.vlrs) if vlrs is None else vlrs)
    assert int(info["evlrs"]) == len(h.evlrs or [])


def assert_bad_input(r, path, code_prefix="GDT-3"):
    assert r.returncode == 3, (
        f"expected exit 3 for {path}, got {r.returncode}\nstderr: {r.stderr[-2000:]}")
    assert str(path) in r.stderr, f"message does not name the file: {r.stderr}"
    assert code_prefix in r.stderr, f"expected {code_prefix} in: {r.stderr}"
    assert "AddressSanitizer" not in r.stderr and "runtime error" not in r.stderr


def geokey_vlr(keys, ascii_params=None):
    words = [1, 1, 0, len(keys)]
    for k in keys:
        words.extend(k)
    vlrs = [laspy.VLR("LASF_Projection", 34735, "GeoKeyDirectoryTag",
                      struct.pack(f"<{len(words)}H", *words))]
    if ascii_params is not None:
        vlrs.append(laspy.VLR("LASF_Projection", 34737, "GeoAsciiParamsTag",
                              ascii_params.encode() + b"\0"))
    return vlrs


def make_las(path, version, fmt, rng, n=200, scales=(0.01, 0.01, 0.01),
             offsets=(0.0, 0.0, 0.0), extra=False, vlrs=(), evlrs=(), wkt_bit=False):
    """Writes a LAS file with laspy; returns the path.  Record integers are
    seeded random values over the whole int32 range, plus its ends, 0 and -1."""
    hdr = laspy.LasHeader(version=version, point_format=fmt)
    if extra:
        hdr.add_extra_dims([laspy.ExtraBytesParams("amplitude", "u2"),
                            laspy.ExtraBytesParams("normal", "3f8"),
                            laspy.ExtraBytesParams("flag", "u1")])
    hdr.scales = np.array(scales, dtype=np.float64)
    hdr.offsets = np.array(offsets, dtype=np.float64)
    las = laspy.LasData(hdr)
    cols = []
    for _ in range(3):
        c = rng.integers(-2**31, 2**31, size=n, dtype=np.int64)
        if n >= 4:
            c[:4] = [-2**31, 2**31 - 1, 0, -1]
        cols.append(c.astype(np.int32))
    las.X, las.Y, las.Z = cols
    if extra:
        las.amplitude = rng.integers(0, 2**16, size=n, dtype=np.int64).astype(np.uint16)
        las.normal = rng.normal(size=(n, 3))
        las.flag = rng.integers(0, 256, size=n, dtype=np.int64).astype(np.uint8)
    if fmt in (1, 3, 4, 5, 6, 7, 8, 9, 10):
        las.gps_time = rng.uniform(0, 1e6, size=n)
    for v in vlrs:
        las.header.vlrs.append(v)
    if evlrs:
        las.evlrs = VLRList(list(evlrs))
    if wkt_bit:
        las.header.global_encoding.wkt = True
    las.write(str(path))
    return path


def patch(path, offset, fmt, *values):
    data = bytearray(path.read_bytes())
    struct.pack_into(fmt, data, offset, *values)
    path.write_bytes(bytes(data))


def read_u(path, offset, fmt):
    return struct.unpack_from(fmt, path.read_bytes(), offset)[0]


def real_las_files(data_dir):
    files = sorted(p for p in data_dir.glob("*.las") if p.name != "garbage_nVariableLength.las")
    if not files:
        pytest.skip(f"no LAS samples in {data_dir}")
    return files


# ---------------------------------------------------------------- real data


def test_real_files_equal_laspy(dump, runner, data_dir):
    for path in real_las_files(data_dir):
        got, _ = dump_points(runner, dump, path)
        assert_points_equal(got, laspy.read(str(path)), path.name)


def test_real_files_info_matches_laspy(dump, runner, data_dir):
    for path in real_las_files(data_dir):
        info, _ = dump_info(runner, dump, path)
        with laspy.open(str(path)) as reader:
            h = reader.header
        # laspy takes the bytes after the last VLR of bad_vlr_count.las for a
        # third VLR; the reader stops at the point data (checked below).
        vlrs = 2 if path.name == "bad_vlr_count.las" else None
        assert_info_matches(info, h, path, vlrs=vlrs)


def test_real_files_crs(dump, runner, data_dir):
    for name in ("epsg_4326.las", "test_epsg_4326.las"):
        path = data_dir / name
        if not path.exists():
            continue
        info, _ = dump_info(runner, dump, path)
        assert info["epsg"] == "4326" and info["geographic"] == "1", (name, info)
        assert info["crs"] == "EPSG:4326"
    path = data_dir / "autzen_trim.las"
    if path.exists():
        info, _ = dump_info(runner, dump, path)
        with laspy.open(str(path)) as reader:
            wkt = next(v for v in reader.header.vlrs
                       if v.user_id == "LASF_Projection" and v.record_id == 2112).string
        name = wkt.split('"')[1]
        assert info["geographic"] == "0"
        assert info["crs"] == f"WKT: {name}"


def test_real_files_tiny_buffers(dump, runner, data_dir):
    small = [p for p in real_las_files(data_dir) if p.stat().st_size < 200_000]
    for path in small:
        ref = run_dump(runner, dump, path)
        assert ref.returncode == 0, ref.stderr
        for buf in (1, 7, 64):
            for chunk in (1, 3):
                r = run_dump(runner, dump, path, "--buffer-bytes", buf, "--chunk", chunk)
                assert r.returncode == 0, r.stderr
                assert r.stdout == ref.stdout, f"{path.name}: buffer {buf} chunk {chunk} differs"
    big = data_dir / "autzen_trim.las"
    if big.exists():
        ref = run_dump(runner, dump, big)
        r = run_dump(runner, dump, big, "--buffer-bytes", 64, "--chunk", 3)
        assert r.returncode == 0 and r.stdout == ref.stdout


@pytest.mark.sanitize
def test_bad_vlr_count_recovers_with_warning(dump, runner, data_dir):
    path = sample(data_dir, "bad_vlr_count.las")
    got, r = dump_points(runner, dump, path)
    assert "warning GDT-3150" in r.stderr and path.name in r.stderr
    assert_points_equal(got, laspy.read(str(path)), path.name)


@pytest.mark.sanitize
def test_garbage_vlr_count_fails_cleanly(dump, runner, data_dir):
    path = sample(data_dir, "garbage_nVariableLength.las")
    for args in ((), ("--info",)):
        r = run_dump(runner, dump, path, *args)
        assert_bad_input(r, path, "GDT-31")


@pytest.mark.sanitize
def test_gps_time_nan_reads(dump, runner, data_dir):
    path = sample(data_dir, "gps-time-nan.las")
    got, _ = dump_points(runner, dump, path)
    assert_points_equal(got, laspy.read(str(path)), path.name)


# ---------------------------------------------------------------- generated


SCALE_CASES = [
    ((0.01, 0.01, 0.01), (0.0, 0.0, 0.0)),
    ((0.0001, 0.0001, 0.001), (1e6, -1e6, 100.0)),
    ((1e-7, 1e-7, 1e-7), (-123.456789, 45.0, 0.0)),
    ((0.25, 3.0, 0.1), (123456.789, 9.87654321e6, -400.5)),
]


def generated_cases():
    cases = []
    k = 0
    for version, formats in FORMATS_BY_VERSION.items():
        for fmt in formats:
            scales, offsets = SCALE_CASES[k % len(SCALE_CASES)]
            cases.append((version, fmt, scales, offsets, k % 2 == 0))
            k += 1
    return cases


def check_generated(runner, dump, tmp_path, version, fmt, scales, offsets, extra, tiny):
    rng = np.random.default_rng(1000 + 17 * fmt + int(version[-1]))
    evlrs = ()
    if version == "1.4":
        evlrs = (laspy.VLR("gdt_test", 7, "opaque", rng.bytes(123)),
                 laspy.VLR("gdt_test", 8, "empty", b""))
    path = make_las(tmp_path / "g.las", version, fmt, rng, n=157, scales=scales,
                    offsets=offsets, extra=extra, evlrs=evlrs)
    las = laspy.read(str(path))
    got, ref = dump_points(runner, dump, path)
    assert_points_equal(got, las, f"{version} format {fmt}")
    info, _ = dump_info(runner, dump, path)
    assert_info_matches(info, las.header, path)
    if extra:
        assert int(info["extra_bytes"]) == 27  # u2 + 3 x f8 + u1
    for buf, chunk in tiny:
        r = run_dump(runner, dump, path, "--buffer-bytes", buf, "--chunk", chunk)
        assert r.returncode == 0 and r.stdout == ref.stdout, (buf, chunk, r.stderr)


@pytest.mark.parametrize("version,fmt,scales,offsets,extra", generated_cases())
def test_generated_equal_laspy(dump, runner, tmp_path, version, fmt, scales, offsets, extra):
    check_generated(runner, dump, tmp_path, version, fmt, scales, offsets, extra,
                    tiny=((1, 1), (7, 3), (64, 1)))


@pytest.mark.sanitize
@pytest.mark.parametrize("version,fmt,scales,offsets,extra",
                         [c for c in generated_cases()
                          if (c[0], c[1]) in {("1.1", 0), ("1.2", 3), ("1.3", 4), ("1.3", 5),
                                              ("1.4", 6), ("1.4", 10)}])
def test_generated_sanitized(dump, runner, tmp_path, version, fmt, scales, offsets, extra):
    """A few of the generated cases, with fewer runs, for the sanitizer build."""
    check_generated(runner, dump, tmp_path, version, fmt, scales, offsets, extra,
                    tiny=((7, 3),))


@pytest.mark.sanitize
@pytest.mark.parametrize("fmt", [0, 1])
def test_version_1_0(dump, runner, tmp_path, fmt):
    rng = np.random.default_rng(77 + fmt)
    path = make_las(tmp_path / "v10.las", "1.1", fmt, rng, n=64, scales=(0.001, 0.001, 0.01),
                    offsets=(5e5, 4e6, 0.0))
    las = laspy.read(str(path))
    patch(path, OFF_VERSION_MINOR, "<B", 0)
    got, _ = dump_points(runner, dump, path)
    assert_points_equal(got, las, "LAS 1.0")
    info, _ = dump_info(runner, dump, path)
    assert info["version"] == "1.0"


@pytest.mark.sanitize
def test_empty_point_set(dump, runner, tmp_path):
    rng = np.random.default_rng(5)
    path = make_las(tmp_path / "empty.las", "1.4", 6, rng, n=0)
    got, _ = dump_points(runner, dump, path)
    assert got.shape[0] == 0
    info, _ = dump_info(runner, dump, path)
    assert info["point_count"] == "0"


@pytest.mark.sanitize
def test_crs_from_vlrs_and_evlrs(dump, runner, tmp_path):
    rng = np.random.default_rng(11)
    cases = [
        # (version, vlrs, evlrs, wkt bit, epsg, geographic, desc)
        ("1.2", geokey_vlr([(1024, 0, 1, 1), (3072, 0, 1, 32617)]), (), False,
         "32617", "0", "EPSG:32617"),
        ("1.2", geokey_vlr([(1024, 0, 1, 2), (2048, 0, 1, 4326)]), (), False,
         "4326", "1", "EPSG:4326"),
        ("1.2", geokey_vlr([(1024, 0, 1, 1), (3072, 0, 1, 32767), (3073, 34737, 11, 0)],
                           "Local grid|"), (), False, "0", "0", "GeoTIFF: Local grid"),
        ("1.2", [laspy.VLR("LASF_Projection", 2112, "WKT", WKT_UTM10.encode() + b"\0")], (),
         False, "26910", "0", "EPSG:26910"),
        ("1.3", [laspy.VLR("LASF_Projection", 2112, "WKT", WKT_LOCAL.encode())], (), False,
         "0", "0", "WKT: Site grid"),
        ("1.4", [], [laspy.VLR("LASF_Projection", 2112, "WKT", WKT_WGS84.encode() + b"\0")],
         True, "4326", "1", "EPSG:4326"),
        ("1.4", [laspy.VLR("LASF_Projection", 2112, "WKT", WKT_UTM10.encode())], [], True,
         "26910", "0", "EPSG:26910"),
        ("1.4", [], [], False, "0", "0", "unknown"),
    ]
    for i, (version, vlrs, evlrs, bit, epsg, geographic, desc) in enumerate(cases):
        path = make_las(tmp_path / f"crs{i}.las", version, 6 if version == "1.4" else 1, rng,
                        n=20, vlrs=vlrs, evlrs=evlrs, wkt_bit=bit)
        info, _ = dump_info(runner, dump, path)
        assert (info["epsg"], info["geographic"], info["crs"]) == (epsg, geographic, desc), i
        got, _ = dump_points(runner, dump, path)
        assert_points_equal(got, laspy.read(str(path)), f"crs case {i}")


# ---------------------------------------------------------------- bad input


def base_file(tmp_path, name="base.las", version="1.2", fmt=3, n=50, evlrs=False,
              wkt=WKT_UTM10):
    """A valid file with GeoTIFF keys, a WKT VLR, extra bytes and, for 1.4,
    EVLRs: the starting point of the lying-header and truncation tests."""
    rng = np.random.default_rng(4242)
    vlrs = geokey_vlr([(1024, 0, 1, 1), (3072, 0, 1, 26910), (3073, 34737, 21, 0)],
                      "NAD83 / UTM zone 10N|")
    vlrs.append(laspy.VLR("LASF_Projection", 2112, "WKT", wkt.encode() + b"\0"))
    ev = ()
    if evlrs:
        ev = (laspy.VLR("gdt_test", 1, "payload", rng.bytes(90)),
              laspy.VLR("LASF_Projection", 2112, "WKT", wkt.encode()))
    return make_las(tmp_path / name, version, fmt, rng, n=n, vlrs=vlrs, evlrs=ev, extra=True)


def lying_cases(path):
    """Patches that make the header lie: (label, offset, struct format,
    value(s)..., expected message number)."""
    count = read_u(path, OFF_LEGACY_COUNT, "<I")
    reclen = read_u(path, OFF_RECORD_LENGTH, "<H")
    at = read_u(path, OFF_POINT_OFFSET, "<I")
    size = path.stat().st_size
    return [
        ("count +1", OFF_LEGACY_COUNT, "<I", count + 1, "GDT-3118"),
        ("count -1", OFF_LEGACY_COUNT, "<I", count - 1, "GDT-3119"),
        ("count huge", OFF_LEGACY_COUNT, "<I", 0xFFFFFFFF, "GDT-3118"),
        ("record length +1", OFF_RECORD_LENGTH, "<H", reclen + 1, "GDT-3118"),
        ("record length -3", OFF_RECORD_LENGTH, "<H", reclen - 3, "GDT-3119"),
        ("record length below format", OFF_RECORD_LENGTH, "<H", 33, "GDT-3111"),
        ("offset to points +1", OFF_POINT_OFFSET, "<I", at + 1, "GDT-3118"),
        ("offset to points -1", OFF_POINT_OFFSET, "<I", at - 1, "GDT-3120"),
        ("offset to points in header", OFF_POINT_OFFSET, "<I", 100, "GDT-3115"),
        ("offset to points past end", OFF_POINT_OFFSET, "<I", size + 10, "GDT-3116"),
        ("bad signature", 0, "<4s", b"LASX", "GDT-3"),
        ("version 2.0", OFF_VERSION_MAJOR, "<BB", 2, 0, "GDT-3106"),
        ("version 1.5", OFF_VERSION_MAJOR, "<BB", 1, 5, "GDT-3106"),
        ("format 11", OFF_FORMAT, "<B", 11, "GDT-3110"),
        ("format 63", OFF_FORMAT, "<B", 63, "GDT-3110"),
        ("LAZ bit", OFF_FORMAT, "<B", 3 | 0x80, "GDT-3974"),
        ("LAZ bit 6", OFF_FORMAT, "<B", 3 | 0x40, "GDT-3974"),
        ("VLR count huge", OFF_VLR_COUNT, "<I", 10**9, "GDT-3122"),
        ("VLR count max", OFF_VLR_COUNT, "<I", 0xFFFFFFFF, "GDT-3122"),
        ("NaN scale x", OFF_SCALE, "<d", math.nan, "GDT-3112"),
        ("zero scale z", OFF_SCALE + 16, "<d", 0.0, "GDT-3112"),
        ("infinite scale y", OFF_SCALE + 8, "<d", math.inf, "GDT-3112"),
        ("NaN offset y", OFF_OFFSET + 8, "<d", math.nan, "GDT-3113"),
        ("infinite offset z", OFF_OFFSET + 16, "<d", -math.inf, "GDT-3113"),
        ("header size small", OFF_HEADER_SIZE, "<H", 200, "GDT-3107"),
        ("header size past end", OFF_HEADER_SIZE, "<H", 65535, "GDT-3108"),
    ]


@pytest.mark.sanitize
def test_lying_headers(dump, runner, tmp_path):
    good = base_file(tmp_path)
    assert run_dump(runner, dump, good).returncode == 0
    bad = tmp_path / "bad.las"
    for label, offset, fmt, *values, code in lying_cases(good):
        shutil.copyfile(good, bad)
        patch(bad, offset, fmt, *values)
        r = run_dump(runner, dump, bad)
        try:
            assert_bad_input(r, bad, code)
            if label.startswith("LAZ"):
                assert "no LASzip VLR" in r.stderr
        except AssertionError as e:
            raise AssertionError(f"{label}: {e}") from None


@pytest.mark.sanitize
def test_lying_headers_1_4(dump, runner, tmp_path):
    good = base_file(tmp_path, version="1.4", fmt=7, evlrs=True)
    assert run_dump(runner, dump, good).returncode == 0
    count = read_u(good, OFF_COUNT64, "<Q")
    ev_at = read_u(good, OFF_EVLR_START, "<Q")
    size = good.stat().st_size
    cases = [
        ("count64 +1", OFF_COUNT64, "<Q", count + 1, "GDT-3118"),
        ("count64 -1", OFF_COUNT64, "<Q", count - 1, "GDT-3119"),
        ("count64 huge", OFF_COUNT64, "<Q", 2**64 - 1, "GDT-3118"),
        ("legacy count disagrees", OFF_LEGACY_COUNT, "<I", count + 5, "GDT-3114"),
        ("EVLR start past end", OFF_EVLR_START, "<Q", size + 1, "GDT-3117"),
        ("EVLR start before points", OFF_EVLR_START, "<Q", 10, "GDT-3117"),
        ("EVLR start inside points", OFF_EVLR_START, "<Q", ev_at - 1, "GDT-3118"),
        ("EVLR count +1", OFF_EVLR_COUNT, "<I", 3, "GDT-3121"),
        ("EVLR count huge", OFF_EVLR_COUNT, "<I", 0xFFFFFFFF, "GDT-3121"),
        ("header size 1.4 too small", OFF_HEADER_SIZE, "<H", 235, "GDT-3107"),
    ]
    bad = tmp_path / "bad14.las"
    for label, offset, fmt, value, code in cases:
        shutil.copyfile(good, bad)
        patch(bad, offset, fmt, value)
        r = run_dump(runner, dump, bad)
        try:
            assert_bad_input(r, bad, code)
        except AssertionError as e:
            raise AssertionError(f"{label}: {e}") from None
    # A legacy count equal to the 64-bit one is fine.
    shutil.copyfile(good, bad)
    patch(bad, OFF_LEGACY_COUNT, "<I", count)
    got, _ = dump_points(runner, dump, bad)
    assert_points_equal(got, laspy.read(str(good)), "legacy count = 64-bit count")


@pytest.mark.sanitize
def test_vlr_count_one_too_many_recovers(dump, runner, tmp_path):
    good = base_file(tmp_path)
    bad = tmp_path / "vlr_plus_one.las"
    shutil.copyfile(good, bad)
    patch(bad, OFF_VLR_COUNT, "<I", read_u(good, OFF_VLR_COUNT, "<I") + 1)
    got, r = dump_points(runner, dump, bad)
    assert "warning GDT-3150" in r.stderr and str(bad) in r.stderr
    assert_points_equal(got, laspy.read(str(good)), "VLR count + 1")


# ---------------------------------------------------------------- truncation


def layout(data):
    """Structure of a valid LAS file's bytes: the header, VLR and EVLR edges
    (each record's start, end of its header, end) and the point region."""
    header_size = struct.unpack_from("<H", data, OFF_HEADER_SIZE)[0]
    points_at = struct.unpack_from("<I", data, OFF_POINT_OFFSET)[0]
    reclen = struct.unpack_from("<H", data, OFF_RECORD_LENGTH)[0]
    count = struct.unpack_from("<I", data, OFF_LEGACY_COUNT)[0]
    edges = [0, 4, 26, header_size - 1, header_size, points_at]
    pos = header_size
    for _ in range(struct.unpack_from("<I", data, OFF_VLR_COUNT)[0]):
        if pos + 54 > points_at:
            break
        edges += [pos + 1, pos + 53, pos + 54]
        pos += 54 + struct.unpack_from("<H", data, pos + 20)[0]
        edges += [pos - 1, pos]
    evlr_at = evlr_n = 0
    if data[OFF_VERSION_MINOR] >= 4:
        count = struct.unpack_from("<Q", data, OFF_COUNT64)[0] or count
        evlr_at = struct.unpack_from("<Q", data, OFF_EVLR_START)[0]
        evlr_n = struct.unpack_from("<I", data, OFF_EVLR_COUNT)[0]
    points_end = points_at + count * reclen
    edges += [points_at + k * reclen + d for k in sorted({1, 2, count // 2, count - 1})
              if 0 < k < count for d in (-1, 0, 1)]
    pos = evlr_at
    for _ in range(evlr_n):
        edges += [pos, pos + 1, pos + 59, pos + 60]
        pos += 60 + struct.unpack_from("<Q", data, pos + 20)[0]
        edges += [pos - 1]
    return points_at, points_end, sorted({e for e in edges if 0 <= e < len(data)})


def truncation_sizes(data, meta_stride, point_stride):
    """Sizes to cut a valid file at: every edge, every meta_stride-th byte of
    the header, VLRs and EVLRs, every point_stride-th byte of the points."""
    points_at, points_end, edges = layout(data)
    sizes = set(edges)
    sizes |= set(range(0, points_at + 1, meta_stride))
    sizes |= set(range(points_at, points_end, point_stride))
    sizes |= set(range(points_end, len(data), meta_stride))
    return sorted(s for s in sizes if s < len(data))


def check_truncations(runner, dump, data, sizes, cut):
    assert sizes and max(sizes) < len(data)
    for size in sizes:
        cut.write_bytes(data[:size])
        r = run_dump(runner, dump, cut)
        try:
            assert_bad_input(r, cut)
        except AssertionError as e:
            raise AssertionError(f"truncated at {size} of {len(data)}: {e}") from None


def truncation_sources(tmp_path, data_dir_or_none):
    """The files to cut: a generated LAS 1.4 file (GeoTIFF keys, WKT VLR, extra
    bytes, EVLRs), and a LAS 1.2 one: the real test_epsg_4326.las when present,
    else a generated one."""
    files = [base_file(tmp_path, name="t14.las", version="1.4", fmt=8, n=40, evlrs=True,
                       wkt=WKT_LOCAL)]
    real = None
    if data_dir_or_none is not None and (data_dir_or_none / "test_epsg_4326.las").exists():
        real = data_dir_or_none / "test_epsg_4326.las"
        files.append(real)
    if real is None:
        files.append(base_file(tmp_path, name="t12.las", version="1.2", fmt=3, n=40,
                               wkt=WKT_LOCAL))
    return files


@pytest.fixture
def maybe_data_dir():
    """The real-data folder, or None: these tests also run without it."""
    return DATA if DATA.is_dir() else None


def test_truncated_every_byte(dump, runner, tmp_path, maybe_data_dir):
    """Every byte through the header, VLRs and EVLRs; a spread through the points."""
    for src in truncation_sources(tmp_path, maybe_data_dir):
        data = src.read_bytes()
        check_truncations(runner, dump, data, truncation_sizes(data, 1, 13),
                          tmp_path / "cut.las")


@pytest.mark.sanitize
def test_truncated_sampled(dump, runner, tmp_path, maybe_data_dir):
    """The same cuts, sampled (every structure edge kept), for the sanitizer build."""
    for src in truncation_sources(tmp_path, maybe_data_dir):
        data = src.read_bytes()
        check_truncations(runner, dump, data, truncation_sizes(data, 83, 661),
                          tmp_path / "cut.las")
