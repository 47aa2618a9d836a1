"""sospoly at scale (issue #11): the default ``sospoly.minimize`` on large sparse programs, dense beside it.

    python benchmarks/sparse.py [--quick] [--sizes 10 20 40 100 200] [--problems rosenbrock ...] [--seed 0]

Problems (n variables, known minimum f*, each checked independently of sospoly):

* ``rosenbrock`` -- generalised Rosenbrock, f = 1 + sum_{i>=2} 100 (x_i - x_{i-1}^2)^2 + (1 - x_i)^2
  (Waki, Kim, Kojima, Muramatsu 2006); f - 1 is a sum of squares vanishing exactly at (+-1, 1, ..., 1)
  (x_1 occurs only squared), so f* = 1 with two global minimisers.
* ``chained_singular`` -- Conn, Gould, Toint (1988): sum over i = 1, 3, 5, ..., n - 3 of
  (x_i + 10 x_{i+1})^2 + 5 (x_{i+2} - x_{i+3})^2 + (x_{i+1} - 2 x_{i+2})^4 + 10 (x_i - x_{i+3})^4; a sum
  of even powers vanishing at 0, f* = 0 (n even).
* ``broyden`` -- Broyden tridiagonal, sum_i ((3 - 2 x_i) x_i - x_{i-1} - 2 x_{i+1} + 1)^2, x_0 = x_{n+1} = 0;
  f* = 0 (Moré, Garbow, Hillstrom 1981, problem 30; the square system has real roots, found here by
  the extracted minimiser itself: its f is the "upper" column).
* ``bilinear`` -- constrained: min sum_{i<n} x_i x_{i+1} s.t. 1 - x_i^2 >= 0; each term is >= -1 on the
  box, with equality along x_i = +-(-1)^i, so f* = -(n - 1) (two global minimisers).
* ``ising`` -- constrained: min sum_{i<n} J_i x_i x_{i+1} + sum_i h_i x_i s.t. x_i^2 - 1 = 0 with seeded
  J ~ U(-1, 1), h ~ U(-1/2, 1/2); f* by dynamic programming over x in {-1, 1}^n (``ising_reference``).

For each n: the default call ``sospoly.minimize(f, eq, ineq)`` (``sparsity="auto"``: the correlative
certificate) and the dense certificate (``sparsity="none"``) at the degree the default call ended with,
both under the default :class:`sospoly.Budget`.  A dense program is sized first
(:func:`sospoly.estimate_size` on its closed-form Gram sides); one that does not fit is not built and shows
"exceeds budget" with its estimate.  N_LMIVAR(dense) is the closed form
:func:`sospoly.n_lmivar_formula` (equal to the assembled count, tests/test_sparse_minimize.py), so the ratio
sparse/dense is reported for every n.  A last table fits time ~ n^a and N_LMIVAR ~ n^b over the sizes run
(those certified at the largest size's degree).
"""
from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import sospoly as sp  # noqa: E402
from sospoly import sigma  # noqa: E402

SIZES = (10, 20, 40, 100, 200)
QUICK_SIZES = (10, 20)
PROBLEMS = ("rosenbrock", "chained_singular", "broyden", "bilinear", "ising")


# ----------------------------------------------------------------------------- problems
def rosenbrock(n: int, seed: int = 0):
    """Generalised Rosenbrock with the leading 1: (f, eq, ineq, f*)."""
    x = sp.variables("x", n=n)
    f = 1.0 + sum(100 * (x[i] - x[i - 1] ** 2) ** 2 + (1 - x[i]) ** 2 for i in range(1, n))
    return f, (), (), 1.0


def chained_singular(n: int, seed: int = 0):
    """Chained singular function (Conn, Gould, Toint 1988), n even: (f, eq, ineq, f*)."""
    if n % 2 or n < 4:
        raise ValueError(f"the chained singular function needs an even n >= 4, got {n}")
    x = sp.variables("x", n=n)
    f = 0.0
    for i in range(0, n - 3, 2):
        f = f + (x[i] + 10 * x[i + 1]) ** 2 + 5 * (x[i + 2] - x[i + 3]) ** 2 + (x[i + 1] - 2 * x[i + 2]) ** 4 \
            + 10 * (x[i] - x[i + 3]) ** 4
    return f, (), (), 0.0


def broyden(n: int, seed: int = 0):
    """Broyden tridiagonal function: (f, eq, ineq, f*)."""
    x = sp.variables("x", n=n)
    f = 0.0
    for i in range(n):
        r = (3 - 2 * x[i]) * x[i] + 1
        if i > 0:
            r = r - x[i - 1]
        if i < n - 1:
            r = r - 2 * x[i + 1]
        f = f + r ** 2
    return f, (), (), 0.0


def bilinear(n: int, seed: int = 0):
    """min sum x_i x_{i+1} on the box [-1, 1]^n: (f, eq, ineq, f* = -(n - 1))."""
    x = sp.variables("x", n=n)
    return sum(x[i] * x[i + 1] for i in range(n - 1)), (), tuple(1 - xi ** 2 for xi in x), -(n - 1.0)


def ising_data(n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.0, 1.0, n - 1), rng.uniform(-0.5, 0.5, n)


def ising_reference(J, h) -> tuple[float, np.ndarray]:
    """Exact min over s in {-1, 1}^n of sum J_i s_i s_{i+1} + sum h_i s_i by dynamic programming
    (independent of sospoly), and a minimiser."""
    s = np.array([-1.0, 1.0])
    cost = h[0] * s                       # best energy of x_1..x_i ending in s
    back = []
    for i in range(1, len(h)):
        tot = cost[:, None] + J[i - 1] * np.outer(s, s) + h[i] * s[None, :]
        back.append(np.argmin(tot, axis=0))
        cost = tot.min(axis=0)
    k = int(np.argmin(cost))
    path = [k]
    for b in reversed(back):
        k = int(b[k])
        path.append(k)
    return float(cost.min()), s[np.array(path[::-1])]


def ising(n: int, seed: int = 0):
    """Ising chain with fields on x_i^2 = 1: (f, eq, ineq, f* by dynamic programming)."""
    J, h = ising_data(n, seed)
    x = sp.variables("x", n=n)
    f = sum(float(J[i]) * x[i] * x[i + 1] for i in range(n - 1)) + sum(float(h[i]) * x[i] for i in range(n))
    return f, tuple(xi ** 2 - 1 for xi in x), (), ising_reference(J, h)[0]


BUILDERS = {"rosenbrock": rosenbrock, "chained_singular": chained_singular, "broyden": broyden,
            "bilinear": bilinear, "ising": ising}


# ----------------------------------------------------------------------------- dense sizing
def dense_count(n: int, degree: int, eq, ineq) -> int:
    """N_LMIVAR of the dense certificate (closed form, SPEC §8)."""
    return sp.n_lmivar_formula(n, degree, [g.degree for g in eq], [h.degree for h in ineq])


def dense_size(n: int, degree: int, eq, ineq) -> sp.ProgramSize:
    """The dense program's estimate from its closed-form Gram sides (nothing is enumerated)."""
    sides = [sigma(n, degree // 2)] + [sigma(n, (degree - h.degree) // 2) for h in ineq]
    return sp.estimate_size(sides, 1 + sum(sigma(n, degree - g.degree) for g in eq))


# ----------------------------------------------------------------------------- runs
def run_one(name: str, n: int, seed: int, budget: sp.Budget, dense_budget: sp.Budget | None = None) -> dict:
    """The default call and, when it fits ``budget`` and ``dense_budget`` is given, the dense one beside it."""
    f, eq, ineq, fstar = BUILDERS[name](n, seed)
    t0 = time.perf_counter()
    res = sp.minimize(f, eq, ineq, budget=budget)
    seconds = time.perf_counter() - t0
    row = dict(problem=name, n=n, fstar=fstar, degree=res.degree, sparsity=res.sparsity, seconds=seconds,
               n_lmivar=res.n_lmivar, lower=res.lower_bound, upper=res.upper_bound, certified=res.optimal,
               status=res.status.value, dense_n_lmivar=dense_count(n, res.degree, eq, ineq))
    size = dense_size(n, res.degree, eq, ineq)
    why = size.exceeds(budget)
    row["dense_estimate"] = size.describe()
    if why is not None or dense_budget is None:
        row["dense"] = None if why is None else "exceeds budget"
        return row
    t0 = time.perf_counter()
    d = sp.minimize(f, eq, ineq, degree=res.degree, sparsity="none", budget=dense_budget)
    row["dense"] = dict(seconds=time.perf_counter() - t0, n_lmivar=d.n_lmivar, lower=d.lower_bound,
                        upper=d.upper_bound, certified=d.optimal, status=d.status.value)
    return row


def _num(v, digits: int = 8) -> str:
    return "-" if v is None else f"{v:.{digits}g}"


def _valid(row: dict, tol: float = 1e-6) -> str:
    """Is the lower bound <= f* (up to tol * max(1, |f*|)) and the upper bound >= f* likewise?"""
    slack = tol * max(1.0, abs(row["fstar"]))
    lo_ok = row["lower"] is None or row["lower"] <= row["fstar"] + slack
    up_ok = row["upper"] is None or row["upper"] >= row["fstar"] - slack
    return "yes" if lo_ok and up_ok else "NO"


def table(rows) -> list[str]:
    out = ["| problem | n | f* | degree | sparsity | time [s] | N_LMIVAR | lower | upper | certified | bounds valid "
           "| dense time [s] | dense N_LMIVAR | dense lower | dense certified | N_LMIVAR sparse/dense |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        d = r["dense"]
        if isinstance(d, dict):
            verdict = "yes" if d["certified"] else f"no ({d['status']})"
            dense = f"{d['seconds']:.2f} | {d['n_lmivar']} | {_num(d['lower'])} | {verdict}"
        elif d == "exceeds budget":
            dense = f"exceeds budget ({r['dense_estimate']}) | {r['dense_n_lmivar']} (formula) | - | -"
        else:
            dense = f"not run | {r['dense_n_lmivar']} (formula) | - | -"
        out.append(f"| {r['problem']} | {r['n']} | {_num(r['fstar'])} | {r['degree']} | {r['sparsity']} | "
                   f"{r['seconds']:.2f} | {r['n_lmivar']} | {_num(r['lower'])} | {_num(r['upper'])} | "
                   f"{'yes' if r['certified'] else 'no (' + r['status'] + ')'} | {_valid(r)} | {dense} | "
                   f"{r['n_lmivar'] / r['dense_n_lmivar']:.2e} |")
    return out


def growth(rows) -> list[str]:
    """Fitted exponents: time ~ n^a, N_LMIVAR ~ n^b per problem (least squares on logs), over the sizes
    certified at the degree of the largest one (a smaller n certified at a lower degree is left out)."""
    out = ["| problem | degree | sizes | time exponent a | N_LMIVAR exponent b |", "|---|---|---|---|---|"]
    for name in dict.fromkeys(r["problem"] for r in rows):
        rs = [r for r in rows if r["problem"] == name]
        rs = [r for r in rs if r["degree"] == rs[-1]["degree"]]
        if len(rs) < 2:
            continue
        ln = np.log([r["n"] for r in rs])
        a = np.polyfit(ln, np.log([max(r["seconds"], 1e-3) for r in rs]), 1)[0]
        b = np.polyfit(ln, np.log([r["n_lmivar"] for r in rs]), 1)[0]
        out.append(f"| {name} | {rs[-1]['degree']} | {', '.join(str(r['n']) for r in rs)} | {a:.2f} | {b:.2f} |")
    return out


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"n in {QUICK_SIZES} only (the test run)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None)
    ap.add_argument("--problems", nargs="+", choices=PROBLEMS, default=list(PROBLEMS))
    ap.add_argument("--seed", type=int, default=0, help="seed of the Ising chain's couplings")
    ap.add_argument("--no-dense", action="store_true", help="size the dense programs but do not solve them")
    ap.add_argument("--dense-time-limit", type=float, default=None,
                    help="seconds per dense call (default: the default budget's, 120; --quick: 10)")
    args = ap.parse_args(argv)
    sizes = args.sizes or (QUICK_SIZES if args.quick else SIZES)
    budget = sp.DEFAULT_BUDGET
    limit = args.dense_time_limit or (10.0 if args.quick else budget.time_limit)
    dense_budget = None if args.no_dense else sp.Budget(limit, budget.max_bytes, budget.max_gram_side)
    cmd = "python benchmarks/sparse.py" + (" " + " ".join(argv if argv is not None else sys.argv[1:])).rstrip()
    print(f"command: `{cmd}`")
    print(f"machine: {platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
          f"numpy {np.__version__}; budget: {budget}; dense calls: "
          f"{'not run' if dense_budget is None else f'time limit {dense_budget.time_limit:g} s'}\n")
    rows = []
    for name in args.problems:
        for n in sizes:
            rows.append(run_one(name, n, args.seed, budget, dense_budget))
    print("\n".join(table(rows)))
    print()
    print("\n".join(growth(rows)))
    bad = [r for r in rows if _valid(r) != "yes" or not r["certified"]]
    print(f"\n{len(rows) - len(bad)} of {len(rows)} programs certified at their known minimum")
    return rows


if __name__ == "__main__":
    rows = main()
    sys.exit(0 if all(r["certified"] and _valid(r) == "yes" for r in rows) else 1)
