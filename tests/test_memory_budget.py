"""Issue 24, defect 5: the memory budget bounds memory.

* The estimate is the peak of what may run (Clarabel's KKT factor and work arrays, calibrated on
  measured peaks; the interior-point method where the auto back-end runs it first); it was the cheaper
  of the two, 6-7x below Clarabel's measured peak (136 MiB estimated, 0.91 GB used).
* Under an address-space limit (RLIMIT_AS) Theorem 1 with filled ellipses (D = I, 1e30 I, 1e-30 I)
  aborted the interpreter in native code ("memory allocation of ... bytes failed"): now the program is
  refused with status budget_exceeded, naming the limit.
* With an unlimited budget a MemoryError no longer escapes: it is the named status budget_exceeded.
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import sospoly
import tritools
from sospoly import SolveStatus, variables
from sospoly.budget import address_space_available, estimate_size

ROOT = Path(__file__).resolve().parents[1]

_SCRIPT = textwrap.dedent("""
    import resource, sys, time
    import numpy as np
    import sospoly, tritools
    from tritools.model.regions import Ellipse
    from tritools.scene import random_scene
    scale, limit, max_bytes = float(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3])
    sc = random_scene(int(sys.argv[4]), 1, seed=2)
    regions = [Ellipse(p, scale * np.eye(2)) for p in sc.points2d[0]]
    if limit > 0:
        resource.setrlimit(resource.RLIMIT_AS, (int(limit), int(limit)))
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    res = tritools.triangulate(sc.cameras, regions, "theorem1", delta=4,
                               budget=sospoly.Budget(time_limit=8, max_bytes=max_bytes))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(res.status.value, base, peak, res.message.replace(chr(10), " "))
""")


def _run(scale, limit, max_bytes, n_views=4):
    proc = subprocess.run([sys.executable, "-c", _SCRIPT, str(scale), str(limit), str(max_bytes), str(n_views)],
                          env=dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1"),
                          capture_output=True, text=True, timeout=300)
    return proc


@pytest.mark.parametrize("scale", [1.0, 1e30, 1e-30])
def test_an_address_space_limit_gives_a_status_not_an_abort(scale):
    proc = _run(scale, 2 ** 30, 2 * 2 ** 30)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-300:])     # was 134: abort in native code
    status, _, _, message = proc.stdout.split(" ", 3)
    if scale == 1e30:
        # an ellipse of radius 1e15 holds every projection: gamma* = 0 is certified by the trivial bound
        # before any program is built (tritools.solve.trivial); still no abort
        assert status == "optimal", (status, message)
    else:
        assert status == "budget_exceeded" and "RLIMIT_AS" in message


def test_the_estimate_is_clarabel_s_peak_not_the_cheaper_back_end():
    L = 91 * 92 // 2
    size = estimate_size([91, 13, 13, 13], 4590, 0)
    assert 0.91e9 <= size.bytes <= 1.2e9 and L * L > 0        # measured peak 0.91 GB; the estimate was 136 MiB
    single = estimate_size([91], 1, 0)
    assert single.bytes == max(single.clarabel_bytes, single.ipm_bytes)      # the IPM runs first, Clarabel next


@pytest.mark.slow
def test_peak_memory_stays_within_the_estimate():
    """3 views with ellipses at delta = 4 (Gram side 91): the measured peak of the solve is below the
    estimate, and a budget below the estimate refuses the program before anything big is allocated."""
    proc = _run(1.0, 0, 4 * 2 ** 30, n_views=3)
    status, base, peak, _ = proc.stdout.split(" ", 3)
    est = estimate_size([91, 13, 13, 13], 4590, 0).bytes
    assert int(peak) - int(base) <= est, (int(peak) - int(base), est)
    proc = _run(1.0, 0, 0.5 * 2 ** 30, n_views=3)
    status, base, peak, message = proc.stdout.split(" ", 3)
    assert status == "budget_exceeded" and "memory budget" in message
    assert int(peak) - int(base) < 0.25 * 2 ** 30


def test_memory_errors_become_a_named_status(monkeypatch):
    mod = sys.modules["sospoly.minimize"]              # the package exports the function under the same name

    def boom(*a, **k):
        raise MemoryError()
    monkeypatch.setattr(mod, "solve_psatz", boom)
    x, y = variables("x y")
    res = sospoly.minimize((x - 1) ** 2 + (y + 2) ** 2, budget=sospoly.UNLIMITED)
    assert res.status == SolveStatus.BUDGET_EXCEEDED and "MemoryError" in res.message and res.lower_bound is None


def test_triangulate_turns_memory_errors_into_budget_exceeded(monkeypatch):
    from tritools.solve.stages import sdp as mod         # the sdp stage's solve
    from tritools.scene import paper_example

    def boom(*a, **k):
        raise MemoryError()
    monkeypatch.setattr(mod, "solve_psatz", boom)
    cams, regions = paper_example(2)
    res = tritools.triangulate(cams, regions, "theorem1", path="sdp")
    assert res.status == tritools.Status.BUDGET_EXCEEDED and "MemoryError" in res.message


def test_address_space_available_reads_the_limit():
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    if soft != resource.RLIM_INFINITY:
        pytest.skip("this process already runs under an address-space limit")
    assert address_space_available() is None
