"""Long segments (or long thin ellipses) beside points: what is certified as a segment grows far beyond the residuals
(docs/triangulation.md, "Long segments").

Three views of ``random_scene(3, 1, 1 px, seed)``: the first two observations as points, the third as a segment of
length L through it (a random direction, the observation at a random offset within 40 % of L from its centre); with
``--shape ellipse`` a filled ellipse of that major axis and minor semi-axis ``--width`` instead.  For
each L and seed: the status, gamma_LB, gamma_UB, the wall time of the call, and gamma of the three points alone
(an upper bound of the segment problem's optimum: the segment holds the third observation).

    OPENBLAS_NUM_THREADS=1 python benchmarks/long_segments.py [--lengths 10 100 1000 10000 1e6] [--seeds 3]
        [--shape segment|ellipse] [--width 1]
"""
from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

import tritools  # noqa: E402
from tritools import Ellipse, Point, Segment  # noqa: E402
from tritools.scene import random_scene  # noqa: E402


def problem(length: float, seed: int, shape: str = "segment", width: float = 1.0):
    """(cameras, regions, observed points) of one row."""
    sc = random_scene(3, 1, noise_px=1.0, seed=seed)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)[0]
    rng = np.random.default_rng(seed)
    d = rng.normal(size=2)
    d /= np.linalg.norm(d)
    t = rng.uniform(-0.4, 0.4) * length
    if shape == "ellipse":
        n = np.array([-d[1], d[0]])
        third = Ellipse(x[2] - t * d, (length / 2) ** 2 * np.outer(d, d) + width ** 2 * np.outer(n, n))
    else:
        third = Segment(x[2] - t * d, (length / 2) * d)
    return C, [Point(x[0]), Point(x[1]), third], x


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lengths", type=float, nargs="+", default=[10, 100, 1e3, 1e4, 1e6])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--shape", choices=("segment", "ellipse"), default="segment")
    ap.add_argument("--width", type=float, default=1.0, help="the ellipse's minor semi-axis, px")
    args = ap.parse_args(argv)
    print("| L px | seed | status | gamma_LB | gamma_UB | wall s | gamma of the points |")
    print("|---:|---:|---|---:|---:|---:|---:|")
    for length in args.lengths:
        for seed in range(args.seeds):
            C, regions, x = problem(length, seed, args.shape, args.width)
            t0 = time.perf_counter()
            r = tritools.triangulate(C, regions)
            dt = time.perf_counter() - t0
            pts = tritools.triangulate(C, x).gamma_ub
            print(f"| {length:g} | {seed} | {r.status} | {r.gamma_lb:.6g} | {r.gamma_ub:.6g} | {dt:.2f} | {pts:.4g} |")


if __name__ == "__main__":
    main()
