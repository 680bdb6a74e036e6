"""plant.pcg64_normals against numpy itself: the same normals, bit for bit, and the same state after.

The oracle is ``numpy.random.Generator(PCG64).standard_normal`` on a second generator built
from the same seed; every comparison is on the raw 64-bit patterns.
"""

import numpy as np
import pytest

from plant.pcg64_normals import applies, draw_into, fill_normals
from plant.randomness import NoiseStream

ZIGGURAT_R = 3.6541528853610088   # numpy's ziggurat_nor_r: |x| beyond it only from the tail branch


def _pair(seed):
    return (np.random.default_rng(np.random.SeedSequence(seed)),
            np.random.default_rng(np.random.SeedSequence(seed)))


@pytest.mark.parametrize("seed", [0, 1, 2**63 + 7])
def test_draws_and_state_equal_numpy(seed):
    ref, ours = _pair(seed)
    x = ref.standard_normal(2_000_003)
    y = np.full(2_000_003, np.nan)
    draw_into(ours, y)
    assert np.array_equal(x.view(np.uint64), y.view(np.uint64))
    assert ours.bit_generator.state == ref.bit_generator.state
    # the wedge (exp) and the tail (log1p) branches were taken, not just the layer test
    assert np.count_nonzero(np.abs(x) > ZIGGURAT_R) > 100
    assert ours.random() == ref.random()            # the generator goes on where numpy's would


def test_blocks_and_mixed_use_equal_numpy():
    """Blocks of any size, interleaved with other draws from the same generator (the buffered
    32-bit half of the state included), give numpy's sequence."""
    ref, ours = _pair(12345)
    sizes = [1, 7, 8192, 3, 50_000, 2]
    for i, n in enumerate(sizes):
        x = ref.standard_normal(n)
        y = np.empty(n)
        draw_into(ours, y)
        assert np.array_equal(x.view(np.uint64), y.view(np.uint64))
        if i % 2 == 0:                              # leaves has_uint32 set on both
            assert ref.integers(0, 2**31, dtype=np.uint32) == ours.integers(0, 2**31, dtype=np.uint32)
        assert ours.bit_generator.state == ref.bit_generator.state


def test_fill_normals_on_a_raw_state():
    """fill_normals on the (hi, lo) words of numpy's 128-bit state and increment."""
    ref = np.random.Generator(np.random.PCG64(2024))
    st0 = ref.bit_generator.state["state"]
    m = (1 << 64) - 1
    st = np.array([st0["state"] >> 64, st0["state"] & m, st0["inc"] >> 64, st0["inc"] & m], dtype=np.uint64)
    out = np.empty(100_000)
    fill_normals(st, out)
    x = ref.standard_normal(100_000)
    assert np.array_equal(x.view(np.uint64), out.view(np.uint64))
    assert (int(st[0]) << 64) | int(st[1]) == ref.bit_generator.state["state"]["state"]


def test_other_bit_generators_keep_numpy():
    """Only an exact PCG64 takes the compiled path; a NoiseStream on another bit generator reads
    numpy's own normals."""
    assert applies(np.random.default_rng(0))
    assert not applies(np.random.Generator(np.random.MT19937(0)))
    assert not applies(np.random.Generator(np.random.PCG64DXSM(0)))
    stream = NoiseStream(np.random.Generator(np.random.Philox(5)), block=1000)
    z, pos = stream.window()
    ref = np.random.Generator(np.random.Philox(5)).standard_normal(1000)
    assert np.array_equal(z[pos:pos + 1000], ref)


def test_noise_stream_reads_numpys_sequence():
    """NoiseStream's buffer across refills and growth is numpy's stream from the same seed."""
    stream = NoiseStream.from_seed(77, block=4096)
    ref = np.random.default_rng(np.random.SeedSequence(77)).standard_normal(40_000)
    got = []
    while sum(len(g) for g in got) < 30_000:
        z, pos = stream.window()
        take = min(3000, z.shape[0] - pos)
        got.append(z[pos:pos + take].copy())
        stream.consumed(pos + take)
        if len(got) % 3 == 0:
            z, pos = stream.grow(stream._pos)
    seq = np.concatenate(got)
    assert np.array_equal(seq.view(np.uint64), ref[:seq.size].view(np.uint64))
