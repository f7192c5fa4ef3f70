"""Counter-based random bits.

Every random quantity in a generated cloud is a hash of (key, index): the
values for index i never depend on which other indices are evaluated with it,
which is what makes the output independent of the chunk size.  The mixer is
the SplitMix64 finaliser, in numpy uint64 arithmetic (wrapping) for arrays and
in Python integers for scalars; both give the same bits on every platform.
"""
import numpy as np

MASK64 = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15
_C1 = 0xBF58476D1CE4E5B9
_C2 = 0x94D049BB133111EB
_GOLDEN_U = np.uint64(_GOLDEN)
_C1_U = np.uint64(_C1)
_C2_U = np.uint64(_C2)
_INV16 = 1.0 / 65536.0


def mix64(z: int) -> int:
    """SplitMix64 finaliser of a Python integer (taken modulo 2**64)."""
    z &= MASK64
    z = ((z ^ (z >> 30)) * _C1) & MASK64
    z = ((z ^ (z >> 27)) * _C2) & MASK64
    return z ^ (z >> 31)


def derive_key(seed: int, *labels) -> int:
    """A 64-bit key from a seed and a path of labels (ints or strings).

    Distinct label paths give unrelated keys; the result is stable across
    Python and numpy versions (no use of hash())."""
    k = mix64(seed + _GOLDEN)
    for lab in labels:
        if isinstance(lab, str):
            v = 0xCBF29CE484222325
            for b in lab.encode("utf-8"):
                v = ((v ^ b) * 0x100000001B3) & MASK64
        else:
            v = int(lab) & MASK64
        k = mix64(k ^ mix64(v + 0x632BE59BD9B4E019))
    return k


def hash_indices(idx: np.ndarray, key: int) -> np.ndarray:
    """64 random bits per index: mix64(key + (idx + 1) * golden), as uint64.

    idx: integer array (any signed/unsigned int dtype, values >= 0)."""
    z = idx.astype(np.uint64, copy=True)
    z += np.uint64(1)
    z *= _GOLDEN_U
    z += np.uint64(key & MASK64)
    tmp = np.empty_like(z)
    np.right_shift(z, 30, out=tmp)
    z ^= tmp
    z *= _C1_U
    np.right_shift(z, 27, out=tmp)
    z ^= tmp
    z *= _C2_U
    np.right_shift(z, 31, out=tmp)
    z ^= tmp
    return z


def remix(h: np.ndarray, key: int) -> np.ndarray:
    """Further 64 bits from hashes h: one xor-multiply-xorshift round with a
    key, cheaper than hash_indices and independent enough for attributes."""
    z = h ^ np.uint64(key & MASK64)
    z *= _C1_U
    z ^= z >> 29
    return z


def unit16(h: np.ndarray) -> np.ndarray:
    """Splits 64-bit hashes into four uniform values in [0, 1) each.

    Returns a float64 array of shape (n, 4) with 16 bits of resolution; the
    columns are independent.  Byte order is fixed (little-endian view)."""
    v = h.astype("<u8", copy=False).view("<u2").reshape(-1, 4)
    return v * _INV16


class Stream:
    """Scalar random stream for layout decisions (a few hundred draws).

    Draw k of a stream is mix64(key + k * golden): deterministic and
    independent of numpy's generator implementations."""

    def __init__(self, seed: int, *labels):
        self._key = derive_key(seed, *labels)
        self._n = 0

    def bits(self) -> int:
        self._n += 1
        return mix64(self._key + self._n * _GOLDEN)

    def uniform(self, lo: float = 0.0, hi: float = 1.0) -> float:
        return lo + (hi - lo) * ((self.bits() >> 11) * (1.0 / 9007199254740992.0))

    def randint(self, lo: int, hi: int) -> int:
        """Integer in [lo, hi] inclusive (hi - lo < 2**32)."""
        return lo + (self.bits() >> 32) % (hi - lo + 1)

    def chance(self, p: float) -> bool:
        return self.uniform() < p
