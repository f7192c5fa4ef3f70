"""Copies of a PoCL kernel cache for tests: linked file by file where the
file system allows (PoCL replaces a cache file by renaming a new one over it
and never writes into one, but for an empty time stamp, so linked copies
stay apart), copied elsewhere."""
import os
import pathlib
import shutil


def copy_cache(src: pathlib.Path, dst: pathlib.Path) -> None:
    """dst gets src's files (dst may exist); PoCL's temporaries are left out,
    and a part that cannot be copied is left to be compiled again."""
    def link(a, b):
        try:
            os.link(a, b)
        except OSError:
            shutil.copy2(a, b)
    try:
        shutil.copytree(src, dst, copy_function=link, dirs_exist_ok=True,
                        ignore=shutil.ignore_patterns("*.tmp*", "*tmp_*"))
    except (shutil.Error, OSError):
        pass  # e.g. a file another process renamed away meanwhile
