"""Mutated LAZ files: truncations at and between chunk boundaries, flipped
bytes in the LASzip VLR, the chunk table and the arithmetic-coded chunks,
lying point counts.  Every one must end in a clean decode or exit 3 with a
message naming the file; never a crash, a sanitizer report or a hang (each
run has a timeout).  The result, including the message, must not depend on
the decoder thread count.  Run against the ASan+UBSan build as well.
"""
import random
import struct

import pytest

import laz_util as lu
from test_laz_reader import random_las

TIMEOUT = 60
# One mask per byte, rotating: the low bit, the high bit, every bit.
MASKS = (0x01, 0x80, 0xFF)


@pytest.fixture(scope="module")
def dump(tool):
    return tool("gdt_dump")


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """Three small LAZ files: 8 chunks of format 3 (the last one shorter), 5
    of format 1 in LAS 1.4 with an EVLR after the chunk table, 4 layered
    chunks of format 7."""
    d = tmp_path_factory.mktemp("lazmut")
    a = lu.write_laz(random_las(d / "a.las", "1.2", 3, 300, seed=31, extra=True), d / "a.laz", 40)
    b = lu.write_laz(random_las(d / "b.las", "1.4", 1, 250, seed=32, evlr=True), d / "b.laz", 50)
    c = lu.write_laz(random_las(d / "c.las", "1.4", 7, 110, seed=33), d / "c.laz", 30)
    return [a, b, c]


def check(runner, dump, path, what):
    """Runs the reader with 1 and 3 threads: exit 0 with the header's count
    of points, or exit 3 naming the file; the same either way."""
    results = []
    for t in (1, 3):
        r = runner([dump, "--threads", t, "--buffer-bytes", 200, path], timeout=TIMEOUT)
        for bad in ("AddressSanitizer", "runtime error", "LeakSanitizer"):
            assert bad not in r.stderr, f"{what}: {r.stderr[-3000:]}"
        assert r.returncode in (0, 3), f"{what}, --threads {t}: rc={r.returncode}\n" \
                                       f"{r.stderr[-3000:]}"
        if r.returncode == 3:
            assert str(path) in r.stderr and "GDT-3" in r.stderr, f"{what}: {r.stderr}"
        results.append((r.returncode, r.stdout, r.stderr.strip().splitlines()[-1:]
                        if r.returncode else []))
    assert results[0] == results[1], f"{what}: --threads 1 and 3 differ: " \
                                     f"{[x[0] for x in results]} {[x[2] for x in results]}"
    return results[0][0]


def mutate(tmp_path, src, fn):
    data = bytearray(src.read_bytes())
    fn(data)
    out = tmp_path / "m.laz"
    out.write_bytes(bytes(data))
    return out


@pytest.mark.sanitize
def test_truncations(dump, runner, tmp_path, base):
    for src in base:
        lay = lu.Layout(src)
        starts = lay.boundaries()
        cuts = set(starts) | {starts[0] + 1, starts[1] - 1, starts[-1] - 1, starts[-1] + 1}
        for lo, hi in zip(starts, starts[1:]):
            cuts.add((lo + hi) // 2)
        cuts.update({lay.points_start, lay.points_start + 4, lay.table_offset + 4,
                     lay.size - 1, lay.vlr[0] + 10})
        for cut in sorted(c for c in cuts if 0 < c < lay.size):
            m = tmp_path / "cut.laz"
            m.write_bytes(src.read_bytes()[:cut])
            rc = check(runner, dump, m, f"{src.name} cut at {cut}")
            if cut < lay.table_offset:
                assert rc == 3, f"{src.name} cut at {cut} inside the chunks reads cleanly"


# The LASzip VLR fields every decoder step depends on: compressor, coder,
# chunk size, item count, and the first item's type and size.
VLR_KEY_BYTES = (0, 1, 2, 3, 12, 13, 15, 32, 33, 34, 36)


@pytest.mark.sanitize
def test_flipped_vlr_bytes(dump, runner, tmp_path, base):
    rng = random.Random(5)
    for src in (base[0], base[2]):
        lay = lu.Layout(src)
        at, n = lay.vlr
        picks = set(VLR_KEY_BYTES) | {rng.randrange(n) for _ in range(10)}
        for i in sorted(picks):
            mask = MASKS[i % len(MASKS)]

            def fn(d, i=i, mask=mask):
                d[at + i] ^= mask
            check(runner, dump, mutate(tmp_path, src, fn), f"{src.name} VLR byte {i}^{mask}")


@pytest.mark.sanitize
def test_flipped_table_bytes(dump, runner, tmp_path, base):
    rng = random.Random(6)
    for src in (base[0], base[2]):
        lay = lu.Layout(src)
        offs = {lay.points_start, lay.points_start + 3, lay.points_start + 7}
        offs |= set(range(lay.table_offset, lay.table_offset + 9))
        offs |= {rng.randrange(lay.table_offset + 9, lay.size) for _ in range(8)}
        for i in sorted(offs):
            mask = MASKS[i % len(MASKS)]

            def fn(d, i=i, mask=mask):
                d[i] ^= mask
            check(runner, dump, mutate(tmp_path, src, fn), f"{src.name} table byte {i}^{mask}")


@pytest.mark.sanitize
def test_flipped_stream_bytes(dump, runner, tmp_path, base):
    rng = random.Random(7)
    for src in base:
        lay = lu.Layout(src)
        last = len(lay.chunks) - 1
        for k, (start, nbytes, _) in enumerate(lay.chunks):
            # every chunk's first byte and one drawn; the first and last
            # chunks also their last byte and the first of their second record
            offs = {start, rng.randrange(start, start + nbytes)}
            if k in (0, last):
                offs |= {start + nbytes - 1, start + lay.record_length + 1}
            for i in sorted(offs):
                def fn(d, i=i):
                    d[i] ^= 1 << rng.randrange(8)
                check(runner, dump, mutate(tmp_path, src, fn), f"{src.name} chunk {k} byte {i}")
        # a run of garbage across a chunk boundary
        mid = lay.chunks[1][0]

        def garbage(d, mid=mid):
            d[mid - 16:mid + 16] = bytes(rng.randrange(256) for _ in range(32))
        check(runner, dump, mutate(tmp_path, src, garbage), f"{src.name} garbage at {mid}")


@pytest.mark.sanitize
def test_lying_point_counts(dump, runner, tmp_path, base):
    for src in base:
        lay = lu.Layout(src)
        v14 = src.read_bytes()[25] >= 4
        for count in (0, 1, lay.count - 1, lay.count + 1, lay.count + 40, 2 * lay.count,
                      lay.chunks[0][2], 0xFFFFFFFF):
            def fn(d, count=count):
                if v14:
                    struct.pack_into("<Q", d, 247, count)
                    struct.pack_into("<I", d, 107, count if count < 2**32 else 0)
                else:
                    struct.pack_into("<I", d, 107, count)
            rc = check(runner, dump, mutate(tmp_path, src, fn), f"{src.name} count {count}")
            if count > lay.count:
                assert rc == 3, f"{src.name}: count {count} > {lay.count} reads cleanly"
        if v14:
            def huge(d):
                struct.pack_into("<Q", d, 247, 1 << 62)
                struct.pack_into("<I", d, 107, 0)
            assert check(runner, dump, mutate(tmp_path, src, huge), "count 2^62") == 3
