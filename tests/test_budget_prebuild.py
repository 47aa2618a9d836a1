"""Dense programs refused before their polynomials are built (wave 11).

At N = 200 points the dense Corollary 1 program of ``path="sdp"`` took 17 s and 2.6 GB of memory to build before
its size estimate (339 GiB) refused it; at N = 400 5 GB before the time limit.  `sospoly.budget.gram_block_exceeds`
is a floor of that estimate from the Gram block's side alone, checked first.
"""
from __future__ import annotations

import resource
import time

import numpy as np
import pytest

import tritools
from sospoly.budget import Budget, estimate_size, gram_block_exceeds
from tritools.scene import robust_protocol_scene


@pytest.mark.parametrize("seed", range(5))
def test_the_floor_never_exceeds_the_estimate(seed):
    """Wherever the floor refuses a block, every program holding it (more blocks, free columns, rows) is refused by
    :func:`estimate_size` too: the floor is below its bytes."""
    rng = np.random.default_rng(seed)
    budget = Budget(max_bytes=float(2 ** rng.integers(20, 34)))
    for _ in range(50):
        side = int(rng.integers(1, 3000))
        others = [int(s) for s in rng.integers(1, side + 1, size=rng.integers(0, 6))]
        size = estimate_size([side, *others], int(rng.integers(0, 10 ** 6)), int(rng.integers(0, 10 ** 6)))
        if gram_block_exceeds(side, budget):
            assert size.exceeds(budget), (side, others)


def test_unlimited_and_small_blocks_pass():
    assert gram_block_exceeds(10 ** 6, None) is None
    assert gram_block_exceeds(50, Budget()) is None
    assert "exceeds the limit" in gram_block_exceeds(6000, Budget(max_bytes=None))


def test_the_memory_message_names_the_program_not_the_block():
    """The floor is Clarabel's KKT system for a program holding the block (review 29b), not the block's own
    matrix: a side-201 block is 323 KiB as floats, the message says what needs the bytes."""
    msg = gram_block_exceeds(201, Budget(max_bytes=2 ** 20))
    assert msg.startswith("a program with a Gram block of side 201 needs at least ")
    assert "Clarabel's KKT system" in msg and "the memory budget 1 MiB" in msg


def test_large_dense_sdp_call_refused_before_building():
    P, x, _, _ = robust_protocol_scene(150, 0, 1.0, np.random.default_rng(1))
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    r = tritools.triangulate(P, x, path="sdp", sparsity="none")
    assert time.perf_counter() - t < 5.0
    assert r.status == tritools.Status.BUDGET_EXCEEDED, r.message
    assert "before building" in r.message
    assert not r.optimal
    assert r.gamma_lb is None or r.gamma_lb <= r.gamma_ub
    grown = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
    assert grown < 500_000                               # KiB: no gigabytes of polynomials


def test_small_dense_sdp_call_unchanged():
    P, x, _, _ = robust_protocol_scene(6, 0, 1.0, np.random.default_rng(2))
    r = tritools.triangulate(P, x, path="sdp")
    assert r.optimal, r.message
