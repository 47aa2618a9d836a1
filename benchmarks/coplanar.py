"""Coplanar camera centres (turntable) benchmark: certified fraction and CPU per point, this tree against a base.

Cameras on a horizontal circle of radius 2 looking at the origin (the robust protocol's intrinsics), the point
uniform in [-0.5, 0.5]^2 x [-z, z], 1 px noise; ``plain`` = ``tritools.triangulate(P, x)`` on clean tracks,
``robust`` = ``robust=4`` px with 30% outliers (uniform image points), ``robust-clean`` the same call on clean
tracks.  Each cell runs in a subprocess, this
tree and ``--base`` (a source tree of another commit, e.g. a ``git archive`` of main) alternated cell by cell;
CPU is ``time.process_time`` of the calls with one BLAS thread.

    OPENBLAS_NUM_THREADS=1 python benchmarks/coplanar.py --sizes 5 6 10 20 --z 0 0.01 0.05 --trials 5 \
        [--base /tmp/main --base-max-n 10]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def circle_cameras(N, rng, K):
    """``tritools.scene.turntable_cameras`` without the jitter draw, written out here so that a ``--base`` tree
    older than that generator gets the same cameras as this tree."""
    P = []
    for k in range(N):
        a = 2 * np.pi * k / N + rng.uniform(-0.2, 0.2)
        c = np.array([2 * np.cos(a), 2 * np.sin(a), 0.0])
        z = -c / np.linalg.norm(c)
        ax = np.cross([0.0, 0.0, 1.0], z)
        ax /= np.linalg.norm(ax)
        R = np.stack([ax, np.cross(z, ax), z])
        P.append(K @ np.hstack([R, -R @ c[:, None]]))
    return np.array(P)


def run_cell(N: int, z: float, mode: str, trials: int) -> dict:
    """The cell in this process: certified count and CPU seconds per point."""
    import tritools
    from tritools.scene import PROTOCOL_IMAGE, PROTOCOL_K

    rng = np.random.default_rng(N)
    cert, cpu = 0, []
    for _ in range(trials):
        P = circle_cameras(N, rng, PROTOCOL_K)
        X = rng.uniform(-0.5, 0.5, 3)
        X[2] = rng.uniform(-z, z)
        h = P @ np.append(X, 1.0)
        obs = h[:, :2] / h[:, 2:] + rng.normal(size=(N, 2))
        if mode == "robust":                    # "robust-clean": the same call on clean tracks
            out = rng.choice(N, max(1, int(0.3 * N)), replace=False)
            obs[out] = rng.uniform([0, 0], PROTOCOL_IMAGE, size=(len(out), 2))
        t0 = time.process_time()
        r = tritools.triangulate(P, obs) if mode == "plain" else tritools.triangulate(P, obs, robust=4.0)
        cpu.append(time.process_time() - t0)
        cert += bool(r.optimal)
    return {"certified": cert, "trials": trials, "median": float(np.median(cpu)), "max": float(np.max(cpu))}


def in_subprocess(root: str, N: int, z: float, mode: str, trials: int) -> dict:
    env = dict(os.environ, PYTHONPATH=root, OPENBLAS_NUM_THREADS="1")
    code = (f"import sys, json; sys.path.insert(0, {ROOT!r} + '/benchmarks'); import coplanar, tritools; "
            f"assert tritools.__file__.startswith({os.path.abspath(root)!r}), tritools.__file__; "
            f"print(json.dumps(coplanar.run_cell({N}, {z}, {mode!r}, {trials})))")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True,
                         cwd=root)                        # "-c" puts the working directory first on sys.path
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[5, 6, 10, 20])
    ap.add_argument("--z", type=float, nargs="+", default=[0.0, 0.01, 0.05])
    ap.add_argument("--modes", nargs="+", default=["plain", "robust"], choices=["plain", "robust", "robust-clean"])
    ap.add_argument("--trials", type=int, default=5)
    ap.add_argument("--base", default=None, help="source tree of the base commit (its cells alternate with ours)")
    ap.add_argument("--base-max-n", type=int, default=10, help="run the base only up to this N (it takes minutes)")
    a = ap.parse_args(argv)
    print("mode | z | N | certified (this) | CPU median / max s (this) | certified (base) | CPU median / max (base)")
    print("--- | --- | --- | --- | --- | --- | ---")
    for mode in a.modes:
        for z in a.z:
            for N in a.sizes:
                ours = in_subprocess(ROOT, N, z, mode, a.trials)
                base = in_subprocess(a.base, N, z, mode, a.trials) if a.base and N <= a.base_max_n else None
                b = (f"{base['certified']}/{base['trials']} | {base['median']:.2f} / {base['max']:.2f}" if base
                     else "- | -")
                print(f"{mode} | {z:g} | {N} | {ours['certified']}/{ours['trials']} | "
                      f"{ours['median']:.2f} / {ours['max']:.2f} | {b}", flush=True)


if __name__ == "__main__":
    main()
