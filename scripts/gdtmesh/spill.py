"""Records distributed over hash buckets, so that equal keys meet in one
bucket that fits in memory.

A Spill holds records of one numpy dtype in nb buckets.  With nb == 1 the
records stay in memory; otherwise every bucket is a file in a private
temporary directory (removed by close()).  Callers choose nb so that one
bucket is about `bucket_bytes` (see buckets_for); the hash functions below
spread any key set evenly, so a bucket exceeds that size only when many
records share one key.
"""
import os
import shutil
import tempfile

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_MIX2 = np.uint64(0xC2B2AE3D27D4EB4F)
MAX_BUCKETS = 512


def buckets_for(nrecords, itemsize, bucket_bytes):
    """Number of buckets so that each holds about bucket_bytes (1..MAX_BUCKETS)."""
    need = -(-int(nrecords) * int(itemsize) // max(1, int(bucket_bytes)))
    return int(min(MAX_BUCKETS, max(1, need)))


def hash_keys(keys, nb):
    """Bucket numbers in [0, nb) of int64 keys (multiplicative hashing)."""
    if nb == 1:
        return np.zeros(np.shape(keys), dtype=np.int64)
    h = np.asarray(keys, dtype=np.int64).view(np.uint64) * _GOLDEN
    h ^= h >> np.uint64(29)
    return (h % np.uint64(nb)).astype(np.int64)


def hash_pairs(a, b, nb):
    """Bucket numbers in [0, nb) of int64 key pairs."""
    if nb == 1:
        return np.zeros(np.shape(a), dtype=np.int64)
    h = np.asarray(a, dtype=np.int64).view(np.uint64) * _GOLDEN
    h ^= h >> np.uint64(31)
    h += np.asarray(b, dtype=np.int64).view(np.uint64) * _MIX2
    h ^= h >> np.uint64(29)
    h *= _GOLDEN
    h ^= h >> np.uint64(32)
    return (h % np.uint64(nb)).astype(np.int64)


class Spill:
    def __init__(self, dtype, nb, tmpdir=None):
        self.dtype = np.dtype(dtype)
        self.nb = int(nb)
        self.count = 0
        self._mem = []
        self._dir = None
        self._files = []
        if self.nb > 1:
            self._dir = tempfile.mkdtemp(prefix="gdtmesh-", dir=tmpdir)
            self._files = [open(os.path.join(self._dir, "b%04d" % i), "wb", buffering=1 << 18)
                           for i in range(self.nb)]

    def add(self, recs, bucket):
        """Appends records (array of self.dtype) to their buckets (int array)."""
        recs = np.asarray(recs, dtype=self.dtype)
        self.count += recs.shape[0]
        if recs.shape[0] == 0:
            return
        if self.nb == 1:
            self._mem.append(recs.copy())
            return
        order = np.argsort(bucket, kind="stable")
        counts = np.bincount(bucket, minlength=self.nb)
        srt = recs[order]
        start = 0
        for b in np.nonzero(counts)[0]:
            end = start + counts[b]
            self._files[b].write(srt[start:end].tobytes())
            start = end

    def __iter__(self):
        """Yields each bucket's records as one in-memory array."""
        if self.nb == 1:
            data = np.concatenate(self._mem) if self._mem else np.zeros(0, self.dtype)
            self._mem = []
            yield data
            return
        for f in self._files:
            f.close()
        for i in range(self.nb):
            path = os.path.join(self._dir, "b%04d" % i)
            data = np.fromfile(path, dtype=self.dtype)
            os.unlink(path)
            yield data

    def close(self):
        for f in self._files:
            if not f.closed:
                f.close()
        self._files = []
        self._mem = []
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False


def hash_rows(cols, nb):
    """Bucket numbers in [0, nb) of rows given as a list of int64 columns."""
    if nb == 1:
        return np.zeros(np.shape(cols[0]), dtype=np.int64)
    h = np.zeros(np.shape(cols[0]), dtype=np.uint64)
    for c in cols:
        h ^= np.asarray(c, dtype=np.int64).view(np.uint64)
        h *= _GOLDEN
        h ^= h >> np.uint64(31)
        h *= _MIX2
        h ^= h >> np.uint64(29)
    return (h % np.uint64(nb)).astype(np.int64)
