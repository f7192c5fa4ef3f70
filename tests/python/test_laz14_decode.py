"""Layered LAZ (point formats 6-10): our decoder against the writers.

Fixtures are written at test time with laspy's two LAZ back-ends, LASzip
(laszip) and laz-rs (lazrs), from point arrays whose every field varies:
several scanner channels in runs (so the per-channel contexts switch often),
classifications above 31, all four classification flags, 15 returns, GPS
time with jumps, RGB, NIR, wave packets and extra bytes.  Both writers code
every item as version 3 (the only version either can write), and laz-rs can
be given any fixed chunk size or variable chunks.  laz-rs 0.8.2 codes formats
9 and 10 wrongly when the scanner channel changes (laspy cannot read those
files back either), so those are written with LASzip or with one channel.

tests/laz_decode prints the decoded records; --need all must give exactly
the bytes of the points written (and laspy's decoding), a selective --need
exactly the needed fields and zeros elsewhere.  Version 4 differs from
version 3 only where the channel changes, so a one-channel version-3 file
relabelled as version 4 must decode the same, and a many-channel one must
not (the two versions really do follow channels differently).  Real
version-4 streams with channel changes come from data/laz14 (written once
with the Rust laz crate, checked against LASzip's decoding at test time).
"""
import struct

import numpy as np
import pytest

import laz14_util as lu

FORMATS = [6, 7, 8, 9, 10]


def check_all(runner, tool, path, las):
    got = lu.decode(runner, tool, path, "all")
    exp = las.points.array.tobytes()
    back = lu.laspy_records(path)
    assert back == exp, "the writer's own file does not read back (fixture bug)"
    lu.assert_records_equal(got, exp, las.header.point_format.size, path)


@pytest.mark.parametrize("fmt", FORMATS)
def test_laszip_writer_all_fields(runner, tool, tmp_path, fmt):
    las = lu.make_las(fmt, 12000, seed=fmt)
    path = tmp_path / f"f{fmt}.laz"
    lu.write_laz(las, path, "laszip")
    assert lu.item_versions(path) == [3] * len(lu.item_versions(path))
    check_all(runner, tool, path, las)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("chunks", [1, 7, 50000, "variable"])
def test_lazrs_writer_chunk_sizes(runner, tool, tmp_path, fmt, chunks):
    n = 400 if chunks == 1 else 6000
    # laz-rs cannot write formats 9 and 10 with channel changes
    las = lu.make_las(fmt, n, seed=10 * fmt + 1, channels=4 if fmt < 9 else 1)
    if chunks == "variable":
        chunks = [1, 2, 57, 1000, 3, n - 1063]
    path = tmp_path / f"f{fmt}.laz"
    lu.write_laz(las, path, "lazrs", chunks)
    check_all(runner, tool, path, las)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("first_channel", [0, 2])
def test_one_channel_not_zero(runner, tool, tmp_path, fmt, first_channel):
    """Version 3 tells the items after POINT14 channel 0 on every point where
    the channel does not change, so a file whose points all use channel 2
    switches those items' contexts from point 2 on."""
    las = lu.make_las(fmt, 3000, seed=fmt + 40, channels=1, channel_base=first_channel)
    path = tmp_path / "c.laz"
    lu.write_laz(las, path, "laszip")
    check_all(runner, tool, path, las)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("need", ["xyz", "class", "flags", "xyz,class,flags", "xyz,flags"])
def test_selective(runner, tool, tmp_path, fmt, need):
    las = lu.make_las(fmt, 8000, seed=fmt + 20)
    path = tmp_path / "s.laz"
    lu.write_laz(las, path, "laszip" if fmt >= 9 else "lazrs", None if fmt >= 9 else 999)
    got = lu.decode(runner, tool, path, need)
    lu.assert_records_equal(got, lu.expected_selective(las, need), las.header.point_format.size,
                            path)


def test_constant_fields_empty_layers(runner, tool, tmp_path):
    """Fields equal over a chunk leave their layers empty (size 0): they
    keep the first point's values, in every channel's context."""
    las = lu.make_las(10, 3000, seed=5)
    a = las.points.array
    for name in ("intensity", "classification", "user_data", "scan_angle", "point_source_id",
                 "gps_time", "red", "green", "blue", "nir", "wavepacket_index",
                 "wavepacket_offset", "wavepacket_size", "return_point_wave_location", "x_t",
                 "y_t", "z_t", "eb_u8"):
        a[name] = a[name][0]
    a["classification_flags"] &= 0xF0
    path = tmp_path / "k.laz"
    lu.write_laz(las, path, "laszip")
    sizes = lu.layer_sizes(path, 0)
    # class, intensity .. GPS time, NIR, wave packet, the u8 extra byte
    # (the Z and RGB layers are written whenever the chunk has points)
    assert [sizes[k] for k in (2, 4, 5, 6, 7, 8, 10, 11, 12)] == [0] * 9, sizes
    check_all(runner, tool, path, las)
    for need in ("xyz,class,flags", "flags"):
        got = lu.decode(runner, tool, path, need)
        lu.assert_records_equal(got, lu.expected_selective(las, need),
                                las.header.point_format.size, path)


@pytest.mark.parametrize("fmt", FORMATS)
def test_version_4(runner, tool, tmp_path, fmt):
    one = lu.make_las(fmt, 3000, seed=fmt + 60, channels=1)
    path = tmp_path / "v4.laz"
    lu.write_laz(one, path, "laszip")
    lu.set_item_versions(path, 4)
    assert lu.item_versions(path) == [4] * len(lu.item_versions(path))
    lu.assert_records_equal(lu.decode(runner, tool, path, "all"), one.points.array.tobytes(),
                            one.header.point_format.size, path)
    if fmt == 6:
        return  # POINT14 alone codes the same in both versions
    many = lu.make_las(fmt, 3000, seed=fmt + 61, channels=4)
    path = tmp_path / "v4many.laz"
    lu.write_laz(many, path, "laszip")
    lu.set_item_versions(path, 4)
    r = runner([tool("laz_decode"), "--need", "all", path], text=False)
    assert r.returncode != 0 or r.stdout != many.points.array.tobytes(), (
        "a version-3 stream with channel changes decodes the same as version 4")


def test_real_file_converted(runner, tool, tmp_path, data_dir):
    import laspy
    src = laspy.read(str(data_dir / "autzen_trim.las"))
    for fmt in (6, 8):
        las = laspy.convert(src, point_format_id=fmt, file_version="1.4")
        path = tmp_path / f"a{fmt}.laz"
        las.write(str(path), do_compress=True, laz_backend=laspy.LazBackend.Laszip)
        check_all(runner, tool, path, las)


# ---- corrupt chunks ------------------------------------------------------

def corrupt_case(tmp_path, fmt=7):
    las = lu.make_las(fmt, 2000, seed=99)
    path = tmp_path / "ok.laz"
    lu.write_laz(las, path, "lazrs", 500)
    return las, path


@pytest.mark.parametrize("need", ["all", "xyz,class,flags"])
@pytest.mark.parametrize("layer", [0, 1, 2, 3, 8, 9])
def test_layer_size_past_chunk(runner, tool, tmp_path, need, layer):
    las, path = corrupt_case(tmp_path)
    bad = tmp_path / "bad.laz"
    data = bytearray(path.read_bytes())
    at = lu.layer_size_offset(bytes(data), 1, layer)
    struct.pack_into("<I", data, at, 0x7FFFFFF0)
    bad.write_bytes(bytes(data))
    r = runner([tool("laz_decode"), "--need", need, bad], text=False)
    assert r.returncode == 3, r.stderr
    err = r.stderr.decode()
    assert "GDT-3943" in err and "chunk 1" in err and str(bad) in err, err


@pytest.mark.parametrize("need", ["all", "xyz"])
def test_layer_size_shifted(runner, tool, tmp_path, need):
    """A layer size one too large leaves the sizes summing past the chunk's
    bytes in the table: refused, never read past."""
    las, path = corrupt_case(tmp_path)
    bad = tmp_path / "bad.laz"
    data = bytearray(path.read_bytes())
    at = lu.layer_size_offset(bytes(data), 2, 0)
    size = struct.unpack_from("<I", data, at)[0]
    struct.pack_into("<I", data, at, size + 1)
    bad.write_bytes(bytes(data))
    r = runner([tool("laz_decode"), "--need", need, bad], text=False)
    assert r.returncode == 3, r.stderr
    assert "GDT-39" in r.stderr.decode()


@pytest.mark.parametrize("need", ["all", "xyz,class,flags"])
def test_layer_shrunk_overruns(runner, tool, tmp_path, need):
    """A changed-values layer declared 8 bytes shorter (the next layer
    starting 8 bytes early, the chunk keeping its size) runs out of bytes:
    a corrupt chunk, not a read of the next layer."""
    las, path = corrupt_case(tmp_path)
    bad = tmp_path / "bad.laz"
    data = bytearray(path.read_bytes())
    at = lu.layer_size_offset(bytes(data), 0, 0)
    size = struct.unpack_from("<I", data, at)[0]
    struct.pack_into("<I", data, at, size - 8)
    struct.pack_into("<I", data, at + 4, struct.unpack_from("<I", data, at + 4)[0] + 8)
    bad.write_bytes(bytes(data))
    r = runner([tool("laz_decode"), "--need", need, bad], text=False)
    assert r.returncode == 3, r.stderr
    err = r.stderr.decode()
    assert "GDT-3944" in err or "GDT-3945" in err, err


def test_truncated_file(runner, tool, tmp_path):
    las, path = corrupt_case(tmp_path)
    data = path.read_bytes()
    start = lu.chunk_start(data, 3)
    bad = tmp_path / "bad.laz"
    # the last chunk cut in the middle of its layer sizes, then in a layer
    for cut, code in ((start + las.header.point_format.size + 10, "GDT-3941"),
                      (start + 300, "GDT-3943")):
        bad.write_bytes(data[:cut])
        r = runner([tool("laz_decode"), "--need", "all", bad], text=False)
        assert r.returncode == 3, r.stderr
        err = r.stderr.decode()
        assert code in err and "chunk 3" in err, err


def test_count_below_table(runner, tool, tmp_path):
    """A chunk whose count says fewer points than the table gives it."""
    las, path = corrupt_case(tmp_path)
    data = bytearray(path.read_bytes())
    struct.pack_into("<I", data, lu.chunk_start(bytes(data), 1) + las.header.point_format.size,
                     499)
    bad = tmp_path / "bad.laz"
    bad.write_bytes(bytes(data))
    r = runner([tool("laz_decode"), "--need", "xyz", bad], text=False)
    assert r.returncode == 3, r.stderr
    err = r.stderr.decode()
    assert "GDT-3942" in err and "chunk 1" in err, err


def test_random_corruption_never_crashes(runner, tool, tmp_path):
    rng = np.random.default_rng(3)
    for fmt in (6, 8, 10):
        las = lu.make_las(fmt, 600, seed=fmt, channels=4 if fmt < 9 else 1)
        path = tmp_path / f"r{fmt}.laz"
        lu.write_laz(las, path, "lazrs", 100)
        data = path.read_bytes()
        lo, hi = lu.chunk_start(data, 0), lu.table_offset(data)
        bad = tmp_path / "bad.laz"
        for _ in range(25):
            d = bytearray(data)
            for i in rng.integers(lo, hi, size=4):
                d[i] = int(rng.integers(0, 256))
            bad.write_bytes(bytes(d))
            for need in ("all", "xyz"):
                r = runner([tool("laz_decode"), "--need", need, bad], text=False)
                assert r.returncode in (0, 3), r.stderr


V4_FILES = sorted((lu.DATA / "laz14").glob("v4_*.laz"))


@pytest.mark.parametrize("path", V4_FILES, ids=[p.name for p in V4_FILES])
def test_version_4_files(runner, tool, tmp_path, path):
    """Version-4 files with many channel changes (see data/laz14/README.md)
    decode as LASzip decodes them; relabelled as version 3 they do not (so
    they do test what version 4 changes)."""
    import laspy
    assert len(V4_FILES) == 3
    assert set(lu.item_versions(path)) == {4}
    las = laspy.read(str(path), laz_backend=laspy.LazBackend.Laszip)
    rl = las.header.point_format.size
    lu.assert_records_equal(lu.decode(runner, tool, path, "all"), las.points.array.tobytes(), rl,
                            path)
    for need in ("xyz,class,flags", "flags"):
        lu.assert_records_equal(lu.decode(runner, tool, path, need),
                                lu.expected_selective(las, need), rl, path)
    v3 = tmp_path / "v3.laz"
    v3.write_bytes(path.read_bytes())
    lu.set_item_versions(v3, 3)
    r = runner([tool("laz_decode"), "--need", "all", v3], text=False)
    assert r.returncode != 0 or r.stdout != las.points.array.tobytes()
