"""Issue #22: the memory estimate of a program (sospoly.budget.estimate_size, from the certificate's shape) stays
above Clarabel's measured peak on the views-sparsity programs of benchmarks/manyview.py, without refusing what
fits: manyview N = 30, large setting, seed 2 was refused (estimate 2.17 GiB against the 2 GiB default budget)
while it ran in 1.18 GB peak RSS (0.83 GB above Clarabel's start).

The peak is measured in a fresh process: VmHWM reset (/proc/self/clear_refs) before every Clarabel call, the
peak above the resident size at its start after it."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from sospoly.budget import estimate_size

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import json, sys
    import sospoly, tritools
    import sospoly.certificates.shape as shape
    import sospoly.solvers.backends as be
    from tritools.scene import uncertain_problem

    def vm(key):
        for line in open('/proc/self/status'):
            if line.startswith(key + ':'):
                return int(line.split()[1]) * 1024

    rec = {'estimates': [], 'peaks': []}
    est0 = shape.estimate_size
    def est(*a, **k):
        s = est0(*a, **k)
        rec['estimates'].append(s.bytes)
        return s
    shape.estimate_size = est
    solve0 = be.ClarabelBackend.solve_once
    def solve(self, *a, **k):
        open('/proc/self/clear_refs', 'w').write('5')
        base = vm('VmRSS')
        try:
            return solve0(self, *a, **k)
        finally:
            rec['peaks'].append(vm('VmHWM') - base)
    be.ClarabelBackend.solve_once = solve
    cams, regs, _ = uncertain_problem(int(sys.argv[1]), 2, kinds="mixed", noise_px=16.0, size_px=16.0)
    r = tritools.triangulate(cams, regs, budget=sospoly.Budget(time_limit=120, max_bytes=16 * 2 ** 30))
    rec['status'] = r.status.value
    print(json.dumps(rec))
""")


def _measure(n_views: int) -> dict:
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(n_views)], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr[-500:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/clear_refs"), reason="needs Linux /proc/self/clear_refs")
def test_the_estimate_is_above_the_measured_clarabel_peak_and_not_far_off():
    rec = _measure(16)
    assert rec["peaks"] and rec["estimates"]
    peak, estimate = max(rec["peaks"]), max(rec["estimates"])
    assert peak > 100 * 2 ** 20                           # the views program ran (its peak is ~340 MiB)
    assert estimate >= 1.2 * peak                         # an upper bound, with margin
    assert estimate <= 2.0 * peak                         # and not ~2x off (it was 1.75x here, 2.7x at N = 30)


def test_the_largest_block_weight_keeps_single_blocks_and_lightens_many():
    """One block: unchanged (the Theorem 1 calibration, w = 1); many equal blocks: the largest-block term is
    weighted by its share, so k blocks of one side cost ~ k * ENTRY + LARGEST / k copies of one block."""
    one = estimate_size([91])
    many = estimate_size([54] * 59)
    L1, L2 = 91 * 92 // 2, 54 * 55 // 2
    assert one.clarabel_bytes >= 8 * 7.0 * L1 ** 2                         # 2.5 + 4.5 copies of its entries
    assert many.clarabel_bytes < 8 * (2.5 * 59 + 4.5) * L2 ** 2          # below the unweighted estimate
    assert many.clarabel_bytes >= 8 * 2.5 * 59 * L2 ** 2


_PATTERN_SCRIPT = textwrap.dedent("""
    import json, sys
    import sospoly, tritools
    import sospoly.certificates.sizing as sizing
    import sospoly.solvers.backends as be
    from tritools.scene import uncertain_problem

    def vm(key):
        for line in open('/proc/self/status'):
            if line.startswith(key + ':'):
                return int(line.split()[1]) * 1024

    rec = {'estimates': [], 'dense': [], 'peaks': []}
    with0 = sizing._with_clarabel_sides
    def with_sides(size, shape, sides):
        s = with0(size, shape, sides)
        rec['dense'].append(size.clarabel_bytes)
        rec['estimates'].append(s.clarabel_bytes)
        return s
    sizing._with_clarabel_sides = with_sides
    solve0 = be.ClarabelBackend.solve_once
    def solve(self, *a, **k):
        open('/proc/self/clear_refs', 'w').write('5')
        base = vm('VmRSS')
        try:
            return solve0(self, *a, **k)
        finally:
            rec['peaks'].append(vm('VmHWM') - base)
    be.ClarabelBackend.solve_once = solve
    cams, regs, _ = uncertain_problem(24, 24002, kinds="mixed")
    r = tritools.triangulate(cams, regs, method="corollary1", delta=2, max_delta=2, backend="clarabel",
                             budget=sospoly.Budget(time_limit=120, max_bytes=300 * 2 ** 20))
    rec['status'] = r.status.value
    print(json.dumps(rec))
""")


@pytest.mark.slow
@pytest.mark.skipif(not os.path.exists("/proc/self/clear_refs"), reason="needs Linux /proc/self/clear_refs")
def test_degree_two_regions_sized_on_their_cliques_above_the_measured_peak():
    """A degree-2 program of 24 views of mixed regions (a Gram block of side 80): 562 MiB dense, refused by a
    300 MiB budget before; sized on the aggregate sparsity of its Gram block (sospoly.certificates.sizing) it fits,
    runs, and Clarabel's measured peak stays below that estimate."""
    proc = subprocess.run([sys.executable, "-c", _PATTERN_SCRIPT], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1"))
    assert proc.returncode == 0, proc.stderr[-500:]
    rec = json.loads(proc.stdout.strip().splitlines()[-1])
    assert rec["status"] != "budget_exceeded"
    assert rec["estimates"] and rec["peaks"]
    assert max(rec["dense"]) > 300 * 2 ** 20 > max(rec["estimates"])
    assert max(rec["peaks"]) <= max(rec["estimates"])
