"""Which certificate shape certifies, at what size (issue 25): sparsity="auto" against every forced choice.

    python benchmarks/sparsity_suite.py

For each problem of the suite (known minima, from the SumOfSquares.jl tutorials, the TSSOS README and the
sparse-benchmark families of benchmarks/sparse.py) and each ``sparsity`` of :func:`sospoly.minimize`
("none", "correlative", "term", "newton" where it applies, and "auto"): certified or not, the lower bound,
N_LMIVAR of the certifying program and the wall time.  "cheapest" is the smallest N_LMIVAR among the forced
choices that certify; the last column says whether "auto" certified with it.
"""
from __future__ import annotations

import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import sospoly as sp  # noqa: E402
from sparse import chained_singular, rosenbrock  # noqa: E402

KINDS = ("none", "correlative", "term", "newton", "auto")


def suite():
    x1, x2, x3 = sp.variables("x1 x2 x3")
    x, y = sp.variables("x y")
    tut = (x1**2 - 2 * x1 * x2 + 3 * x2**2 - 2 * x1**2 * x2 + 2 * x1**2 * x2**2 - 2 * x2 * x3 + 6 * x3**2
           + 18 * x2**2 * x3 - 54 * x2 * x3**2 + 142 * x2**2 * x3**2)
    readme = 1 + x1**4 + x2**4 + x3**4 + x1 * x2 * x3 + x2
    yield "SOS.jl term-sparsity tutorial", tut, (), (), 0.0
    yield "TSSOS README (unconstrained)", readme, (), (), 0.4752748
    yield "TSSOS README (constrained)", readme, [x2**2 + x3**2 - 1], [1 - x1**2 - 2 * x2**2], 0.6861925
    yield "SOS.jl sign-symmetry tutorial", 1 + x1**4 + x1 * x2 + x2**4 + x3**2, (), (), 0.875
    yield "SOS.jl polynomial optimization", x**3 - x**2 + 2 * x * y - y**2 + y**3, (), [x, y, x + y - 1], 0.0
    yield "six-hump camel", 4 * x**2 - 2.1 * x**4 + x**6 / 3 + x * y - 4 * y**2 + 4 * y**4, (), (), -1.0316284535
    for n in (6, 10):
        f, eq, ineq, fs = rosenbrock(n)
        yield f"Rosenbrock n={n}", f, eq, ineq, fs
    f, eq, ineq, fs = chained_singular(8)
    yield "chained singular n=8", f, eq, ineq, fs


def main() -> list[str]:
    lines = ["| problem | f* | " + " | ".join(f"{k}: cert / N_LMIVAR / s" for k in KINDS) +
             " | cheapest certifying | auto picked | auto = cheapest? |",
             "|---|---|" + "---|" * (len(KINDS) + 3)]
    for name, f, eq, ineq, fstar in suite():
        cells, best = [], None
        auto = None
        for kind in KINDS:
            if kind == "newton" and (eq or ineq):
                cells.append("n/a")
                continue
            t = time.perf_counter()
            try:
                r = sp.minimize(f, eq, ineq, sparsity=kind, budget=sp.Budget(time_limit=60))
            except ValueError as exc:
                cells.append(f"refused ({exc})"[:40])
                continue
            secs = time.perf_counter() - t
            ok = r.optimal and r.lower_bound is not None and abs(r.lower_bound - fstar) < 1e-5 * max(1, abs(fstar))
            cells.append(f"{'yes' if ok else 'no'} / {r.n_lmivar} / {secs:.2f}")
            if kind == "auto":
                auto = (ok, r.n_lmivar, r.sparsity)
            elif ok and (best is None or r.n_lmivar < best[1]):
                best = (kind, r.n_lmivar)
        same = "-" if best is None else ("yes" if auto and auto[0] and auto[1] <= best[1] else "no")
        lines.append(f"| {name} | {fstar:g} | " + " | ".join(cells) +
                     f" | {best[0] + f' ({best[1]})' if best else 'none'} | {auto[2]} ({auto[1]}) | {same} |")
        print(lines[-1], flush=True)
    return lines


if __name__ == "__main__":
    print("\n".join(main()))
