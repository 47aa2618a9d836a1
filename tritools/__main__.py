"""Command line: ``python -m tritools example K`` reproduces the paper's Example K (2, 3, 4).

Prints, for Theorem 1 (delta = 4) and Corollary 1 (delta = 2, then 4), the
estimate, gamma_LB, gamma_UB, the certificate and N_LMIVAR beside the paper's
printed values.  Exit code 2 with a one-line message on bad arguments.
"""
from __future__ import annotations

import argparse
import json
import os
import sys


def _example(args) -> int:
    from .scene import paper_example, paper_table
    from .triangulate import triangulate

    cams, regions = paper_example(args.k)
    paper = {(r["method"], r.get("delta")): r for r in paper_table(args.k)}
    rows = [("theorem1", 4), ("corollary1", 2), ("corollary1", 4)]
    out = []
    for method, delta in rows:
        r = triangulate(cams, regions, method, delta=delta)
        p = paper[(method, delta)]
        out.append({"method": method, "delta": delta, "X": None if r.X is None else r.X.round(6).tolist(),
                    "gamma_lb": r.gamma_lb, "gamma_ub": r.gamma_ub, "optimal": bool(r.optimal),
                    "n_lmivar": r.n_lmivar, "seconds": round(r.timings.get("total", float("nan")), 3),
                    "paper": {"X": p["X"], "gamma": p["gamma"], "optimal": p["optimal"], "n_lmivar": p["n_lmivar"]}})
    if args.json:
        print(json.dumps(out, indent=1))
        return 0
    print(f"Example {args.k} of Chesi (2026): certified multiple-view L2 triangulation")
    print(f"{'method':<16}{'X^':<30}{'gamma_LB':>10}{'gamma_UB':>10}{'optimal':>9}{'N_LMIVAR':>10}   paper: X^, gamma, optimal, N_LMIVAR")
    for o in out:
        X = "NA" if o["X"] is None else "(" + ", ".join(f"{v:.3f}" if abs(v) < 1e4 else f"{v:.2e}" for v in o["X"]) + ")"
        p = o["paper"]
        print(f"{o['method'] + ' d=' + str(o['delta']):<16}{X:<30}{o['gamma_lb']:>10.3f}{o['gamma_ub']:>10.3f}"
              f"{'yes' if o['optimal'] else 'no':>9}{o['n_lmivar']:>10}   "
              f"({', '.join(f'{v:.3f}' for v in p['X'])}), {p['gamma']:.3f}, {'yes' if p['optimal'] else 'no'}, {p['n_lmivar']}")
    return 0


def main(argv=None) -> int:
    os.environ.setdefault("RUST_BACKTRACE", "0")
    ap = argparse.ArgumentParser(prog="tritools", description="certified multiple-view L2 triangulation")
    sub = ap.add_subparsers(dest="command", required=True)
    ex = sub.add_parser("example", help="reproduce the paper's Example 2, 3 or 4")
    ex.add_argument("k", type=int, choices=(2, 3, 4))
    ex.add_argument("--json", action="store_true", help="machine-readable output")
    args = ap.parse_args(argv)
    if args.command == "example":
        return _example(args)
    return 2  # pragma: no cover


if __name__ == "__main__":
    sys.exit(main())
