"""Robust (TLS) certification at tight thresholds, c = k sigma, on long protocol tracks, trees side by side.

    python benchmarks/robust_tight.py --tree /tmp/main_copy --tree . --sizes 10 20 25 30 --sigmas 2 3 \
        --fractions 0 0.1 0.2 --noise 1 5 --trials 5

Scenes: :func:`tritools.scene.robust_protocol_scene` (the CVPR 2023 protocol of benchmarks/robust.py), the rng
seeded 7 per cell; threshold c = k * noise px.  Every cell runs in one subprocess per tree, the trees interleaved
cell by cell (same load), with ``PYTHONPATH`` set to the tree.  Columns per tree: certified count and the median /
max CPU seconds per call (``time.process_time``), statuses of the uncertified calls.
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys

log = logging.getLogger("robust_tight")

CELL = r"""
import json, sys, time
import numpy as np
import tritools
assert tritools.__file__.startswith(sys.argv[2]), (tritools.__file__, sys.argv[2])
from tritools.scene import robust_protocol_scene
N, n_out, noise, c, trials, limit = json.loads(sys.argv[1])
rng = np.random.default_rng(7)
out = []
for _ in range(trials):
    P, obs, *_ = robust_protocol_scene(N, n_out, noise, rng)
    t0 = time.process_time()
    r = tritools.triangulate(P, obs, robust=c, time_limit=limit)
    out.append([bool(r.optimal), time.process_time() - t0, r.status.value])
print(json.dumps(out))
"""


def run_cell(tree: str, N: int, frac: float, noise: float, c: float, trials: int, limit: float) -> list:
    env = dict(os.environ, PYTHONPATH=os.path.abspath(tree), OPENBLAS_NUM_THREADS="1")
    arg = json.dumps([N, int(round(frac * N)), noise, c, trials, limit])
    res = subprocess.run([sys.executable, "-c", CELL, arg, os.path.abspath(tree)], env=env, capture_output=True,
                         text=True, check=True, cwd=os.path.abspath(tree))   # sys.path[0] = cwd: the tree
    return json.loads(res.stdout.strip().splitlines()[-1])


def summary(rows: list) -> str:
    t = sorted(r[1] for r in rows)
    med = t[len(t) // 2] if len(t) % 2 else 0.5 * (t[len(t) // 2 - 1] + t[len(t) // 2])
    bad = {}
    for ok, _, st in rows:
        if not ok:
            bad[st] = bad.get(st, 0) + 1
    extra = " " + ",".join(f"{k}:{v}" for k, v in bad.items()) if bad else ""
    return f"{sum(r[0] for r in rows)}/{len(rows)} {med:.3f}/{t[-1]:.2f}s{extra}"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--tree", action="append", required=True, help="a source tree (repeat: side by side)")
    ap.add_argument("--sizes", type=int, nargs="+", default=[10, 20, 25, 30])
    ap.add_argument("--sigmas", type=float, nargs="+", default=[2.0, 3.0])
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.0, 0.1, 0.2])
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0, 5.0])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--time-limit", type=float, default=30.0)
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    log.info("| N | noise | c | outliers | " + " | ".join(f"{t}: cert, med/max CPU" for t in a.tree) + " |")
    log.info("|---" * (4 + len(a.tree)) + "|")
    for N in a.sizes:
        for noise in a.noise:
            for k in a.sigmas:
                for frac in a.fractions:
                    cols = [summary(run_cell(t, N, frac, noise, k * noise, a.trials, a.time_limit)) for t in a.tree]
                    log.info(f"| {N} | {noise:g} | {k * noise:g} ({k:g} sigma) | {frac:.0%} | " + " | ".join(cols)
                             + " |")


if __name__ == "__main__":
    main()
