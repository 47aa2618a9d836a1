"""sospoly.solve_program against a hand-written cvxpy SOS program under variable scaling (review 39b A1/A2).

    python benchmarks/scaled_sos.py

The program: max c s.t. X^4 + Y^4 + 0.5 X Y + 1 - c is SOS, X = s x, Y = s y -- the same program for every s
(optimum 1 - 1/32 = 0.96875, attained at X = -Y = +-sqrt(1/8)).  sospoly writes it with ``SOSProgram`` and
``solve_program``; the peer is the textbook cvxpy build (a 6 x 6 PSD Gram matrix on (1, x, y, x^2, xy, y^2), one
coefficient-matching equality per monomial) solved by Clarabel through cvxpy.  Columns: the status and objective of
each, its error against 0.96875 (an "optimal" objective above the optimum is a false claim), and the wall time
(median of 3).
"""
from __future__ import annotations

import os
import statistics
import sys
import time
import warnings

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

import sospoly as sp  # noqa: E402

OPTIMUM = 0.96875
SCALES = (1.0, 1e-3, 1e-6, 2.0 ** -30, 1e3)


def scaled_quartic_program(s: float) -> sp.SOSProgram:
    """max c s.t. X^4 + Y^4 + 0.5 X Y + 1 - c SOS with X = s x, Y = s y (optimum :data:`OPTIMUM` for every s)."""
    x, y = sp.variables("x y")
    X, Y = x * s, y * s
    prog = sp.SOSProgram(("x", "y"))
    c = prog.scalar("c")
    prog.add_sos(X**4 + Y**4 + 0.5 * X * Y + 1 - c, name="u")
    prog.maximize(c)
    return prog


def sospoly_solve(s: float):
    sol = sp.solve_program(scaled_quartic_program(s))
    return sol.status.value, sol.objective


def cvxpy_solve(s: float):
    import cvxpy as cp

    basis = [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)]
    target = {(4, 0): s**4, (0, 4): s**4, (1, 1): 0.5 * s**2, (0, 0): 1.0}
    G = cp.Variable((6, 6), symmetric=True)
    c = cp.Variable()
    products: dict = {}
    for i, a in enumerate(basis):
        for j, b in enumerate(basis):
            products.setdefault((a[0] + b[0], a[1] + b[1]), []).append(G[i, j])
    cons = [G >> 0]
    for m, entries in products.items():
        rhs = target.get(m, 0.0) - (c if m == (0, 0) else 0.0)
        cons.append(cp.sum(cp.hstack(entries)) == rhs)
    prob = cp.Problem(cp.Maximize(c), cons)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")               # (its status says "optimal_inaccurate" already)
            prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError as exc:
        return f"error: {exc}"[:40], None
    return prob.status, (None if c.value is None else float(c.value))


def timed(fn, s):
    out, ts = None, []
    for _ in range(3):
        t = time.perf_counter()
        out = fn(s)
        ts.append(time.perf_counter() - t)
    return out, statistics.median(ts)


def main() -> int:
    print("s | sospoly status | objective | error | t [s] | cvxpy status | objective | error | t [s]")
    print("--- | --- | --- | --- | --- | --- | --- | --- | ---")
    for s in SCALES:
        row = [f"{s:.3g}"]
        for fn in (sospoly_solve, cvxpy_solve):
            (status, obj), t = timed(fn, s)
            err = "-" if obj is None else f"{obj - OPTIMUM:+.2e}"
            row += [status, "-" if obj is None else f"{obj:.10f}", err, f"{t:.3f}"]
        print(" | ".join(row))
    return 0


if __name__ == "__main__":
    np.set_printoptions(precision=4)
    sys.exit(main())
