"""The OpenCL program-binary cache: every program built from its source is kept
as the device's binary in programs/ of the kernel cache directory, a later run
takes it from there (-v says how many came from where), and an entry that is
damaged in any way is never used: the program is built from its source again,
the entry is written again, and the output is the same bytes."""
import os
import pathlib

import tiled_util as tu

MAGIC = b"GDTPROG1"


def programs_dir():
    return pathlib.Path(os.environ["POCL_CACHE_DIR"]) / "programs"


def counts(stderr):
    line = next(ln for ln in stderr.splitlines() if "OpenCL programs:" in ln)
    words = line.split()
    return int(words[words.index("from") - 1]), int(words[words.index("built") - 1])


def run(gdt_bin, cloud, out):
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "-v"])
    assert r.returncode == 0, r.stderr
    return r.stderr


def test_programs_come_from_the_cache_and_damage_is_ignored(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 8000, 4, "lidar")
    run(gdt_bin, cloud, tmp_path / "a.ply")  # fills the cache if it was empty
    err = run(gdt_bin, cloud, tmp_path / "b.ply")
    cached, built = counts(err)
    assert cached == 7 and built == 0, err
    assert str(programs_dir()) in err
    first = (tmp_path / "b.ply").read_bytes()
    entries = sorted(programs_dir().glob("*.bin"))
    assert len(entries) >= 7
    for e in entries:
        assert e.read_bytes()[:8] == MAGIC, e

    # damage every entry, each in one of four ways: cut short, a body that is
    # not a binary, another key in the header, a byte more than it says
    for i, e in enumerate(entries):
        data = e.read_bytes()
        if i % 4 == 0:
            data = data[:20]
        elif i % 4 == 1:
            data = data[:32] + bytes(range(256)) * 4
        elif i % 4 == 2:
            data = data[:8] + bytes(8) + data[16:]
        else:
            data = data + b"\0"
        e.write_bytes(data)
    err = run(gdt_bin, cloud, tmp_path / "c.ply")
    cached, built = counts(err)
    assert built >= 1 and cached + built == 7, err
    assert (tmp_path / "c.ply").read_bytes() == first
    # rewritten whole: the next run takes all of them from the cache again
    err = run(gdt_bin, cloud, tmp_path / "d.ply")
    assert counts(err) == (7, 0), err
    assert (tmp_path / "d.ply").read_bytes() == first
    assert not list(programs_dir().glob("*.tmp-*"))
