"""PCD reader: the streaming reader (gdt_dump) against PCL's reader (pcd_dump_pcl).

Files are written by PCL itself (pcd_write_pcl, seeded) in every encoding,
coordinate type and name case; gdt_dump must print exactly the points PCL
reads, in the same order, whatever the read-buffer size.  Corrupt files must
give exit 3 with a numbered message naming the file, never a crash.
"""
import random
import re
import struct

import pytest

ENCODINGS = ["ascii", "binary", "binary_compressed"]
TOOLS = ["gdt_dump", "pcd_write_pcl", "pcd_dump_pcl"]


@pytest.fixture(scope="module")
def tools(tools_dir, tool):
    for t in TOOLS:
        tool(t)
    return tools_dir


def write_pcd(tools, runner, path, **opts):
    """Writes a cloud through PCL; returns the number of valid points written."""
    cmd = [tools / "pcd_write_pcl", "--out", path]
    for k, v in opts.items():
        flag = "--" + k.replace("_", "-")
        if v is True:
            cmd.append(flag)
        else:
            cmd += [flag, v]
    r = runner(cmd)
    assert r.returncode == 0, r.stderr
    return int(r.stdout)


def gdt_dump(tools, runner, path, *args):
    return runner([tools / "gdt_dump", *args, path])


def pcl_dump(tools, runner, path):
    r = runner([tools / "pcd_dump_pcl", path])
    assert r.returncode == 0, r.stderr
    return r.stdout


def assert_same_as_pcl(tools, runner, path, expect_points, *args):
    ours = gdt_dump(tools, runner, path, *args)
    assert ours.returncode == 0, ours.stderr
    ref = pcl_dump(tools, runner, path)
    assert ours.stdout.count("\n") == expect_points
    assert ours.stdout == ref
    return ours


def nan_warnings(stderr):
    return re.findall(r"warning GDT-3250: .*skipped (\d+) of (\d+) points", stderr)


def data_layout(blob):
    """(data offset, bytes per binary record, POINTS) of a PCD file's bytes."""
    head, sep, _ = blob.partition(b"\nDATA ")
    assert sep, "no DATA line"
    off = len(head) + len(sep) + blob[len(head) + len(sep):].index(b"\n") + 1
    keys = {}
    for line in head.decode().splitlines():
        parts = line.split()
        if parts and not parts[0].startswith("#"):
            keys[parts[0]] = parts[1:]
    sizes = [int(s) for s in keys["SIZE"]]
    counts = [int(c) for c in keys.get("COUNT", ["1"] * len(sizes))]
    return off, sum(s * c for s, c in zip(sizes, counts)), int(keys["POINTS"][0])


def exact_copy(blob, encoding):
    """The file without the zero padding PCL's writers append."""
    off, rec, n = data_layout(blob)
    if encoding == "binary":
        return blob[: off + rec * n]
    if encoding == "binary_compressed":
        csize = struct.unpack_from("<I", blob, off)[0]
        return blob[: off + 8 + csize]
    return blob


def assert_bad(r, path, code=None):
    """Exit 3 (bad input) with a numbered message naming the file; no crash."""
    assert r.returncode == 3, (r.returncode, r.stderr[-2000:])
    assert str(path) in r.stderr
    assert re.search(r"error GDT-3\d{3}", r.stderr), r.stderr
    if code is not None:
        assert f"GDT-{code}" in r.stderr, r.stderr
    assert "Sanitizer" not in r.stderr


# --------------------------------------------------------------------------
# PCL-written files read like PCL reads them


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("ctype", ["F4", "F8"])
@pytest.mark.parametrize("case", ["lower", "upper"])
@pytest.mark.parametrize("xyz_last", [False, True])
def test_matches_pcl(tools, runner, tmp_path, encoding, ctype, case, xyz_last):
    p = tmp_path / "c.pcd"
    opts = dict(encoding=encoding, type=ctype, case=case, extra="intensity,rgb,normal,label,gps",
                width="30", height="20", nan_frac="0.1", seed="11",
                origin="-5000,2000" if ctype == "F4" else "481000,4877000")
    if xyz_last:
        opts["xyz_last"] = True
    valid = write_pcd(tools, runner, p, **opts)
    assert 0 < valid < 600  # the organized cloud has invalid points
    ours = assert_same_as_pcl(tools, runner, p, valid)
    assert nan_warnings(ours.stderr) == [(str(600 - valid), "600")]
    info = gdt_dump(tools, runner, p, "--info")
    assert info.returncode == 0, info.stderr
    assert "format=PCD\n" in info.stdout and "version=0.7\n" in info.stdout
    assert f"encoding={encoding}\n" in info.stdout
    assert "point_count=600\n" in info.stdout
    assert "crs=unknown (PCD has no CRS)\n" in info.stdout


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("ctype", ["I1", "I2", "I4", "I8", "U1", "U2", "U4", "U8"])
def test_integer_coordinates(tools, runner, tmp_path, encoding, ctype):
    p = tmp_path / "i.pcd"
    span = "100" if ctype[1] == "1" else "20000"
    valid = write_pcd(tools, runner, p, encoding=encoding, type=ctype, extra="intensity",
                      width="200", span=span, seed="5")
    assert valid == 200
    assert_same_as_pcl(tools, runner, p, 200)


@pytest.mark.parametrize("encoding", ENCODINGS)
@pytest.mark.parametrize("typed", ["xyz", "xyzi", "xyzrgb"])
@pytest.mark.parametrize("via_cloud2", [False, True])
def test_typed_pcl_clouds(tools, runner, tmp_path, encoding, typed, via_cloud2):
    """Typed PCL clouds; through PCLPointCloud2 the binary files carry '_' padding."""
    p = tmp_path / "t.pcd"
    opts = dict(encoding=encoding, typed=typed, width="40", height="25", nan_frac="0.2",
                seed="3")
    if via_cloud2:
        opts["via_cloud2"] = True
    valid = write_pcd(tools, runner, p, **opts)
    assert_same_as_pcl(tools, runner, p, valid)
    if via_cloud2 and encoding == "binary":
        assert b"FIELDS x y z _" in p.read_bytes()


def test_nan_in_z_only(tools, runner, tmp_path):
    p = tmp_path / "z.pcd"
    valid = write_pcd(tools, runner, p, encoding="binary", type="F8", width="500",
                      nan_frac="0.3", nan_z_only=True, seed="8")
    ours = assert_same_as_pcl(tools, runner, p, valid)
    assert nan_warnings(ours.stderr) == [(str(500 - valid), "500")]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_all_invalid_is_empty_not_error(tools, runner, tmp_path, encoding):
    p = tmp_path / "n.pcd"
    valid = write_pcd(tools, runner, p, encoding=encoding, type="F4", width="20",
                      height="10", nan_frac="1.0")
    assert valid == 0
    r = gdt_dump(tools, runner, p)
    assert r.returncode == 0 and r.stdout == ""
    assert nan_warnings(r.stderr) == [("200", "200")]


def test_encodings_agree(tools, runner, tmp_path):
    """Same seed: binary, compressed and full-precision ascii give the same points."""
    outs = []
    for enc in ENCODINGS:
        p = tmp_path / f"{enc}.pcd"
        write_pcd(tools, runner, p, encoding=enc, type="F8", extra="gps,normal",
                  width="700", origin="637000,851000", precision="17", seed="21")
        r = gdt_dump(tools, runner, p)
        assert r.returncode == 0, r.stderr
        outs.append(r.stdout)
    assert outs[0].count("\n") == 700
    assert outs[0] == outs[1] == outs[2]


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_tiny_buffers_identical(tools, runner, tmp_path, encoding):
    p = tmp_path / "b.pcd"
    valid = write_pcd(tools, runner, p, encoding=encoding, type="F8",
                      extra="intensity,normal,gps", width="300", height="3", nan_frac="0.05",
                      seed="9")
    ref = assert_same_as_pcl(tools, runner, p, valid).stdout
    for buf in ["1", "2", "3", "7", "13", "64", "4096"]:
        for chunk in ["1", "5"]:
            r = gdt_dump(tools, runner, p, "--buffer-bytes", buf, "--chunk", chunk)
            assert r.returncode == 0, r.stderr
            assert r.stdout == ref, (buf, chunk)
            assert len(nan_warnings(r.stderr)) == 1


def test_f4_precision_warning(tools, runner, tmp_path):
    far = tmp_path / "far.pcd"
    near = tmp_path / "near.pcd"
    far8 = tmp_path / "far8.pcd"
    write_pcd(tools, runner, far, encoding="binary", type="F4", width="100",
              origin="500000,4000000")
    write_pcd(tools, runner, near, encoding="binary", type="F4", width="100",
              origin="-15000,-15000", span="30000")
    write_pcd(tools, runner, far8, encoding="binary", type="F8", width="100",
              origin="500000,4000000")
    r = gdt_dump(tools, runner, far)
    assert r.returncode == 0 and r.stderr.count("GDT-3251") == 1, r.stderr
    for p in (near, far8):
        r = gdt_dump(tools, runner, p)
        assert r.returncode == 0 and "GDT-3251" not in r.stderr, r.stderr


def test_autzen_equals_pcl(tools, runner, data_dir):
    p = data_dir / "autzen-utm.pcd"
    ours = assert_same_as_pcl(tools, runner, p, 1065)
    assert ours.stderr == ""
    for buf in ["1", "51", "52", "53", "1000"]:
        r = gdt_dump(tools, runner, p, "--buffer-bytes", buf, "--chunk", "7")
        assert r.returncode == 0 and r.stdout == ours.stdout
    info = gdt_dump(tools, runner, p, "--info").stdout
    assert "encoding=binary\n" in info and "point_count=1065\n" in info
    assert "version=0.7\n" in info and "record_length=52\n" in info
    # UTM coordinates in F8: Autzen stadium lies near 494 km E, 4877 km N.
    first = [float(v) for v in ours.stdout.split("\n", 1)[0].split()[:3]]
    assert 490000 < first[0] < 500000 and 4870000 < first[1] < 4880000


# --------------------------------------------------------------------------
# hand-written headers: old versions, comments, CRLF, empty clouds

BASE = (
    "# .PCD v0.7 - hand written\n"
    "VERSION 0.7\n"
    "FIELDS x y z intensity\n"
    "SIZE 4 4 4 4\n"
    "TYPE F F F F\n"
    "COUNT 1 1 1 1\n"
    "WIDTH 3\n"
    "HEIGHT 1\n"
    "VIEWPOINT 0 0 0 1 0 0 0\n"
    "POINTS 3\n"
    "DATA ascii\n"
    "1.5 2.25 3 4\n"
    "5 6 7.125 8\n"
    "-9 10 11 12\n"
)
BASE_POINTS = [(1.5, 2.25, 3.0), (5.0, 6.0, 7.125), (-9.0, 10.0, 11.0)]


def points_of(stdout):
    return [tuple(float(v) for v in line.split()[:3]) for line in stdout.splitlines()]


@pytest.mark.parametrize("variant", ["base", "crlf", "comments", "v05_columns", "no_version",
                                     "v06", "tabs_empty_lines", "blank_lines"])
def test_hand_written_headers(tools, runner, tmp_path, variant):
    text = BASE
    if variant == "crlf":
        text = text.replace("\n", "\r\n")
    elif variant == "comments":
        text = text.replace("WIDTH", "# a comment\n   # indented one\nWIDTH")
    elif variant == "v05_columns":  # 0.5: COLUMNS, no SIZE/TYPE/COUNT/HEIGHT/VIEWPOINT/POINTS
        text = re.sub(r"(SIZE|TYPE|COUNT|HEIGHT|VIEWPOINT|POINTS)[^\n]*\n", "", text)
        text = text.replace("VERSION 0.7", "VERSION .5").replace("FIELDS", "COLUMNS")
    elif variant == "no_version":
        text = text.replace("VERSION 0.7\n", "")
    elif variant == "v06":
        text = text.replace("VERSION 0.7", "VERSION 0.6").replace("VIEWPOINT 0 0 0 1 0 0 0\n", "")
    elif variant == "tabs_empty_lines":
        text = text.replace("5 6 7.125 8\n", "\n\n5\t6 7.125\t 8  \n\n")
    elif variant == "blank_lines":
        text = text.replace("5 6 7.125 8\n", " \t\n5 6 7.125 8\n  \n")
    p = tmp_path / "h.pcd"
    p.write_bytes(text.encode())
    r = gdt_dump(tools, runner, p)
    assert r.returncode == 0, r.stderr
    assert points_of(r.stdout) == BASE_POINTS
    # PCL needs POINTS, which 0.5 files may omit; it reads a line of blanks
    # as a point of zeros, where this reader skips it like an empty line.
    if variant not in ("v05_columns", "blank_lines"):
        assert r.stdout == pcl_dump(tools, runner, p)
    info = gdt_dump(tools, runner, p, "--info").stdout
    expect_version = {"v05_columns": "0.5", "no_version": "none", "v06": "0.6"}.get(variant, "0.7")
    assert f"version={expect_version}\n" in info


@pytest.mark.parametrize("encoding", ENCODINGS)
def test_empty_cloud(tools, runner, tmp_path, encoding):
    text = BASE.split("DATA")[0].replace("WIDTH 3", "WIDTH 0").replace("POINTS 3", "POINTS 0")
    blob = (text + f"DATA {encoding}\n").encode()
    if encoding == "binary_compressed":
        blob += struct.pack("<II", 0, 0)
    p = tmp_path / "e.pcd"
    p.write_bytes(blob)
    r = gdt_dump(tools, runner, p)
    assert r.returncode == 0 and r.stdout == "", r.stderr
    assert "point_count=0\n" in gdt_dump(tools, runner, p, "--info").stdout


# --------------------------------------------------------------------------
# bad input: exit 3, numbered message naming the file, never a crash

BAD_HEADERS = [
    ("missing_fields", lambda t: re.sub(r"FIELDS[^\n]*\n", "", t), 3209),
    ("missing_points", lambda t: re.sub(r"POINTS[^\n]*\n", "", t), 3206),
    ("missing_size", lambda t: re.sub(r"SIZE[^\n]*\n", "", t), 3206),
    ("missing_data", lambda t: t.split("DATA")[0], 3203),
    ("duplicate_width", lambda t: t.replace("HEIGHT 1", "WIDTH 3\nHEIGHT 1"), 3205),
    ("duplicate_fields", lambda t: t.replace("SIZE", "FIELDS x y z i\nSIZE"), 3205),
    ("size_short", lambda t: t.replace("SIZE 4 4 4 4", "SIZE 4 4 4"), 3209),
    ("type_long", lambda t: t.replace("TYPE F F F F", "TYPE F F F F F"), 3209),
    ("count_short", lambda t: t.replace("COUNT 1 1 1 1", "COUNT 1 1"), 3209),
    ("size_before_fields", lambda t: t.replace("FIELDS x y z intensity\nSIZE 4 4 4 4",
                                               "SIZE 4 4 4 4\nFIELDS x y z intensity"), 3209),
    ("no_z", lambda t: t.replace("FIELDS x y z", "FIELDS x y w"), 3216),
    ("two_x", lambda t: t.replace("FIELDS x y z intensity", "FIELDS x y z X"), 3216),
    ("x_count_2", lambda t: t.replace("COUNT 1 1 1 1", "COUNT 2 1 1 1"), 3216),
    ("size_3", lambda t: t.replace("SIZE 4 4 4 4", "SIZE 4 3 4 4"), 3210),
    ("float_size_2", lambda t: t.replace("SIZE 4 4 4 4", "SIZE 4 4 2 4"), 3210),
    ("type_letter", lambda t: t.replace("TYPE F F F F", "TYPE F F Q F"), 3210),
    ("count_zero", lambda t: t.replace("COUNT 1 1 1 1", "COUNT 1 1 1 0"), 3211),
    ("count_huge", lambda t: t.replace("COUNT 1 1 1 1", "COUNT 1 1 1 99999999999"), 3211),
    ("width_negative", lambda t: t.replace("WIDTH 3", "WIDTH -3"), 3212),
    ("points_text", lambda t: t.replace("POINTS 3", "POINTS three"), 3212),
    ("points_mismatch", lambda t: t.replace("POINTS 3", "POINTS 4"), 3213),
    ("width_height_overflow", lambda t: t.replace("WIDTH 3", "WIDTH 4294967296").replace(
        "HEIGHT 1", "HEIGHT 4294967296"), 3213),
    ("viewpoint_short", lambda t: t.replace("VIEWPOINT 0 0 0 1 0 0 0", "VIEWPOINT 0 0 0"), 3214),
    ("viewpoint_text", lambda t: t.replace("VIEWPOINT 0 0 0 1", "VIEWPOINT 0 0 0 one"), 3214),
    ("data_unknown", lambda t: t.replace("DATA ascii", "DATA zipped"), 3215),
    ("version_unknown", lambda t: t.replace("VERSION 0.7", "VERSION 0.9"), 3207),
    ("unknown_key", lambda t: t.replace("HEIGHT 1", "HEIGHT 1\nCOLOUR red"), 3204),
    ("garbage_key", lambda t: t.replace("HEIGHT 1", "HEIGHT 1\n\x01\x7f\xfe\x80 junk"), 3204),
    ("nul_in_header", lambda t: t.replace("HEIGHT 1", "HEIGHT\x001"), 3202),
    ("huge_header_line", lambda t: t.replace("FIELDS", "#" + "x" * 300000 + "\nFIELDS"), 3202),
    ("huge_points", lambda t: t.replace("WIDTH 3", "WIDTH 9000000000000000000").replace(
        "POINTS 3", "POINTS 9000000000000000000"), 3212),
    ("ascii_short_line", lambda t: t.replace("5 6 7.125 8", "5 6 7.125"), 3240),
    ("ascii_long_line", lambda t: t.replace("5 6 7.125 8", "5 6 7.125 8 9"), 3240),
    ("ascii_bad_number", lambda t: t.replace("7.125", "7.1.25"), 3241),
    ("ascii_bad_extra_field", lambda t: t.replace(" 8\n", " eight\n"), 3241),
    ("ascii_long_token", lambda t: t.replace("7.125", "7" * 200), 3241),
    ("ascii_missing_line", lambda t: t.replace("-9 10 11 12\n", ""), 3242),
    ("ascii_extra_line", lambda t: t + "1 2 3 4\n", 3243),
    ("ascii_int_range", lambda t: t.replace("TYPE F F F F", "TYPE F F I F").replace(
        "SIZE 4 4 4 4", "SIZE 4 4 1 4").replace("7.125", "300"), 3241),
    ("ascii_int_fraction", lambda t: t.replace("TYPE F F F F", "TYPE F F I F").replace(
        "7.125", "7.5"), 3241),
]


@pytest.mark.sanitize
@pytest.mark.parametrize("name,edit,code", BAD_HEADERS, ids=[b[0] for b in BAD_HEADERS])
def test_bad_header(tools, runner, tmp_path, name, edit, code):
    p = tmp_path / f"{name}.pcd"
    p.write_bytes(edit(BASE).encode("latin-1"))
    assert_bad(gdt_dump(tools, runner, p), p, code)


@pytest.mark.sanitize
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_truncated_everywhere(tools, runner, tmp_path, encoding):
    src = tmp_path / "full.pcd"
    write_pcd(tools, runner, src, encoding=encoding, type="F8", extra="intensity,normal",
              width="120", seed="4")
    blob = exact_copy(src.read_bytes(), encoding)
    exact = tmp_path / "exact.pcd"
    exact.write_bytes(blob)
    good = gdt_dump(tools, runner, exact)
    assert good.returncode == 0 and good.stdout == pcl_dump(tools, runner, src)
    # ascii: a cut inside the last line's last number still looks complete
    end = blob.rstrip(b"\n").rindex(b"\n") if encoding == "ascii" else len(blob)
    rng = random.Random(77)
    offsets = sorted(set([0, 1, 5, 20, end - 1] + [rng.randrange(end) for _ in range(25)]))
    cut = tmp_path / "cut.pcd"
    for off in offsets:
        cut.write_bytes(blob[:off])
        assert_bad(gdt_dump(tools, runner, cut, "--buffer-bytes", "17"), cut)


@pytest.mark.sanitize
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_lying_points(tools, runner, tmp_path, encoding):
    src = tmp_path / "full.pcd"
    write_pcd(tools, runner, src, encoding=encoding, type="F4", extra="rgb", width="150", seed="6")
    blob = exact_copy(src.read_bytes(), encoding)
    more = blob.replace(b"WIDTH 150\n", b"WIDTH 151\n").replace(b"POINTS 150\n", b"POINTS 151\n")
    fewer = blob.replace(b"WIDTH 150\n", b"WIDTH 149\n").replace(b"POINTS 150\n", b"POINTS 149\n")
    mismatch = blob.replace(b"POINTS 150\n", b"POINTS 151\n")
    expect_more = {"ascii": 3242, "binary": 3220, "binary_compressed": 3231}[encoding]
    cases = [(more, expect_more), (mismatch, 3213)]
    # binary files may legally carry bytes after the records (PCL pads them)
    if encoding != "binary":
        cases.append((fewer, {"ascii": 3243, "binary_compressed": 3231}[encoding]))
    p = tmp_path / "lie.pcd"
    for data, code in cases:
        p.write_bytes(data)
        assert_bad(gdt_dump(tools, runner, p), p, code)


@pytest.mark.sanitize
def test_bad_lzf(tools, runner, tmp_path):
    src = tmp_path / "full.pcd"
    write_pcd(tools, runner, src, encoding="binary_compressed", type="F8",
              extra="intensity,gps", width="400", seed="12")
    blob = bytearray(exact_copy(src.read_bytes(), "binary_compressed"))
    off, rec, n = data_layout(bytes(blob))
    csize, usize = struct.unpack_from("<II", blob, off)
    assert usize == rec * n and 0 < csize < len(blob)
    p = tmp_path / "bad.pcd"

    def check(data, code=None):
        p.write_bytes(bytes(data))
        r = gdt_dump(tools, runner, p, "--buffer-bytes", "100")
        assert_bad(r, p, code)

    def with_sizes(c, u):
        b = bytearray(blob)
        struct.pack_into("<II", b, off, c, u)
        return b

    check(with_sizes(csize + 1, usize), 3232)                # beyond the end of the file
    check(with_sizes(0xFFFFFFFF, usize), 3232)
    check(with_sizes(csize, usize + 8), 3231)                # not POINTS x record
    check(with_sizes(csize, 0xFFFFFFFF), 3231)
    check(with_sizes(csize - 5, usize), None)                # stream cut short
    check(with_sizes(2, usize), 3233)                        # impossible ratio
    bad = bytearray(blob)
    bad[off + 8] = 0xE0 | 0x1F                               # first item a back-reference
    check(bad, 3234)
    padded = tmp_path / "padded.pcd"                          # trailing padding is legal
    padded.write_bytes(bytes(blob) + bytes(4096))
    r = gdt_dump(tools, runner, padded)
    assert r.returncode == 0 and r.stdout == pcl_dump(tools, runner, src)


def lzf_literals(data):
    """LZF items copying data literally (runs of at most 32 bytes)."""
    out = bytearray()
    for i in range(0, len(data), 32):
        run = data[i:i + 32]
        out += bytes([len(run) - 1]) + run
    return bytes(out)


def lzf_ref(length, dist):
    """LZF back-reference item copying `length` (3..264) bytes from `dist` (1..8192) back."""
    n, d = length - 2, dist - 1
    if n < 7:
        return bytes([(n << 5) | (d >> 8), d & 0xFF])
    return bytes([(7 << 5) | (d >> 8), n - 7, d & 0xFF])


# x = 1.5, 1.5, 1.5; y = 2, 3, 4; z = 5, 5, 5 as F8 columns (72 bytes)
X15, Z5 = struct.pack("<d", 1.5), struct.pack("<d", 5.0)
Y = struct.pack("<3d", 2.0, 3.0, 4.0)
GOOD_STREAM = lzf_literals(X15) + lzf_ref(16, 8) + lzf_literals(Y) + lzf_literals(Z5) + \
    lzf_ref(16, 8)
ZERO72 = lzf_literals(bytes(8)) + lzf_ref(64, 8)  # 72 zero bytes in 12 stream bytes
HAND_STREAMS = [
    ("valid", GOOD_STREAM, None),
    ("literal_past_end", bytes([0x1F]) + bytes(10), 3235),
    ("zeros", ZERO72, None),
    ("reference_first", bytes([0x20, 0x00]) + ZERO72, 3234),
    ("reference_too_far", lzf_literals(X15) + lzf_ref(3, 8192) + lzf_literals(bytes(61)), 3234),
    ("longer_than_declared", ZERO72 + lzf_literals(b"\x01"), 3236),
    ("dangling_control", ZERO72 + bytes([0xE0]), 3236),
    ("reference_past_end", lzf_literals(bytes(64)) + lzf_ref(10, 8), 3236),
    ("shorter_than_declared", lzf_literals(bytes(70)), 3235),
]


@pytest.mark.sanitize
@pytest.mark.parametrize("name,stream,code", HAND_STREAMS, ids=[h[0] for h in HAND_STREAMS])
def test_hand_made_lzf(tools, runner, tmp_path, name, stream, code):
    header = ("VERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 3\n"
              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 3\nDATA binary_compressed\n")
    p = tmp_path / f"{name}.pcd"
    p.write_bytes(header.encode() + struct.pack("<II", len(stream), 72) + stream)
    r = gdt_dump(tools, runner, p, "--buffer-bytes", "3")
    if code is None:
        assert r.returncode == 0, r.stderr
        expect = [(1.5, 2.0, 5.0), (1.5, 3.0, 5.0), (1.5, 4.0, 5.0)] if name == "valid" else \
            [(0.0, 0.0, 0.0)] * 3
        assert points_of(r.stdout) == expect
        assert r.stdout == pcl_dump(tools, runner, p)
    else:
        assert_bad(r, p, code)


@pytest.mark.sanitize
@pytest.mark.parametrize("encoding", ENCODINGS)
def test_random_corruption_never_crashes(tools, runner, tmp_path, encoding):
    """Seeded byte flips anywhere: exit 0 (still a valid file) or 3, nothing else."""
    src = tmp_path / "full.pcd"
    write_pcd(tools, runner, src, encoding=encoding, type="F4", extra="intensity",
              width="60", seed="13")
    blob = exact_copy(src.read_bytes(), encoding)
    rng = random.Random(1000 + ENCODINGS.index(encoding))
    p = tmp_path / "fuzz.pcd"
    refused = 0
    for _ in range(30):
        b = bytearray(blob)
        for _ in range(rng.randint(1, 4)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        p.write_bytes(bytes(b))
        r = gdt_dump(tools, runner, p, "--buffer-bytes", str(rng.choice([1, 9, 4096])))
        assert r.returncode in (0, 3), (r.returncode, r.stderr[-2000:])
        assert "Sanitizer" not in r.stderr and "runtime error" not in r.stderr
        if r.returncode == 3:
            refused += 1
            assert str(p) in r.stderr and re.search(r"error GDT-3\d{3}", r.stderr)
    assert refused > 0
