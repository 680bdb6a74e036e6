"""The plant's random numbers: one stream of unit normals, drawn from a numpy Generator in blocks.

Passing a ``numpy.random.Generator`` into a compiled function costs ~10 µs per call (numba
unboxes the bit generator every time), more than a whole noise-free sample interval. The
compiled plant therefore reads its randomness from a buffer of unit normals that
:class:`NoiseStream` fills with ``Generator.standard_normal`` — for numpy's PCG64 (the bit generator
of ``default_rng``) through :func:`plant.pcg64_normals.draw_into`, the same numbers and the same
generator state afterwards at ~2 ns a normal instead of ~8. The stream is consumed strictly
in order and a Generator's normals do not depend on how they are blocked, so results are
bit-identical whatever the block size, across runs and executors, from one
``SeedSequence(seed)``.

Uniform variates (bridge-crossing tests, the reflection minimum) come from the same stream as
U = Φ(Z) = ½·erfc(−Z/√2), which is exactly uniform on (0, 1) for a unit normal Z.

A kernel that reaches the end of the buffer raises :class:`NoiseExhausted`; the caller
extends the buffer and runs the same (pure) interval again from the same position, which
reproduces the same draws.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from plant.pcg64_normals import applies, draw_into

__all__ = ["NoiseStream", "NoiseExhausted"]


class NoiseExhausted(Exception):
    """The kernel ran past the end of the normal buffer (the caller extends it and retries)."""


# Position of the read cursor inside the kernels' work sheet (see plant.multimode.interval).
ZPOS = 0


@njit(cache=True)
def normal(z, cursor):
    """Next unit normal of the stream; ``cursor`` is a one-element int64 array."""
    i = cursor[ZPOS]
    if i >= z.shape[0]:
        raise NoiseExhausted()
    cursor[ZPOS] = i + 1
    return z[i]


@njit(cache=True)
def uniform(z, cursor):
    """U = Φ(Z) on (0, 1), from the next unit normal."""
    return 0.5 * math.erfc(-normal(z, cursor) / math.sqrt(2.0))


@njit(cache=True)
def uniform_below(z, cursor, p):
    """U < p for U = Φ(Z) of the next unit normal, the same decision as ``uniform(z, cursor) < p``.

    Φ(Z) ≥ ½ for Z ≥ 0 and < ½ for Z < 0, so the sign of Z decides whenever p and ½ lie on
    opposite sides of it; only the remaining draws pay for erfc.
    """
    x = normal(z, cursor)
    if x >= 0.0 and p <= 0.5:
        return False
    if x < 0.0 and p > 0.5:
        return True
    return 0.5 * math.erfc(-x / math.sqrt(2.0)) < p


class NoiseStream:
    """Unit normals from ``rng`` with a read position; the plant's only source of randomness.

    Parameters
    ----------
    rng : numpy.random.Generator
        The plant-noise generator (spawned from the run's ``SeedSequence``).
    block : int
        Normals drawn per refill. Does not change any result.
    """

    __slots__ = ("_rng", "_buf", "_pos", "_block", "_minimum", "_spare", "_pcg64")

    def __init__(self, rng: np.random.Generator, block: int = 8192) -> None:
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"NoiseStream needs a numpy.random.Generator, got {type(rng).__name__}")
        self._rng = rng
        self._buf = np.empty(0)
        self._pos = 0
        self._block = int(block)
        self._minimum = min(2048, self._block // 2)
        self._spare = np.empty(0)
        self._pcg64 = applies(rng)

    @classmethod
    def from_seed(cls, seed: int, block: int = 8192) -> "NoiseStream":
        return cls(np.random.default_rng(np.random.SeedSequence(seed)), block)

    def window(self) -> tuple[np.ndarray, int]:
        """The buffer and read position, with at least min(2048, block/2) unread normals."""
        if self._buf.shape[0] - self._pos < self._minimum:
            self._refill(self._pos, self._block)
        return self._buf, self._pos

    def grow(self, pos: int) -> tuple[np.ndarray, int]:
        """After :class:`NoiseExhausted`: keep the normals from ``pos`` on, append a block, and
        return the buffer and the new position of ``pos``."""
        self._refill(pos, max(self._block, self._buf.shape[0] - pos))
        return self._buf, self._pos

    def _refill(self, pos: int, n: int) -> None:
        """Keep the unread normals from ``pos`` on and append ``n`` new ones.

        Two storage arrays alternate (the buffer handed to the kernel is a view of one), so a
        refill writes into memory that is already mapped instead of a fresh allocation.
        """
        keep = self._buf.shape[0] - pos
        size = keep + n
        store = self._spare
        if store.shape[0] < size:
            store = np.empty(max(size, 2 * self._block))
        buf = store[:size]
        buf[:keep] = self._buf[pos:]
        if self._pcg64:
            draw_into(self._rng, buf[keep:])          # the same normals, ~4x cheaper (plant.pcg64_normals)
        else:
            self._rng.standard_normal(out=buf[keep:])
        self._spare = self._buf.base if self._buf.base is not None else self._buf
        self._buf = buf
        self._pos = 0

    def consumed(self, pos: int) -> None:
        """Move the read position to ``pos`` (returned by the kernel)."""
        self._pos = int(pos)
