"""Shared fixtures for the Python test suite.

The build directory under test is $GDT_BUILD_DIR (default: build/ at the
repository root).  Real LiDAR samples live in ../shared/data beside the
repository; tests that need them skip with a message where it is absent.
"""
import os
import pathlib
import subprocess
import tempfile

import pytest

from cache_util import copy_cache

ROOT = pathlib.Path(__file__).resolve().parents[2]
DATA = pathlib.Path(os.environ.get("GDT_TEST_DATA_DIR", ROOT.parent / "shared" / "data"))

# One PoCL kernel cache per pytest worker: PoCL 3 builds a kernel's
# work-group variants into its cache as they are first run, and processes
# that do so at the same time in one cache have been seen to crash
# (pocl/pocl#430, #1480).  The programs run by one worker share its cache;
# tests of the cache location itself remove this variable.  The workers
# inherit the environment of the process that started them, which loaded
# this file first: a directory chosen here (GDT_TEST_POCL_CACHE names it) is
# chosen again by each worker, one given by the user is kept.
# A worker's cache made here starts as a copy of $GDT_TEST_POCL_SEED when
# that names one (scripts/test.sh: the cache the builds and C tests filled).
if "POCL_CACHE_DIR" not in os.environ or \
        os.environ.get("GDT_TEST_POCL_CACHE") == os.environ["POCL_CACHE_DIR"]:
    _worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
    _cache = pathlib.Path(tempfile.gettempdir()) / f"gdt-test-pocl-{os.getuid()}-{_worker}"
    _fresh = not _cache.exists()
    _cache.mkdir(parents=True, exist_ok=True)
    _seed = os.environ.get("GDT_TEST_POCL_SEED", "")
    if _fresh and _seed and pathlib.Path(_seed).is_dir():
        copy_cache(pathlib.Path(_seed), _cache)
    os.environ["POCL_CACHE_DIR"] = str(_cache)
    os.environ["GDT_TEST_POCL_CACHE"] = str(_cache)


def build_dir() -> pathlib.Path:
    return pathlib.Path(os.environ.get("GDT_BUILD_DIR", ROOT / "build")).resolve()


@pytest.fixture(scope="session")
def root() -> pathlib.Path:
    return ROOT


@pytest.fixture(scope="session")
def gdt_bin() -> pathlib.Path:
    exe = build_dir() / "tiler" / "gdt-tile"
    if not exe.exists():
        pytest.fail(f"gdt-tile not built at {exe} (set GDT_BUILD_DIR)")
    return exe


@pytest.fixture(scope="session")
def tools_dir() -> pathlib.Path:
    return build_dir() / "tests"


@pytest.fixture(scope="session")
def tool(tools_dir):
    """tool(name) is the path of the built test tool name; fails the test when it is absent."""
    def find(name):
        exe = tools_dir / name
        if not exe.exists():
            pytest.fail(f"{name} not built at {exe} (set GDT_BUILD_DIR)")
        return exe
    return find


@pytest.fixture(scope="session")
def data_dir() -> pathlib.Path:
    if not DATA.is_dir():
        pytest.skip(f"real LiDAR samples not found at {DATA} (../shared/data)")
    return DATA


def run(cmd, **kw):
    """Runs a command, returns CompletedProcess with text output; never raises on exit status."""
    kw.setdefault("capture_output", True)
    kw.setdefault("text", True)
    kw.setdefault("timeout", 600)
    return subprocess.run([str(c) for c in cmd], **kw)


@pytest.fixture(scope="session")
def runner():
    return run
