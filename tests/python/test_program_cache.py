"""The OpenCL program-binary cache: every program built from its source is kept
as the device's binary in programs/ of the kernel cache directory, a later run
takes it from there (-v says how many came from where), and an entry that is
damaged in any way is never used: the program is built from its source again,
the entry is written again, and the output is the same bytes."""
import fcntl
import os
import pathlib
import shutil
import time

import tiled_util as tu
from cache_util import copy_cache

MAGIC = b"GDTPROG2"


def private_cache(tmp_path):
    """A kernel cache of this test's own: a copy of the session's PoCL kernels
    (no compiling), without its program binaries, which other workers may be
    writing meanwhile."""
    cache = tmp_path / "cache"
    try:
        shutil.copytree(os.environ["POCL_CACHE_DIR"], cache,
                        ignore=shutil.ignore_patterns("programs", "*.tmp*"))
    except shutil.Error:
        pass  # a file another worker renamed away meanwhile: PoCL rebuilds it
    return cache


def counts(stderr):
    line = next(ln for ln in stderr.splitlines() if "OpenCL programs:" in ln)
    words = line.split()
    return int(words[words.index("from") - 1]), int(words[words.index("built") - 1])


def run(gdt_bin, cloud, out, cache):
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "-v"],
               env=dict(os.environ, POCL_CACHE_DIR=str(cache)))
    assert r.returncode == 0, r.stderr
    return r.stderr


def test_programs_come_from_the_cache_and_damage_is_ignored(gdt_bin, tmp_path):
    cloud = tu.gen_cloud(tmp_path / "c.las", 8000, 4, "lidar")
    cache = private_cache(tmp_path)
    programs = cache / "programs"
    err = run(gdt_bin, cloud, tmp_path / "a.ply", cache)
    assert counts(err)[0] == 0, err
    err = run(gdt_bin, cloud, tmp_path / "b.ply", cache)
    cached, built = counts(err)
    total = cached + built
    assert cached > 0 and built == 0, err
    assert str(programs) in err
    first = (tmp_path / "b.ply").read_bytes()
    entries = sorted(programs.glob("*.bin"))
    assert len(entries) == total
    for e in entries:
        assert e.read_bytes()[:8] == MAGIC, e

    # damage every entry, each in one of five ways: cut short, a body that is
    # not a binary, one byte of the body flipped (its length and header
    # intact), another key in the header, a byte more than it says
    for i, e in enumerate(entries):
        data = e.read_bytes()
        if i % 5 == 0:
            data = data[:20]
        elif i % 5 == 1:
            data = data[:40] + bytes(range(256)) * 4
        elif i % 5 == 2:
            data = data[:-100] + bytes([data[-100] ^ 0x20]) + data[-99:]
        elif i % 5 == 3:
            data = data[:8] + bytes(8) + data[16:]
        else:
            data = data + b"\0"
        e.write_bytes(data)
    err = run(gdt_bin, cloud, tmp_path / "c.ply", cache)
    # every damaged entry is refused before the runtime sees it
    assert counts(err) == (0, total), err
    assert (tmp_path / "c.ply").read_bytes() == first
    # rewritten whole: the next run takes all of them from the cache again
    err = run(gdt_bin, cloud, tmp_path / "d.ply", cache)
    assert counts(err) == (total, 0), err
    assert (tmp_path / "d.ply").read_bytes() == first
    assert not list(programs.glob("*.tmp-*"))


def seeded_cache(path, mode=0o755):
    """A kernel cache directory at path holding the session's PoCL kernels
    and programs (no compiling)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    copy_cache(pathlib.Path(os.environ["POCL_CACHE_DIR"]), path)
    path.chmod(mode)
    return path


def test_an_empty_or_unusable_cache_directory_is_passed_over(gdt_bin, tmp_path):
    """POCL_CACHE_DIR empty (PoCL itself aborts on one) or not a directory, a
    home that cannot be written (batch jobs, containers): the run uses the next
    place (XDG_CACHE_HOME, then gdt-tile-pocl-<uid> in TMPDIR), names each one
    passed over in a warning, and makes the same mesh.  A directory in TMPDIR
    that others may write is never used."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 3000, 5, "lidar")
    xdg = tmp_path / "xdg"
    seeded_cache(xdg / "gdt-tile" / "pocl")
    tmp = tmp_path / "tmp"
    own = seeded_cache(tmp / f"gdt-tile-pocl-{os.getuid()}", 0o700)
    not_a_dir = tmp_path / "file"
    not_a_dir.write_text("x")
    base = {k: v for k, v in os.environ.items()
            if k not in ("POCL_CACHE_DIR", "XDG_CACHE_HOME", "HOME", "TMPDIR")}
    meshes = set()
    for name, env, used, passed in (
            ("empty", dict(POCL_CACHE_DIR="", XDG_CACHE_HOME=str(xdg)),
             xdg / "gdt-tile" / "pocl", []),
            ("a file", dict(POCL_CACHE_DIR=str(not_a_dir), XDG_CACHE_HOME=str(xdg)),
             xdg / "gdt-tile" / "pocl", [not_a_dir]),
            ("no home", dict(HOME="/proc/gdt-no-home", TMPDIR=str(tmp)), own,
             ["/proc/gdt-no-home/.cache/gdt-tile/pocl"])):
        out = tmp_path / f"{name}.ply"
        r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "-v"], env=dict(base, **env))
        assert r.returncode == 0, (name, r.stderr)
        assert f"{used}/programs" in r.stderr, (name, r.stderr)
        for p in passed:
            assert f"cannot use {p} as the OpenCL kernel cache directory" in r.stderr, \
                (name, r.stderr)
        assert r.stderr.count("as the OpenCL kernel cache directory") == len(passed), r.stderr
        meshes.add(out.read_bytes())
    assert len(meshes) == 1

    # a place in TMPDIR open to others is refused, whatever happens next
    own.chmod(0o777)
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", tmp_path / "open.ply", "-v"],
               env=dict(base, HOME="/proc/gdt-no-home", TMPDIR=str(tmp)))
    assert f"cannot use {own} as the OpenCL kernel cache directory: Operation not permitted" \
        in r.stderr, r.stderr
    assert f"{own}/programs" not in r.stderr
    assert "Assertion" not in r.stderr and r.returncode in (0, 5), r.stderr


def test_the_temporary_cache_directory_is_made_private(gdt_bin, tmp_path):
    """Without a usable home the cache directory made in TMPDIR is the
    user's alone (mode 0700), whatever the umask: the next run takes it.
    The input is missing, so the run stops right after choosing it."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {k: v for k, v in os.environ.items()
           if k not in ("POCL_CACHE_DIR", "XDG_CACHE_HOME", "HOME", "TMPDIR")}
    env.update(HOME="/proc/gdt-no-home", TMPDIR=str(tmp))
    made = tmp / f"gdt-tile-pocl-{os.getuid()}"
    for _ in range(2):
        r = tu.run([gdt_bin, tmp_path / "missing.las", "-o", tmp_path / "o.ply"], env=env)
        assert r.returncode != 0 and "missing.las" in r.stderr, r.stderr
        assert made.is_dir() and (made.stat().st_mode & 0o777) == 0o700, oct(made.stat().st_mode)
        assert f"cannot use {made}" not in r.stderr, r.stderr


def test_pocl_leftover_files_older_than_an_hour_are_removed(gdt_bin, tmp_path):
    """PoCL 3.1 leaves an empty "tempfile_XXXXXX" in its cache directory at
    every start; in a POCL_CACHE_DIR the user set, a run removes those of this
    user older than an hour, and nothing else: not a recent one (another
    process may be about to fill it), not one with data, a suffix or another
    length, not a directory (in gdt-tile's own directory those with data or
    a build's suffix go too: test_cache_entries_unused_for_30_days_are_removed)."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 3000, 4, "lidar")
    cache = private_cache(tmp_path)
    for f in cache.glob("tempfile_*"):
        f.unlink()
    old = time.time() - 2 * 3600
    gone = [cache / n for n in ("tempfile_Ab12Cd", "tempfile_000000", "tempfile_zZzZzZ")]
    kept = [cache / n for n in ("tempfile_Qq11Ww", "tempfile_Rr22Tt.so", "tempfile_abc",
                                "tempfile_Fresh1", "tempfile_Dd33Ee", "tempfileX000000")]
    for f in gone + kept:
        if f.name == "tempfile_Dd33Ee":
            f.mkdir()
        else:
            f.write_bytes(b"x" if f.name == "tempfile_Qq11Ww" else b"")
        if f.name != "tempfile_Fresh1":
            os.utime(f, (old, old))
    run(gdt_bin, cloud, tmp_path / "a.ply", cache)
    for f in gone:
        assert not f.exists(), f
    for f in kept:
        assert f.exists(), f
    new = set(cache.glob("tempfile_*")) - set(kept)
    assert len(new) <= 1, sorted(new)  # this run's own, at most


def test_cache_entries_unused_for_30_days_are_removed(gdt_bin, tmp_path):
    """In gdt-tile's own kernel cache ($XDG_CACHE_HOME/gdt-tile/pocl here) a run
    removes program binaries and PoCL program directories that no run used for
    30 days (PoCL's last_accessed file, else the directory's time), PoCL's
    temporary files of interrupted builds older than an hour, nothing else,
    and nothing of the 30-day entries while another run holds the directory's
    lock; a binary a run loads has its time renewed.  In a POCL_CACHE_DIR the
    user set, PoCL's entries and filled temporaries are the user's: only the
    program binaries (and empty temporaries) are pruned there."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 3000, 4, "lidar")
    xdg = tmp_path / "xdg"
    cache = xdg / "gdt-tile" / "pocl"
    cache.parent.mkdir(parents=True)
    shutil.copytree(private_cache(tmp_path), cache)
    env = {k: v for k, v in os.environ.items() if k != "POCL_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(xdg)
    old = time.time() - 40 * 86400

    def age(p):
        for q in sorted(p.rglob("*"), key=lambda q: -len(q.parts)) if p.is_dir() else []:
            os.utime(q, (old, old), follow_symlinks=False)
        os.utime(p, (old, old))

    def pocl_entry(rel, last_accessed=True):
        d = cache / rel
        (d / "k" / "0-0-0").mkdir(parents=True)
        (d / "program.bc").write_bytes(b"bc")
        (d / "k" / "0-0-0" / "k.so").write_bytes(b"so")
        if last_accessed:
            (d / "last_accessed").write_bytes(b"")
        return d

    gone = [pocl_entry("AB/CDEFGHIJKLMNOP"), pocl_entry("AD/PPPPPPPPPP", last_accessed=False)]
    kept = [pocl_entry("AC/ABCDEFGHIJ"), pocl_entry("zz/ABCDEFGHIJ"), pocl_entry("AE/ABCdefGHIJ"),
            pocl_entry("AQ/ABCDEFGHIJ"), pocl_entry("AF/ABCDEFG")]
    for d in gone + kept:
        age(d)
        age(d.parent)
    os.utime(cache / "AC" / "ABCDEFGHIJ" / "last_accessed")  # used today
    programs = cache / "programs"
    programs.mkdir(exist_ok=True)
    old_bin, new_bin, other = (programs / "0123456789abcdef.bin", programs / "fedcba9876543210.bin",
                               programs / "notes.txt")
    for f in (old_bin, new_bin, other):
        f.write_bytes(b"x")
    for f in (old_bin, other):
        os.utime(f, (old, old))
    # PoCL's temporaries of interrupted builds, filled or not, go after an
    # hour in a directory of gdt-tile's own; a recent one, another suffix, a
    # directory or a link stay
    hour_ago = time.time() - 2 * 3600
    tmp_gone = [cache / n for n in ("tempfile_Ab12Cd.so", "tempfile_Ef34Gh.so.o",
                                    "tempfile_Ij56Kl.preproc.cl", "tempfile_Mn78Op.bc",
                                    "tempfile_Qr90St")]
    tmp_kept = [cache / n for n in ("tempfile_Fresh1.so", "tempfile_Uv12Wx.exe",
                                    "tempfile_Yz34Ab.so.x", "tempfile_Cd56Ef.so",
                                    "tempfile_Gh78Ij.so")]
    for f in tmp_gone + tmp_kept:
        if f.name == "tempfile_Cd56Ef.so":
            f.mkdir()
        elif f.name == "tempfile_Gh78Ij.so":
            f.symlink_to(other)
        else:
            f.write_bytes(b"\x7fELF partial" if f.name != "tempfile_Qr90St" else b"")
        if f.name != "tempfile_Fresh1.so":
            os.utime(f, (hour_ago, hour_ago), follow_symlinks=False)

    # while another run uses the directory (a shared lock on .in-use), nothing goes
    with open(cache / ".in-use", "a") as lk:
        fcntl.flock(lk, fcntl.LOCK_SH)
        r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", tmp_path / "a0.ply"], env=env)
        assert r.returncode == 0, r.stderr
        for d in gone:
            assert (d / "program.bc").exists(), d
        assert old_bin.exists()
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", tmp_path / "a.ply", "-v"], env=env)
    assert r.returncode == 0, r.stderr
    assert str(programs) in r.stderr
    for d in gone:
        assert not d.exists(), d
    assert (cache / "AB").is_dir() and (cache / "AD").is_dir()  # PoCL may fill them anytime
    for d in kept:
        assert (d / "k" / "0-0-0" / "k.so").exists(), d
    assert not old_bin.exists() and new_bin.exists() and other.exists()
    for f in tmp_gone:
        assert not f.exists(), f
    for f in tmp_kept:
        assert f.is_symlink() or f.exists(), f  # the link itself, not its target

    # a binary loaded again is renewed; one used 20 days ago stays
    real = sorted(p for p in programs.glob("*.bin") if p != new_bin)
    assert real, sorted(programs.iterdir())
    for p in real:
        os.utime(p, (time.time() - 20 * 86400,) * 2)
    r = tu.run([gdt_bin, cloud, "--tile", "128", "-o", tmp_path / "b.ply", "-v"], env=env)
    assert r.returncode == 0, r.stderr
    assert counts(r.stderr)[0] > 0, r.stderr
    fresh = [p for p in real if p.exists() and p.stat().st_mtime > time.time() - 3600]
    assert len(fresh) == counts(r.stderr)[0], (len(fresh), r.stderr)

    # a POCL_CACHE_DIR of the user's: PoCL's old entries stay, old binaries go,
    # and of PoCL's temporaries only the empty ones without a suffix
    own = private_cache(tmp_path / "own")
    partial = own / "tempfile_Ab12Cd.so"
    partial.write_bytes(b"\x7fELF partial")
    os.utime(partial, (hour_ago, hour_ago))
    keep = own / "AB" / "CDEFGHIJKLMNOP"
    shutil.copytree(gone[0].parent.parent / "AC", own / "AB")  # any PoCL-like entry
    (own / "AB" / "ABCDEFGHIJ").rename(keep)
    age(keep)
    (own / "programs").mkdir(exist_ok=True)
    stale = own / "programs" / "0123456789abcdef.bin"
    stale.write_bytes(b"x")
    os.utime(stale, (old, old))
    run(gdt_bin, cloud, tmp_path / "c.ply", own)
    assert (keep / "program.bc").exists() and not stale.exists() and partial.exists()


def test_a_moved_kernel_directory_keeps_its_compiled_programs(gdt_bin, root, tmp_path):
    """A program's text carries its headers, not the kernel directory's path:
    the kernels copied elsewhere (an install, a bundle on another machine)
    take every program from the cache; a changed header builds those that
    include it again; an error in a header is reported at its own line."""
    cloud = tu.gen_cloud(tmp_path / "c.las", 4000, 4, "lidar")
    cache = private_cache(tmp_path)

    def run_in(kdir, out):
        return tu.run([gdt_bin, cloud, "--tile", "128", "-o", out, "-v"],
                      env=dict(os.environ, POCL_CACHE_DIR=str(cache), GDT_KERNEL_DIR=str(kdir)))

    first = tmp_path / "k1"
    shutil.copytree(root / "kernels", first)
    r = run_in(first, tmp_path / "a.ply")
    assert r.returncode == 0, r.stderr
    built = counts(r.stderr)[1]
    assert built > 0, r.stderr
    moved = tmp_path / "elsewhere" / "kernels"
    moved.parent.mkdir()
    shutil.move(str(first), str(moved))
    r = run_in(moved, tmp_path / "b.ply")
    assert r.returncode == 0, r.stderr
    assert counts(r.stderr) == (built, 0), r.stderr
    assert (tmp_path / "b.ply").read_bytes() == (tmp_path / "a.ply").read_bytes()

    # the predicates header is in every program; gcd_tri.clh in some only
    tri = moved / "gcd_tri.clh"
    tri.write_text(tri.read_text() + "\n/* changed */\n")
    r = run_in(moved, tmp_path / "c.ply")
    assert r.returncode == 0, r.stderr
    cached, rebuilt = counts(r.stderr)
    assert 0 < rebuilt < built and cached + rebuilt == built, r.stderr
    assert (tmp_path / "c.ply").read_bytes() == (tmp_path / "a.ply").read_bytes()

    geom = moved / "gcd_geom.clh"
    lines = geom.read_text().split("\n")
    at = next(i for i, ln in enumerate(lines) if ln.startswith("#define")) + 1
    lines.insert(at, "this is not OpenCL C;")
    geom.write_text("\n".join(lines))
    r = run_in(moved, tmp_path / "d.ply")
    assert r.returncode == 5, r.stderr
    assert f"gcd_geom.clh:{at + 1}:" in r.stderr, r.stderr
    assert not (tmp_path / "d.ply").exists()
