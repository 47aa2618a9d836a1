"""N_LMIVAR and Gram sizes: closed forms of SPEC §8 beside the assembled programs.

    python benchmarks/complexity.py [--max-views 12] [--max-assemble-pairs 60000]

For N = 2..max-views views, delta = 2, 4, 6, Theorem 1 and Corollary 1, with all
regions points and with one uncertain region (a segment in view 1).  "formula"
is :func:`sospoly.n_lmivar_formula` fed with the constraint degrees;
"assembled" counts the independent scalars of the program actually built by
:func:`sospoly.build_psatz` (decision variables + tau of the u Gram matrix).
Theorem 1's N2 is the numerical rank of the minor matrix at
``tritools.model.constraints.RANK_RTOL`` on the normalised cameras of a random scene: for
real camera geometry its singular values spread over many decades, so N2 is
smaller than the generic rank (e.g. 50 for four views) and so is N_LMIVAR.
Programs whose u Gram matrix has more than ``--max-assemble-pairs`` upper-triangular
entries are not assembled ("too large"), and Theorem 1 needs the rank N2 of the
C(2N,4)-row minor matrix, computed up to ``--max-theorem1-views`` views.
"""
from __future__ import annotations

import argparse
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import sospoly  # noqa: E402
from sospoly import sigma  # noqa: E402
from tritools import Point, Segment  # noqa: E402
from tritools.model.normalize import normalization_for  # noqa: E402
from tritools.model.problem import build_problem  # noqa: E402
from tritools.scene import random_scene  # noqa: E402


def row(N, method, delta, uncertain, args):
    scene = random_scene(N, 1, noise_px=1.0, seed=N)
    regions = [Point(x) for x in scene.points2d[0]]
    if uncertain:
        regions[0] = Segment(scene.points2d[0][0], np.array([3.0, 1.0]))
    if method == "theorem1" and N > args.max_theorem1_views:
        return None
    norm = normalization_for(scene.cameras, regions)      # as tritools.triangulate does
    pb = build_problem(norm.cameras(scene.cameras), norm.regions(regions), method)
    nv = len(pb.gens)
    eq_deg = [g.degree for g in pb.eq]
    ineq_deg = [h.degree for h in pb.ineq]
    dmin = sospoly.delta_min(pb.f, pb.eq, pb.ineq)
    if delta < dmin:
        return dict(N=N, method=method, delta=delta, uncertain=uncertain, nv=nv, note=f"delta < delta_min={dmin}")
    formula = sospoly.n_lmivar_formula(nv, delta, eq_deg, ineq_deg)
    s = sigma(nv, delta // 2)
    pairs = s * (s + 1) // 2
    assembled = None
    if pairs <= args.max_assemble_pairs:
        assembled = sospoly.build_psatz(pb.f, pb.eq, pb.ineq, delta, gens=pb.gens).n_lmivar
    return dict(N=N, method=method, delta=delta, uncertain=uncertain, nv=nv, N2=pb.info["N2"], gram=s,
                formula=formula, assembled=assembled, note="" if assembled is not None else "too large to assemble")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--max-views", type=int, default=12)
    ap.add_argument("--max-theorem1-views", type=int, default=6)
    ap.add_argument("--max-assemble-pairs", type=int, default=60000)
    args = ap.parse_args(argv)
    print("| N | method | delta | regions | N_v | N2 | Gram size | N_LMIVAR formula | N_LMIVAR assembled | note |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    mismatches = 0
    for N in range(2, args.max_views + 1):
        for method in ("corollary1", "theorem1"):
            for delta in (2, 4, 6):
                for unc in (False, True):
                    r = row(N, method, delta, unc, args)
                    if r is None:
                        print(f"| {N} | {method} | {delta} | {'1 segment' if unc else 'points'} | | | | | | "
                              f"minor matrix C(2N,4) = {sospoly.algebra.basis.comb(2 * N, 4)} rows: not computed |")
                        continue
                    if "formula" not in r:
                        print(f"| {N} | {method} | {delta} | {'1 segment' if unc else 'points'} | {r['nv']} "
                              f"| | | | | {r['note']} |")
                        continue
                    if r["assembled"] is not None and r["assembled"] != r["formula"]:
                        mismatches += 1
                    print(f"| {N} | {method} | {delta} | {'1 segment' if unc else 'points'} | {r['nv']} | {r['N2']} | "
                          f"{r['gram']} | {r['formula']} | "
                          f"{r['assembled'] if r['assembled'] is not None else '-'} | {r['note']} |")
    print(f"\nformula != assembled in {mismatches} rows")
    return mismatches


if __name__ == "__main__":
    sys.exit(1 if main() else 0)
