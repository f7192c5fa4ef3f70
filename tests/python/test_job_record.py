"""gdt-tile --resume DIR on a damaged job journal: refused with exit 6 and
a message, never a crash, never a run on records that cannot be trusted.

The journals are written here with Python's sqlite3 in the layout of
tiler/private/job.h, or taken from tests/fuzz/regress/job/ (inputs that
once crashed the job-journal fuzz target).
"""
import shutil
import sqlite3

import pytest

from conftest import ROOT, run

SCHEMA = """
CREATE TABLE meta(key TEXT PRIMARY KEY, value TEXT NOT NULL);
CREATE TABLE stage(name TEXT PRIMARY KEY, done INTEGER NOT NULL);
CREATE TABLE tile(k INTEGER PRIMARY KEY, file TEXT NOT NULL, size INTEGER NOT NULL,
                  checksum INTEGER NOT NULL);
CREATE TABLE pfile(k INTEGER NOT NULL, kind INTEGER NOT NULL, size INTEGER NOT NULL,
                   checksum INTEGER NOT NULL, PRIMARY KEY(k, kind));
"""


def write_job(job, params):
    job.mkdir()
    db = sqlite3.connect(job / "job.db")
    db.executescript(SCHEMA)
    db.execute("INSERT INTO meta VALUES ('schema', '2')")
    db.execute("INSERT INTO meta VALUES ('id', ?)", ("0123456789abcdef" * 2,))
    db.execute("INSERT INTO meta VALUES ('params', ?)", (params,))
    db.commit()
    db.close()


@pytest.mark.sanitize
@pytest.mark.parametrize("count", ["18446744073709551615", "4294967296000", "200"])
def test_resume_input_count_beyond_record(gdt_bin, tmp_path, count):
    # 2^64 - 1 once wrapped the array size to 0 and the run wrote past it
    params = (f"tile=64\ncell=0\nhalo=0\ndup=0\nquantum=0.001\ninputs={count}\n"
              f"input={tmp_path / 'a.las'}\noutput={tmp_path / 'o.ply'}\n")
    write_job(tmp_path / "job", params)
    r = run([gdt_bin, "--resume", tmp_path / "job"])
    assert r.returncode == 6, r.stderr
    assert "GDT-6905" in r.stderr
    assert not (tmp_path / "o.ply").exists()


@pytest.mark.sanitize
def test_resume_damaged_journal(gdt_bin, tmp_path):
    # B-tree pages out of order: SQLite would read and write it without an error
    job = tmp_path / "job"
    job.mkdir()
    shutil.copyfile(ROOT / "tests" / "fuzz" / "regress" / "job" / "damaged_btree_tile.db",
                    job / "job.db")
    r = run([gdt_bin, "--resume", job])
    assert r.returncode == 6, r.stderr
    assert "GDT-6901" in r.stderr and "damaged" in r.stderr
