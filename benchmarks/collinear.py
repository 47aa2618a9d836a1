"""Collinear camera centres (drives along the optical axis, rectified rigs): certified fraction, CPU per point and
the worst lower bound against a multi-start reference, this tree against a base (review 31a).

``drive``: N frames 0.5 m apart along their optical axis (R = I, f = 1000, 1280 x 720), centres jittered by
``--jitter`` metres (std), a point 4-30 m ahead of the last frame, 1 px noise.  ``rig``: a rectified rig, R = I,
centres 0.3 m apart on the image x axis, the point 4-15 m in front.  ``tritools.triangulate(P, x)`` with every
default; the reference is the best of Levenberg-Marquardt runs (scipy) from the true point, the returned X and five
perturbed starts (an upper bound of gamma*: ``lb-ref`` <= 0 for every valid bound).  Each cell runs in a
subprocess, this tree and ``--base`` (a source tree of another commit, e.g. ``git worktree add /tmp/base <rev>``)
alternated cell by cell; CPU is ``time.process_time`` of the calls with one BLAS thread.

    OPENBLAS_NUM_THREADS=1 python benchmarks/collinear.py --kinds drive rig --sizes 5 8 9 12 16 \
        --jitter 0 1e-4 --trials 3 [--base /tmp/base]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
K = np.array([[1000.0, 0, 640], [0, 1000, 360], [0, 0, 1]])


def scene(kind: str, N: int, jitter: float, rng):
    """(cameras (N, 3, 4), observations (N, 2), the true point) of one cell's trial (module docstring)."""
    axis = 2 if kind == "drive" else 0
    C = np.zeros((N, 3))
    C[:, axis] = (0.5 if kind == "drive" else 0.3) * np.arange(N)
    C = C + jitter * rng.standard_normal((N, 3))
    cams = np.array([K @ np.c_[np.eye(3), -c] for c in C])
    ahead = C[:, 2].max() + rng.uniform(4, 30) if kind == "drive" else rng.uniform(4, 15)
    X = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), ahead])
    h = cams @ np.append(X, 1.0)
    return cams, h[:, :2] / h[:, 2:] + rng.standard_normal((N, 2)), X


def reference(cams, x, starts) -> float:
    from scipy.optimize import least_squares

    def res(Y):
        h = cams @ np.append(Y, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()
    best = min(np.sum(least_squares(res, s, method="lm", xtol=1e-15, ftol=1e-15).fun ** 2) for s in starts)
    return float(np.sqrt(best / (2 * len(cams))))


def cell(tree: str, kind: str, N: int, jitter: float, trials: int, seed: int) -> dict:
    """One cell in this process, from the source tree ``tree``."""
    import time
    sys.path.insert(0, tree)
    import tritools
    assert tritools.__file__.startswith(tree)
    rng = np.random.default_rng([seed, N, int(jitter * 1e9)])
    cpu, cert, worst = [], 0, -np.inf
    for _ in range(trials):
        cams, x, X = scene(kind, N, jitter, rng)
        t = time.process_time()
        r = tritools.triangulate(cams, x)
        cpu.append(time.process_time() - t)
        g = reference(cams, x, [X, r.X] + [X + rng.normal(0, 1, 3) for _ in range(5)])
        cert += bool(r.optimal)
        worst = max(worst, (r.gamma_lb if r.gamma_lb is not None else 0.0) - g)
    return {"cert": cert, "trials": trials, "cpu_med": float(np.median(cpu)), "cpu_max": float(np.max(cpu)),
            "lb_ref": float(worst)}


def run_cell(tree: str, args, kind, N, jitter) -> dict:
    cmd = [sys.executable, __file__, "--cell", tree, kind, str(N), repr(jitter), str(args.trials), str(args.seed)]
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=args.timeout)
    if out.returncode != 0:
        return {"error": out.stderr.strip().splitlines()[-1] if out.stderr.strip() else f"exit {out.returncode}"}
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--kinds", nargs="+", default=["drive", "rig"], choices=["drive", "rig"])
    p.add_argument("--sizes", nargs="+", type=int, default=[5, 8, 9, 12, 16])
    p.add_argument("--jitter", nargs="+", type=float, default=[0.0, 1e-4])
    p.add_argument("--trials", type=int, default=3)
    p.add_argument("--seed", type=int, default=31)
    p.add_argument("--base", default=None, help="source tree of the commit to compare with")
    p.add_argument("--timeout", type=float, default=1200)
    p.add_argument("--cell", nargs=6, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.cell:
        tree, kind, N, jitter, trials, seed = a.cell
        print(json.dumps(cell(tree, kind, int(N), float(jitter), int(trials), int(seed))))
        return 0
    trees = [("this", ROOT)] + ([("base", a.base)] if a.base else [])
    print("kind | N | jitter [m] | tree | certified | CPU median [s] | CPU max [s] | max lb-ref")
    print("--- | --- | --- | --- | --- | --- | --- | ---")
    for kind in a.kinds:
        for jitter in (a.jitter if kind == "drive" else [0.0]):
            for N in a.sizes:
                for name, tree in trees:
                    r = run_cell(tree, a, kind, N, jitter)
                    if "error" in r:
                        print(f"{kind} | {N} | {jitter:g} | {name} | error: {r['error']} | | |")
                        continue
                    print(f"{kind} | {N} | {jitter:g} | {name} | {r['cert']}/{r['trials']} | {r['cpu_med']:.2f} | "
                          f"{r['cpu_max']:.2f} | {r['lb_ref']:.2g}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
