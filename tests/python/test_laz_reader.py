"""LAZ input: gdt-tile reads LASzip-compressed LAS through the LAS source.

The oracle is laspy with its lazrs back-end (an independent LASzip
implementation): every LAZ file gives the points laspy reads from it, in
file order, for every decoder thread count, and through the whole pipeline
the same mesh bytes as the LAS file it compresses.  Broken files (chunk
table lying about a chunk, implausible chunk sizes, points outside the
header bounds, no table) give the documented messages; the mutation tests
are in test_laz_mutate.py.
"""
import json
import os
import pathlib
import shutil
import struct
import subprocess
import sys

import laspy
import numpy as np
import pytest

import laz_util as lu
from laspy.vlrs.vlrlist import VLRList

ROOT = pathlib.Path(__file__).resolve().parents[2]
GEN = ROOT / "scripts" / "gen_cloud.py"
VALIDATE = ROOT / "scripts" / "validate_mesh.py"
THREADS = (1, 2, 7)


@pytest.fixture(scope="session")
def dump(tool):
    return tool("gdt_dump")


def sample(data_dir, name):
    path = data_dir / name
    if not path.exists():
        pytest.skip(f"{name} not in the data folder")
    return path


def gen_cloud(path, points, seed, *extra):
    r = subprocess.run([sys.executable, str(GEN), str(path), "--points", str(points), "--seed",
                        str(seed), "-q", *map(str, extra)], capture_output=True, text=True,
                       timeout=600)
    assert r.returncode == 0, r.stderr
    return path


def dump_text(runner, dump, path, *args):
    r = runner([dump, *args, path])
    assert r.returncode == 0, f"gdt_dump {' '.join(map(str, args))} {path}: rc={r.returncode}\n" \
                              f"{r.stderr[-3000:]}"
    return r.stdout, r.stderr


def dump_info(runner, dump, path):
    out, _ = dump_text(runner, dump, path, "--info")
    return dict(line.partition("=")[::2] for line in out.splitlines())


def expected_text(las):
    """gdt_dump's lines for the points laspy reads (x y z as %.17g, X Y Z)."""
    h = las.header
    ints = [np.asarray(v, dtype=np.int64) for v in (las.X, las.Y, las.Z)]
    coords = [ints[k].astype(np.float64) * np.float64(h.scales[k]) + np.float64(h.offsets[k])
              for k in range(3)]
    return ints, coords


def assert_dump_equals_laspy(text, path, what):
    las = laspy.read(str(path))
    vals = np.array(text.split(), dtype=np.float64).reshape(-1, 6)
    ints, coords = expected_text(las)
    assert vals.shape[0] == len(las.points), f"{what}: {vals.shape[0]} points, " \
                                             f"laspy {len(las.points)}"
    for k in range(3):
        assert np.array_equal(vals[:, 3 + k].astype(np.int64), ints[k]), \
            f"{what}: record integers of axis {k} differ"
        assert np.array_equal(vals[:, k], coords[k]), f"{what}: coordinates of axis {k} differ"


def random_las(path, version, fmt, n, seed, extra=False, evlr=False):
    """A LAS file of n points with seeded random record integers over a
    modest range (so the LAZ integer coders see real differences) and every
    field of the format filled."""
    rng = np.random.default_rng(seed)
    hdr = laspy.LasHeader(version=version, point_format=fmt)
    if extra:
        hdr.add_extra_dims([laspy.ExtraBytesParams("amplitude", "u2"),
                            laspy.ExtraBytesParams("flag", "u1")])
    hdr.scales = np.array([0.01, 0.01, 0.001])
    hdr.offsets = np.array([500000.0, 4000000.0, 0.0])
    las = laspy.LasData(hdr)
    las.X = rng.integers(0, 200000, n).astype(np.int32)
    las.Y = rng.integers(0, 200000, n).astype(np.int32)
    las.Z = rng.integers(-5000, 90000, n).astype(np.int32)
    las.intensity = rng.integers(0, 65536, n).astype(np.uint16)
    las.return_number = rng.integers(1, 4, n).astype(np.uint8)
    las.number_of_returns = np.maximum(las.return_number, rng.integers(1, 4, n)).astype(np.uint8)
    las.classification = rng.integers(0, 19 if fmt < 6 else 200, n).astype(np.uint8)
    if "gps_time" in las.point_format.dimension_names:
        las.gps_time = np.cumsum(rng.uniform(0, 1e-3, n)) + 1e5
    if "red" in las.point_format.dimension_names:
        for c in ("red", "green", "blue"):
            setattr(las, c, rng.integers(0, 65536, n).astype(np.uint16))
    if extra:
        las.amplitude = rng.integers(0, 65536, n).astype(np.uint16)
        las.flag = rng.integers(0, 256, n).astype(np.uint8)
    if evlr:
        las.evlrs = VLRList([laspy.VLR("gdt_test", 7, "opaque", rng.bytes(123))])
    las.update_header()
    las.write(str(path))
    return path


# ------------------------------------------------------------ the source


def test_autzen_laz_gives_the_las_points(dump, runner, data_dir):
    laz = sample(data_dir, "autzen_trim.laz")
    las = sample(data_dir, "autzen_trim.las")
    want, _ = dump_text(runner, dump, las)
    for t in THREADS:
        got, _ = dump_text(runner, dump, laz, "--threads", t)
        assert got == want, f"--threads {t}: the LAZ points differ from the LAS ones"


def test_autzen_laz_info(dump, runner, data_dir):
    info = dump_info(runner, dump, sample(data_dir, "autzen_trim.laz"))
    h = laspy.open(str(data_dir / "autzen_trim.laz")).header
    assert info["format"] == "LAZ" and info["version"] == "1.2"
    assert info["encoding"] == "point format 3" and int(info["record_length"]) == 34
    assert int(info["point_count"]) == h.point_count
    assert info["compressor"] == "pointwise chunked"
    assert info["laz_items"] == "POINT10 v2, GPSTIME11 v2, RGB12 v2"
    assert int(info["laz_chunk_size"]) == 50000
    assert int(info["laz_chunks"]) == -(-h.point_count // 50000)
    assert int(info["vlrs"]) == len(h.vlrs)


CASES = [
    # (version, format, points, chunk, extra bytes, EVLR)
    ("1.2", 0, 301, 50, False, False),
    ("1.2", 1, 257, 64, True, False),
    ("1.2", 2, 200, 17, False, False),
    ("1.2", 3, 1000, 111, True, False),
    ("1.2", 3, 5, None, False, False),
    ("1.4", 1, 300, 40, False, True),
    ("1.4", 3, 420, 100, True, True),
    ("1.4", 6, 333, 50, False, True),
    ("1.4", 7, 280, 64, True, False),
    ("1.4", 8, 150, 41, True, True),
]


@pytest.mark.parametrize("version,fmt,n,chunk,extra,evlr", CASES)
def test_lazrs_files_equal_laspy(dump, runner, tmp_path, version, fmt, n, chunk, extra, evlr):
    """lazrs-written files of the pointwise formats (the last chunk shorter,
    extra bytes, LAS 1.4 with 64-bit counts and an EVLR after the chunk
    table) read as laspy reads them, for every thread count and tiny read
    pieces."""
    src = random_las(tmp_path / "src.las", version, fmt, n, seed=n + fmt, extra=extra, evlr=evlr)
    laz = lu.write_laz(src, tmp_path / "src.laz", chunk)
    info = dump_info(runner, dump, laz)
    assert info["format"] == "LAZ" and int(info["point_count"]) == n
    assert int(info["evlrs"]) == (1 if evlr else 0)
    if chunk is not None:
        assert int(info["laz_chunks"]) == -(-n // chunk)
    ref = None
    for args in [("--threads", 1), ("--threads", 2), ("--threads", 7),
                 ("--threads", 3, "--buffer-bytes", 100, "--chunk", 7),
                 ("--threads", 1, "--need", 1), ("--threads", 3, "--need", 3)]:
        got, _ = dump_text(runner, dump, laz, *args)
        if ref is None:
            assert_dump_equals_laspy(got, src, f"{fmt=} {chunk=}")
            ref = got
        assert got == ref, f"{args}: points differ from --threads 1"


@pytest.mark.parametrize("fmt", [3, 6])
def test_las14_64bit_count_only(dump, runner, tmp_path, fmt):
    """LAS 1.4 with the legacy count 0: the 64-bit count gives the points."""
    src = random_las(tmp_path / "src.las", "1.4", fmt, 250, seed=fmt, evlr=True)
    laz = lu.write_laz(src, tmp_path / "src.laz", 60)
    data = bytearray(laz.read_bytes())
    assert struct.unpack_from("<Q", data, 247)[0] == 250
    struct.pack_into("<I", data, 107, 0)
    laz.write_bytes(bytes(data))
    for t in (1, 3):
        got, _ = dump_text(runner, dump, laz, "--threads", t)
        assert_dump_equals_laspy(got, src, f"format {fmt}, legacy count 0, --threads {t}")


def test_no_chunk_table_reads_the_chunks_in_order(dump, runner, tmp_path):
    """A table offset outside the file: warning, the chunks are found one
    after the other, the last one shorter, the header's count decides."""
    src = random_las(tmp_path / "src.las", "1.2", 3, 530, seed=5)
    laz = lu.write_laz(src, tmp_path / "src.laz", 100)
    lay = lu.Layout(laz)
    data = bytearray(laz.read_bytes())
    struct.pack_into("<q", data, lay.points_start, 1 << 60)
    laz.write_bytes(bytes(data))
    for t in (1, 4):
        got, err = dump_text(runner, dump, laz, "--threads", t)
        assert "GDT-3911" in err, err
        assert_dump_equals_laspy(got, src, f"no table, --threads {t}")
    assert int(dump_info(runner, dump, laz)["laz_chunks"]) == 0


def test_table_that_misplaces_a_chunk_is_refused(dump, runner, tmp_path):
    """A table moving one byte from chunk 2 to chunk 1 (same total): chunk 1
    decodes from fewer bytes than the table gives it."""
    src = random_las(tmp_path / "src.las", "1.2", 1, 400, seed=7)
    laz = lu.write_laz(src, tmp_path / "src.laz", 50)
    lay = lu.Layout(laz)
    entries = [(c[2], c[1]) for c in lay.chunks]
    entries[1] = (entries[1][0], entries[1][1] + 1)
    entries[2] = (entries[2][0], entries[2][1] - 1)
    lu.write_table(laz, entries, lay.vlr_payload)
    errs = set()
    for t in THREADS:
        r = runner([dump, "--threads", t, laz])
        assert r.returncode == 3, r.stderr
        assert "GDT-3971" in r.stderr and "chunk 1 " in r.stderr and str(laz) in r.stderr, \
            r.stderr
        errs.add(r.stderr.strip().splitlines()[-1])
    assert len(errs) == 1, f"the error depends on the thread count: {errs}"


def test_implausible_chunk_size_is_refused(dump, runner, tmp_path):
    """A chunk the table says takes more than twice its records' bytes
    (here 70000 bytes of padding after chunk 0, the table and the table
    offset consistent with it) is refused at open."""
    src = random_las(tmp_path / "src.las", "1.2", 0, 60, seed=9)
    laz = lu.write_laz(src, tmp_path / "src.laz", 20)
    lay = lu.Layout(laz)
    data = laz.read_bytes()
    start0, bytes0, _ = lay.chunks[0]
    pad = 70000
    body = data[:start0 + bytes0] + bytes(pad) + data[start0 + bytes0:lay.table_offset]
    fixed = bytearray(body)
    struct.pack_into("<q", fixed, lay.points_start, lay.table_offset + pad)
    laz.write_bytes(bytes(fixed) + data[lay.table_offset:])
    entries = [(c[2], c[1]) for c in lay.chunks]
    entries[0] = (entries[0][0], entries[0][1] + pad)
    lu.write_table(laz, entries, lay.vlr_payload)
    r = runner([dump, "--info", laz])
    assert r.returncode == 3 and "GDT-3972" in r.stderr and "chunk 0 " in r.stderr, r.stderr


def test_points_outside_the_header_bounds_warn_once(dump, runner, tmp_path, gdt_bin):
    """Header bounds smaller than the data by more than a scale step: one
    warning per file naming the chunk, the points are still read."""
    src = random_las(tmp_path / "src.las", "1.2", 3, 300, seed=11)
    laz = lu.write_laz(src, tmp_path / "src.laz", 100)
    las = laspy.read(str(src))
    order = np.argsort(np.asarray(las.X), kind="stable")
    last = int(order[-1])  # the point with the largest X
    data = bytearray(laz.read_bytes())
    xmax = struct.unpack_from("<d", data, 179)[0]
    struct.pack_into("<d", data, 179, xmax - 0.05)  # five scale steps below the largest x
    laz.write_bytes(bytes(data))
    for t in (1, 3):
        got, err = dump_text(runner, dump, laz, "--threads", t)
        assert err.count("GDT-3990") == 1, err
        assert f"LAZ chunk {last // 100}" in err, err
        assert len(got.splitlines()) == 300
    struct.pack_into("<d", data, 179, xmax + 0.005)  # within one step: no warning
    laz.write_bytes(bytes(data))
    _, err = dump_text(runner, dump, laz)
    assert "GDT-3990" not in err, err


def test_corrupt_chunk_error_is_the_same_for_every_thread_count(dump, runner, tmp_path):
    """Bytes of chunk 5 of 12 overwritten: exit 3 naming the file and chunk
    5, the same message whatever the thread count."""
    src = random_las(tmp_path / "src.las", "1.2", 3, 1200, seed=13)
    laz = lu.write_laz(src, tmp_path / "src.laz", 100)
    lay = lu.Layout(laz)
    start, nbytes, _ = lay.chunks[5]
    data = bytearray(laz.read_bytes())
    for i in range(start + 40, start + nbytes - 8):
        data[i] ^= 0x5A
    laz.write_bytes(bytes(data))
    msgs = set()
    for t in THREADS:
        r = runner([dump, "--threads", t, laz], timeout=60)
        assert r.returncode == 3, f"--threads {t}: rc={r.returncode} {r.stderr[-2000:]}"
        assert str(laz) in r.stderr and "chunk 5" in r.stderr, r.stderr
        msgs.add(r.stderr.strip().splitlines()[-1])
    assert len(msgs) == 1, msgs


# ------------------------------------------------------------ the pipeline


def ply_parts(path):
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    return data[:end].decode(), data[end:]


def tile(runner, gdt_bin, inputs, out, *args):
    r = runner([gdt_bin, *inputs, "--tile", 4096, "-o", out, "-q", *args], cwd=out.parent)
    assert r.returncode == 0, f"{inputs} {args}: rc={r.returncode}\n{r.stderr[-3000:]}"
    return out


def test_autzen_laz_tiled_mesh_equals_las(gdt_bin, runner, data_dir, tmp_path):
    laz = sample(data_dir, "autzen_trim.laz")
    las = sample(data_dir, "autzen_trim.las")
    ref = tile(runner, gdt_bin, [las], tmp_path / "las.ply", "--threads", 2)
    _, want = ply_parts(ref)
    outs = []
    for t in THREADS:
        out = tile(runner, gdt_bin, [laz], tmp_path / f"laz{t}.ply", "--threads", t)
        _, body = ply_parts(out)
        assert body == want, f"--threads {t}: the LAZ mesh differs from the LAS one"
        outs.append(out.read_bytes())
    assert outs[0] == outs[1] == outs[2], "the output bytes depend on --threads"
    v = subprocess.run([sys.executable, str(VALIDATE), str(tmp_path / "laz1.ply"), "--input",
                        str(las)], capture_output=True, text=True, timeout=600)
    assert v.returncode == 0, v.stdout + v.stderr


def test_small_chunks_many_threads_tiled(gdt_bin, runner, data_dir, tmp_path):
    """autzen rewritten in chunks of 997 points (111 chunks): the workers
    run far ahead of the consumer and wrap around their slots many times."""
    las = sample(data_dir, "autzen_trim.las")
    laz = lu.write_laz(las, tmp_path / "small.laz", 997)
    _, want = ply_parts(tile(runner, gdt_bin, [las], tmp_path / "las.ply", "--threads", 1))
    outs = set()
    for t in THREADS:
        out = tile(runner, gdt_bin, [laz], tmp_path / f"laz{t}.ply", "--threads", t)
        _, body = ply_parts(out)
        assert body == want, f"--threads {t}"
        outs.add(out.read_bytes())
    assert len(outs) == 1


def test_mixed_las_and_laz_inputs(gdt_bin, runner, data_dir, tmp_path):
    """Halves of autzen as LAS + LAZ (and LAZ + LAS) give the mesh of the two
    LAS halves."""
    full = laspy.read(str(sample(data_dir, "autzen_trim.las")))
    half = len(full.points) // 2
    parts = []
    for i, sl in enumerate((slice(0, half), slice(half, None))):
        p = laspy.LasData(full.header)
        p.points = full.points[sl].copy()
        p.update_header()
        path = tmp_path / f"part{i}.las"
        p.write(str(path))
        parts.append(path)
    lazs = [lu.write_laz(p, p.with_suffix(".laz"), 5000) for p in parts]
    _, want = ply_parts(tile(runner, gdt_bin, parts, tmp_path / "las.ply"))
    for combo in ([parts[0], lazs[1]], [lazs[0], parts[1]], lazs):
        _, body = ply_parts(tile(runner, gdt_bin, combo, tmp_path / "mixed.ply", "--threads", 3))
        assert body == want, f"{[p.name for p in combo]}"


def test_info_shows_the_compression(gdt_bin, runner, data_dir, tmp_path):
    laz = sample(data_dir, "autzen_trim.laz")
    las = sample(data_dir, "autzen_trim.las")
    js = tmp_path / "info.json"
    r = runner([gdt_bin, laz, las, "--info", "--json", js, "--threads", 2])
    assert r.returncode == 0, r.stderr
    assert "format       : LAZ 1.2, point format 3 (34 bytes/record, 0 extra bytes)" in r.stdout
    assert "compression  : LASzip pointwise chunked: POINT10 v2, GPSTIME11 v2, RGB12 v2" \
        in r.stdout
    assert "chunks       : 3, 50000 points each" in r.stdout
    assert r.stdout.count("compression  :") == 1, "the LAS input shows a compression"
    j = json.loads(js.read_text())
    assert j["inputs"][0]["format"] == "LAZ" and j["inputs"][1]["format"] == "LAS"
    assert j["inputs"][0]["compression"] == {
        "compressor": "pointwise chunked", "items": "POINT10 v2, GPSTIME11 v2, RGB12 v2",
        "chunk_size": 50000, "chunks": 3}
    assert "compression" not in j["inputs"][1]
    # the same cloud twice: every point a duplicate of the LAS one
    assert j["duplicates"] >= j["points"] // 2


def test_reference_on_laz_equals_las(gdt_bin, runner, data_dir, tmp_path):
    outs = []
    for name in ("autzen_trim.las", "autzen_trim.laz"):
        out = tmp_path / (name + ".ply")
        r = runner([gdt_bin, sample(data_dir, name), "--reference", "-q", "-o", out,
                    "--threads", 3])
        assert r.returncode == 0, r.stderr
        outs.append(ply_parts(out)[1])
    assert outs[0] == outs[1]


@pytest.mark.parametrize("fmt", [1, 3, 6, 7, 8])
def test_generated_laz_through_the_pipeline(gdt_bin, runner, tmp_path, fmt):
    version = "1.4" if fmt >= 6 else "1.2"
    las = gen_cloud(tmp_path / "c.las", 20000, fmt, "--point-format", fmt, "--kind", "lidar",
                    "--las-version", version)
    laz = lu.write_laz(las, tmp_path / "c.laz", 3000)
    _, want = ply_parts(tile(runner, gdt_bin, [las], tmp_path / "las.ply"))
    for t in (1, 4):
        _, body = ply_parts(tile(runner, gdt_bin, [laz], tmp_path / "laz.ply", "--threads", t))
        assert body == want, f"format {fmt}, --threads {t}"


def test_corrupt_laz_fails_the_run(gdt_bin, runner, tmp_path):
    src = random_las(tmp_path / "src.las", "1.2", 3, 800, seed=21)
    laz = lu.write_laz(src, tmp_path / "src.laz", 100)
    lay = lu.Layout(laz)
    data = bytearray(laz.read_bytes())
    start, nbytes, _ = lay.chunks[3]
    data[start + nbytes // 2:start + nbytes - 4] = bytes(nbytes - 4 - nbytes // 2)
    laz.write_bytes(bytes(data))
    out = tmp_path / "out.ply"
    r = runner([gdt_bin, laz, "--tile", 4096, "-o", out, "--threads", 2], cwd=tmp_path)
    assert r.returncode == 3, r.stderr
    assert str(laz) in r.stderr and "chunk 3" in r.stderr, r.stderr
    assert not out.exists()


def test_changed_laz_input_refused_by_the_job(gdt_bin, runner, data_dir, tmp_path):
    """The job fingerprint covers a LAZ input like a LAS one: the same bytes
    recompressed with one z changed are refused (exit 6 naming the file)
    until --restart."""
    src = laspy.read(str(sample(data_dir, "autzen_trim.las")))
    laz = lu.write_laz(src, tmp_path / "in.laz", 10000)
    out = tmp_path / "out.ply"
    cmd = [gdt_bin, laz, "--tile", 4096, "-o", out, "--keep-job", "-q"]
    r = runner(cmd, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    before = out.read_bytes()
    z = np.asarray(src.Z).copy()
    z[54321] += 1
    src.Z = z
    size = laz.stat().st_size
    lu.write_laz(src, laz, 10000)
    r = runner(cmd, cwd=tmp_path)
    assert r.returncode == 6, f"rc={r.returncode} (input size {size} -> " \
                              f"{laz.stat().st_size})\n{r.stderr}"
    assert "GDT-6" in r.stderr and "in.laz" in r.stderr and "--restart" in r.stderr, r.stderr
    assert out.read_bytes() == before
    r = runner(cmd + ["--restart"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes() != before


def dump_digest(dump, path, *args):
    """SHA-1 of gdt_dump's output, streamed (millions of lines)."""
    import hashlib
    h = hashlib.sha1()
    with subprocess.Popen([str(dump), *map(str, args), str(path)], stdout=subprocess.PIPE) as p:
        for block in iter(lambda: p.stdout.read(1 << 20), b""):
            h.update(block)
    assert p.returncode == 0, f"gdt_dump {args} {path}: rc={p.returncode}"
    return h.hexdigest()


@pytest.mark.slow
def test_chunks_too_large_for_a_worker_slot(dump, tmp_path):
    """A chunk of 2,000,000 points of 34 bytes (68 MB of records, above the
    64 MiB a worker's slot takes) is decoded in pieces by the reading
    thread, the short last chunk by a worker: the same points for every
    thread count."""
    src = random_las(tmp_path / "big.las", "1.2", 3, 2_100_000, seed=3)
    laz = lu.write_laz(src, tmp_path / "big.laz", 2_000_000)
    want = dump_digest(dump, src)
    for t in (1, 3):
        assert dump_digest(dump, laz, "--threads", t) == want, f"--threads {t}"


def test_pass_2_reads_the_records_pass_1_decoded(gdt_bin, runner, data_dir, tmp_path):
    """A LAZ input is decoded once: pass 2 reads back the records pass 1 kept
    (an unlinked file in the job directory, so nothing is left behind); the
    mesh is the LAS one, with a filter too, and LAS inputs are read twice."""
    laz = sample(data_dir, "autzen_trim.laz")
    las = sample(data_dir, "autzen_trim.las")
    note = "reading the points decoded by the first pass"
    for args in ((), ("--keep-class", "2")):
        job = tmp_path / f"job{len(args)}"
        out = tmp_path / f"mixed{len(args)}.ply"
        r = runner([gdt_bin, laz, las, "--tile", 4096, "-o", out, "-v", "--job", job,
                    "--keep-job", *args], cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-3000:]
        lines = [ln for ln in r.stderr.splitlines() if note in ln]
        assert len(lines) == 1 and "autzen_trim.laz" in lines[0], r.stderr[-3000:]
        assert not [p for p in job.rglob("*") if "replay" in p.name], list(job.rglob("*"))
        ref = tmp_path / f"ref{len(args)}.ply"
        tile(runner, gdt_bin, [las, las], ref, *args)
        assert ply_parts(out)[1] == ply_parts(ref)[1], args


def test_the_decoded_records_are_freed_before_pass_2_syncs(gdt_bin, runner, data_dir, tmp_path):
    """Once pass 2 has read the records pass 1 decoded, and nothing reads the
    cloud again, their temporary file is freed before pass 2 makes its tile
    files durable (a sync of the file system would otherwise write 16 bytes
    a point to the disk only to delete them); with --ground-out, which reads
    the cloud a third time, they are kept."""
    laz = sample(data_dir, "autzen_trim.laz")
    note = "the points decoded by the first pass are released"
    for extra in ((), ("--ground", "pmf", "--ground-out", tmp_path / "g.las")):
        job = tmp_path / f"job{len(extra)}"
        r = runner([gdt_bin, laz, "--tile", 1024, "-o", tmp_path / f"o{len(extra)}.ply", "-v",
                    "--job", job, *extra], cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-3000:]
        lines = r.stderr.splitlines()
        released = [i for i, ln in enumerate(lines) if note in ln]
        synced = [i for i, ln in enumerate(lines) if "tiler --dup merge:" in ln]
        replayed = [ln for ln in lines if "reading the points decoded by the first pass" in ln]
        assert len(replayed) == 1, r.stderr[-3000:]  # pass 2 read them
        if extra:
            assert released == [], r.stderr[-3000:]
        else:
            # after pass 2 read them, before the merge's end (its sync)
            assert len(released) == 1, r.stderr[-3000:]
            assert len(synced) == 1 and released[0] < synced[0], r.stderr[-3000:]


@pytest.mark.parametrize("fmt", [3, 6])
def test_workers_that_cannot_be_started(dump, runner, tools_dir, tmp_path, fmt):
    """When the system refuses threads (pthread_create fails with EAGAIN for
    every worker, or after the first), the chunks are decoded by the
    workers that did start or by the reading thread: the same points, in
    the same order, and no hang."""
    import os
    shim = tools_dir / "libgdt_fail_threads.so"
    if not shim.exists():
        pytest.fail(f"libgdt_fail_threads.so not built at {shim}")
    src = random_las(tmp_path / "src.las", "1.4", fmt, 20_000, seed=fmt)
    laz = lu.write_laz(src, tmp_path / "src.laz", 1000)
    want, _ = dump_text(runner, dump, laz, "--threads", 1)
    assert_dump_equals_laspy(want, src, f"format {fmt}")
    for allowed in (0, 1, 2):
        log = tmp_path / f"refused{allowed}.log"
        env = dict(os.environ, LD_PRELOAD=str(shim), GDT_TEST_THREADS_ALLOWED=str(allowed),
                   GDT_TEST_THREADS_LOG=str(log))
        r = subprocess.run([str(dump), "--threads", "4", str(laz)], capture_output=True,
                           text=True, timeout=120, env=env)
        assert r.returncode == 0, f"{allowed} threads allowed: rc={r.returncode}\n{r.stderr}"
        assert r.stdout == want, f"{allowed} threads allowed: the points differ"
        assert log.exists(), f"{allowed} threads allowed: no thread was refused (shim not loaded?)"
