"""Fixed cost of one ``tritools.triangulate()`` call against the per-track cost of ``triangulate_many`` (issue #22).

    python benchmarks/singlecall.py                               # synthetic tracks, quick (~20 s)
    python benchmarks/singlecall.py --oxford ../shared/data/oxford  # + Oxford point tracks (every 40th of Example 1)
    python benchmarks/singlecall.py --calls                       # + Python-level calls per call (cProfile)

Synthetic rows: seeded ``random_scene(N, points, 1 px)`` point tracks (N = 2, 5, 10) and the same keypoints of a
5-view scene as 1 px discs; "own cameras" rows give every track its own camera array (the scene's cameras times
1 + j/1000 for track j: the same projections, other bytes), so a single call cannot reuse the camera-only work
it remembers for the last cameras (:mod:`tritools.solve.fastpath_cameras`), as on Oxford tracks.  ``single`` is
the 10th percentile of the CPU time of one call (``time.process_time``, one BLAS thread: the low percentile is the
least disturbed by other jobs on a shared machine), ``many`` the best per-track CPU time of ``triangulate_many``
over the repeats.  Times on a shared machine are noisy: compare runs of
two branches interleaved.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import statistics
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

import tritools  # noqa: E402
from tritools import Ellipse, Point  # noqa: E402
from tritools.scene import random_scene  # noqa: E402


def synthetic_tracks(n_points: int) -> dict:
    """{name: (cameras or a list of one camera array per track, [regions of one track, ...])}."""
    out = {}
    for N in (2, 5, 10):
        sc = random_scene(N, n_points, noise_px=1.0, seed=N)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
        out[f"points N = {N}"] = (C, [x[j] for j in range(n_points)])
        if N < 10:
            out[f"points N = {N}, own cameras"] = ([C * (1 + j / 1000) for j in range(n_points)],
                                                   [x[j] for j in range(n_points)])
    sc = random_scene(5, n_points, noise_px=1.0, seed=55)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    out["1 px discs N = 5"] = (C, [[Ellipse(p, np.eye(2)) for p in x[j]] for j in range(n_points)])
    return out


def cpu_of(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def _cameras_of(C, n: int) -> list:
    return C if isinstance(C, list) else [C] * n


def single_and_many(C, tracks, repeats: int) -> tuple[float, float]:
    """(10th percentile of one call, best per-track time of triangulate_many), CPU ms."""
    cams = _cameras_of(C, len(tracks))
    for c, r in zip(cams[:3], tracks[:3]):                  # imports and first-call costs are not timed
        tritools.triangulate(c, r)
    singles = [cpu_of(lambda: tritools.triangulate(c, r)) for _ in range(repeats) for c, r in zip(cams, tracks)]
    probs = list(zip(cams, tracks))
    many = min(cpu_of(lambda: tritools.triangulate_many(probs, progress=False)) for _ in range(repeats))
    return float(np.percentile(singles, 10)) * 1e3, many / len(probs) * 1e3


def calls_per_call(C, tracks) -> float:
    """Python-level function calls (cProfile) per triangulate(): a measure of the fixed cost that load does not move."""
    cams = _cameras_of(C, len(tracks))
    tritools.triangulate(cams[-1], tracks[-1])
    pr = cProfile.Profile()
    pr.enable()
    for c, r in zip(cams, tracks):
        tritools.triangulate(c, r)
    pr.disable()
    return pstats.Stats(pr).total_calls / len(tracks)


def oxford_row(data_dir: str) -> tuple[int, float, float]:
    """(#tracks, median single call, triangulate_many per track) on every 40th track of Example 1, CPU ms."""
    from tritools.io.oxford import PAPER_SEQUENCES, load_sequence

    probs = []
    for name in PAPER_SEQUENCES:
        seq = load_sequence(name, data_dir)
        probs += [tuple(np.asarray(a) for a in seq.problem(tr)) for tr in seq.tracks[::40]]
    for c, x in probs[:5]:
        tritools.triangulate(c, x)
    single = statistics.median(cpu_of(lambda: tritools.triangulate(c, x)) for c, x in probs)
    items = [(c, [Point(p) for p in x]) for c, x in probs]
    many = min(cpu_of(lambda: tritools.triangulate_many(items, progress=False)) for _ in range(3)) / len(items)
    return len(probs), single * 1e3, many * 1e3


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, default=40, help="tracks per synthetic row")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--oxford", metavar="DATA_DIR", default=None, help="also the Oxford point tracks")
    ap.add_argument("--calls", action="store_true", help="also the Python-level calls per triangulate()")
    args = ap.parse_args(argv)
    print("| track | single ms | many ms/track | ratio |" + (" calls/call |" if args.calls else ""))
    print("|---|---:|---:|---:|" + ("---:|" if args.calls else ""))
    for name, (C, tracks) in synthetic_tracks(args.points).items():
        single, many = single_and_many(C, tracks, args.repeats)
        extra = f" {calls_per_call(C, tracks[:10]):.0f} |" if args.calls else ""
        print(f"| {name} | {single:.2f} | {many:.3f} | {single / many:.1f} |" + extra)
    if args.oxford:
        n, single, many = oxford_row(args.oxford)
        print(f"| Oxford, {n} point tracks (median) | {single:.2f} | {many:.3f} | {single / many:.1f} |")


if __name__ == "__main__":
    main()
