"""Helpers of test_resume.py: gdt-tile runs that can be interrupted at a
chosen instant or in a chosen stage, the stage timeline read from the plain
progress lines on stderr, in-place edits of LAS records, and byte-level
comparison of two outputs.

Progress lines (stderr is a pipe, so plain lines): "gdt-tile: <stage>:
started ..." when a stage starts and "gdt-tile: <stage>: done ..." when it
ends.  Stage names are mapped to the five stages of a tiled run (pass1,
pass2, tiles, merge, write) plus "dup" (the tiler's duplicate merge, the end
of pass 2); a process killed before its first "started" line died in
"startup".
"""
import json
import os
import pathlib
import re
import signal
import struct
import subprocess
import sys
import threading
import time

ROOT = pathlib.Path(__file__).resolve().parents[2]
SCRIPTS = ROOT / "scripts"

REQUIRED_STAGES = ("pass1", "pass2", "tiles", "merge", "write")
PROGRESS = re.compile(r"^gdt-tile: ([^:]+): (started|done)\b")
TRI_NAME = re.compile(r"^tile_-?\d+_-?\d+\.tri$")
STAGE_PATTERNS = (
    ("pass1", re.compile(r"^pass\s*1$")),
    ("pass2", re.compile(r"^pass\s*2$")),
    ("dup", re.compile(r"\bdup")),
    ("ground", re.compile(r"^ground")),
    ("tiles", re.compile(r"^(tiles?|tile stage|core)$")),
    ("merge", re.compile(r"^(seam )?merge$")),
    ("write", re.compile(r"^(write|ply|output|assembl\w*)$")),
)


def stage_key(name):
    """The canonical stage of a progress line's stage name (None: unknown)."""
    name = name.strip().lower()
    for key, pat in STAGE_PATTERNS:
        if pat.search(name):
            return key
    return None


def shell(cmd):
    return " ".join(str(c) for c in cmd)


def gen_cloud(path, points, seed, *extra):
    r = subprocess.run([sys.executable, str(SCRIPTS / "gen_cloud.py"), str(path), "--points",
                        str(points), "--seed", str(seed), "-q", *map(str, extra)],
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return pathlib.Path(path)


def compare_meshes(a, b):
    return subprocess.run([sys.executable, str(SCRIPTS / "compare_meshes.py"), str(a), str(b)],
                          capture_output=True, text=True, timeout=600)


# ---------------------------------------------------------------- runs

class Run:
    """One gdt-tile process with stderr read line by line, each line stamped
    with its arrival time (seconds since the start).

    stop_at(instant) / stop_in(stage, offset) send a signal (default SIGKILL)
    to this process only (by pid, and only while it is not reaped, so the pid
    cannot belong to another process); finish() waits and returns the exit
    status.  After finish(): .rc, .stderr, .events, .died_in, .signalled."""

    def __init__(self, cmd, cwd=None):
        self.cmd = [str(c) for c in cmd]
        self.lines = []          # (t, line)
        self.cond = threading.Condition()
        self.t0 = time.monotonic()
        self.proc = subprocess.Popen(self.cmd, cwd=cwd, stdin=subprocess.DEVNULL,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                     text=True, errors="replace")
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()
        self.signalled = None
        self.sent_at = None
        self.rc = None

    def _read(self):
        for line in self.proc.stderr:
            with self.cond:
                self.lines.append((time.monotonic() - self.t0, line.rstrip("\n")))
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def elapsed(self):
        return time.monotonic() - self.t0

    def send(self, sig):
        """Sends sig now, unless the process has ended."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            self.signalled = sig
            self.sent_at = self.elapsed()

    def stop_at(self, instant, sig=signal.SIGKILL):
        """Signals the process `instant` seconds after its start (if it still runs)."""
        try:
            self.proc.wait(timeout=max(0.0, instant - self.elapsed()))
        except subprocess.TimeoutExpired:
            self.send(sig)

    def wait_for(self, pred, timeout=120.0, poll=0.002):
        """Waits until pred(self) holds; False when the process ended first."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if pred(self):
                return True
            if self.proc.poll() is not None:
                return pred(self)
            time.sleep(poll)
        raise AssertionError(f"timed out waiting in {shell(self.cmd)}")

    def started(self, stage):
        with self.cond:
            return any(stage_key(m.group(1)) == stage and m.group(2) == "started"
                       for m in (PROGRESS.match(l) for _, l in self.lines) if m)

    def stop_in(self, stage, offset, sig=signal.SIGKILL):
        """Signals the process `offset` seconds after the start line of
        `stage`; if the stage never starts (or the process ends first), no
        signal is sent unless a later stage already runs, then at once."""
        order = ["pass1", "pass2", "dup", "tiles", "merge", "write"]
        later = set(order[order.index(stage) + 1:]) if stage in order else set()
        self.wait_for(lambda r: r.started(stage) or any(r.started(s) for s in later))
        if self.started(stage):
            t = self.stage_start(stage)
            self.stop_at(t + offset, sig)
        else:
            self.send(sig)

    def stop_after(self, stage, offset, sig=signal.SIGKILL):
        """Signals the process `offset` seconds after the done line of
        `stage` (if it still runs then)."""
        if self.wait_for(lambda r: r.stage_end(stage) is not None):
            self.stop_at(self.stage_end(stage) + offset, sig)

    def stage_end(self, stage):
        for t, kind, key in self.timeline():
            if key == stage and kind == "done":
                return t
        return None

    def stage_start(self, stage):
        for t, kind, key in self.timeline():
            if key == stage and kind == "started":
                return t
        return None

    def timeline(self):
        """[(t, 'started'|'done', stage key)] in arrival order."""
        with self.cond:
            out = []
            for t, l in self.lines:
                m = PROGRESS.match(l)
                if m:
                    out.append((t, m.group(2), stage_key(m.group(1)) or m.group(1)))
            return out

    def finish(self, timeout=600):
        try:
            self.rc = self.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
            self.reader.join(10)
            raise AssertionError(f"no exit within {timeout} s: {shell(self.cmd)}\n{self.text()}")
        self.reader.join(30)
        return self.rc

    def text(self):
        with self.cond:
            return "\n".join(l for _, l in self.lines)

    @property
    def stderr(self):
        return self.text()

    @property
    def died_in(self):
        """Where the process was when it ended: the last started stage
        ("after <stage>" when its done line came too), or "startup"."""
        last = None
        for _, kind, key in self.timeline():
            last = (kind, key)
        if last is None:
            return "startup"
        return last[1] if last[0] == "started" else f"after {last[1]}"

    @property
    def last_started(self):
        """The last stage that started ("startup": none).  A process that
        stops on an error or a signal ends its current stage's progress on
        the way out, so this, not died_in, is where it stopped."""
        return last_started(self.text())

    @property
    def killed(self):
        return self.rc == -signal.SIGKILL


def last_started(text):
    """The stage of the last "started" progress line of text ("startup": none)."""
    last = "startup"
    for line in text.splitlines():
        m = PROGRESS.match(line)
        if m and m.group(2) == "started":
            last = stage_key(m.group(1)) or m.group(1)
    return last


def durations(timeline, total):
    """{stage: (start, duration)} from a complete run's timeline; a stage
    without its done line ends where the next starts (or at total)."""
    out = {}
    starts = [(t, key) for t, kind, key in timeline if kind == "started"]
    for n, (t, key) in enumerate(starts):
        done = [u for u, kind, k in timeline if kind == "done" and k == key and u >= t]
        end = done[0] if done else (starts[n + 1][0] if n + 1 < len(starts) else total)
        out[key] = (t, max(0.0, end - t))
    return out


def stage_at(timeline, instant):
    """The stage a complete run was in at `instant` (same naming as died_in)."""
    where = "startup"
    for t, kind, key in timeline:
        if t > instant:
            break
        where = key if kind == "started" else f"after {key}"
    return where


# ---------------------------------------------------------------- job files

def tri_files(job):
    d = pathlib.Path(job) / "tiles"
    if not d.is_dir():
        return []
    return sorted(p for p in d.iterdir() if TRI_NAME.match(p.name))


def job_usage(job, page=4096):
    """Bytes (rounded up to whole pages, as tmpfs charges them) of the job's
    files by kind: 'tri', 'tiler' (.pts, .edge), 'index' (.vdb), 'db',
    'other'; and the size of the largest file."""
    use = {"tri": 0, "tiler": 0, "index": 0, "db": 0, "other": 0}
    largest = 0
    for p in pathlib.Path(job).rglob("*"):
        if not p.is_file():
            continue
        size = p.stat().st_size
        largest = max(largest, size)
        pages = -(-size // page) * page
        if TRI_NAME.match(p.name):
            use["tri"] += pages
        elif p.suffix in (".pts", ".edge"):
            use["tiler"] += pages
        elif p.suffix == ".vdb":
            use["index"] += pages
        elif p.name.startswith("job.db"):
            use["db"] += pages
        else:
            use["other"] += pages
    return use, largest


def read_json(path):
    return json.loads(pathlib.Path(path).read_text())


# ---------------------------------------------------------------- LAS edits

def las_layout(path):
    """(offset to point data, record length, point count) of a LAS file."""
    with open(path, "rb") as f:
        hdr = f.read(375)
    assert hdr[:4] == b"LASF", f"{path}: not a LAS file"
    offset = struct.unpack_from("<I", hdr, 96)[0]
    reclen = struct.unpack_from("<H", hdr, 105)[0]
    count = struct.unpack_from("<I", hdr, 107)[0]
    if count == 0 and len(hdr) >= 255:
        count = struct.unpack_from("<Q", hdr, 247)[0]
    return offset, reclen, count


def las_bump_z(path, index):
    """Changes the Z record integer of point `index` by one, staying inside
    the header's z bounds (so the file stays valid); returns (old, new)."""
    offset, reclen, count = las_layout(path)
    assert 0 <= index < count
    with open(path, "r+b") as f:
        hdr = f.read(227)
        zscale, = struct.unpack_from("<d", hdr, 147)
        zoff, = struct.unpack_from("<d", hdr, 171)
        zmax, zmin = struct.unpack_from("<2d", hdr, 211)
        pos = offset + index * reclen + 8
        f.seek(pos)
        old, = struct.unpack("<i", f.read(4))
        z = old * zscale + zoff
        new = old + 1 if (old + 1) * zscale + zoff <= zmax else old - 1
        assert zmin <= new * zscale + zoff <= zmax and zmin <= z <= zmax
        f.seek(pos)
        f.write(struct.pack("<i", new))
    return old, new


# ---------------------------------------------------------------- outputs

def describe_difference(a, b):
    """A short account of how files a and b differ (for failure messages)."""
    a, b = pathlib.Path(a), pathlib.Path(b)
    if not b.exists():
        return f"{b} does not exist"
    x, y = a.read_bytes(), b.read_bytes()
    if x == y:
        return "identical"
    n = min(len(x), len(y))
    first = next((i for i in range(n) if x[i] != y[i]), n)
    hx = x.split(b"end_header\n", 1)[0]
    hy = y.split(b"end_header\n", 1)[0]
    c = compare_meshes(a, b)
    return (f"{a} ({len(x)} bytes) vs {b} ({len(y)} bytes): first difference at byte "
            f"{first}; headers {'equal' if hx == hy else 'differ'}; compare_meshes exit "
            f"{c.returncode}: {(c.stdout + c.stderr).strip()[:400]}")


def listing(folder):
    folder = pathlib.Path(folder)
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


def run_in_namespace(script, args, env, timeout=900):
    """Runs the shell code script (with positional parameters args) in a
    private mount namespace, so it may mount tmpfs; returns the
    CompletedProcess, or None without unshare.  The script echoes MOUNTED
    once its mounts are in place: without it, mounting was not possible."""
    import shutil
    if shutil.which("unshare") is None:
        return None
    return subprocess.run(["unshare", "-m", "sh", "-c", script, "sh", *map(str, args)],
                          capture_output=True, text=True, timeout=timeout,
                          env={**os.environ, **env})


def kill_then_rerun(cmd, out, stage, offset):
    """Runs cmd (writing out) killed in stage after offset seconds, checks
    that a kill before the write stage left no output (one that lands in it,
    as the run can outpace the offset, may come after the atomic rename),
    then runs cmd again to the end; returns the output's bytes."""
    p = Run(cmd)
    p.stop_in(stage, offset)
    rc = p.finish()
    assert rc in (0, -signal.SIGKILL), p.stderr
    if rc != 0 and p.died_in not in ("write", "after write"):
        assert not pathlib.Path(out).exists(), p.died_in
    r = subprocess.run([str(c) for c in cmd] + ["-q"], capture_output=True, text=True,
                       timeout=900)
    assert r.returncode == 0, r.stderr
    return pathlib.Path(out).read_bytes()
