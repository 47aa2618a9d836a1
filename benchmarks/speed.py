"""Speed of certified triangulation on Example 1 (Oxford data), one run, same points (issue #5).

    python benchmarks/speed.py                 # 10 tracks per N for the per-point methods
    python benchmarks/speed.py --limit 3       # quick
    python benchmarks/speed.py --full          # every method on all 8956 tracks (naive cvxpy: --cvxpy-limit)

Columns per N (ms per point): the vectorised fast path (tritools.solve.fastpath over *all* tracks
of that N), the SDP path (``triangulate(..., path="sdp")``), a naive per-point cvxpy build
of the same delta = 2 SDP solved by Clarabel, the scipy local methods of tritools.baselines
(Newton, Nelder-Mead, SQP), DLT, pycolmap's multi-view triangulation when installed, and
the paper's ACT (Tables 1-6, mean over the sequences weighted by #cases).  Then: the whole
of Example 1 through ``triangulate_many`` (path auto; and first, path sdp: the batched
delta = 2 SDP of tritools.solve.sdp_batch, in-process, per N and whole), Theorem 1 at delta = 4 on Example 4
(first solve vs later solves) and on Example 5 cases (new data, same structure), and the peak memory
of a full Example 1 run.

BLAS is limited to one thread (OPENBLAS_NUM_THREADS=1, set before numpy is imported): the
fast path works on stacks of small matrices, where BLAS threads only add contention.
Times are wall-clock on a shared machine: noisy.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ["RUST_BACKTRACE"] = "0"
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, os.path.dirname(__file__))

import numpy as np  # noqa: E402

import tritools  # noqa: E402
from tritools import Point  # noqa: E402
from tritools import baselines as B  # noqa: E402
from tritools.solve.fastpath import verify_points  # noqa: E402
from tritools.io.oxford import PAPER_SEQUENCES, load_sequence  # noqa: E402

from example1 import PAPER, PAPER_TABLE7  # noqa: E402


def load_tracks(data_dir):
    """{N: [(cameras, points2d), ...]} over the six sequences of Example 1."""
    groups: dict[int, list] = {}
    for name in PAPER_SEQUENCES:
        seq = load_sequence(name, data_dir)
        for tr in seq.tracks:
            groups.setdefault(tr.n_views, []).append(seq.problem(tr))
    return dict(sorted(groups.items()))


def paper_act() -> dict:
    """N -> the paper's ACT [s], mean over the sequences weighted by #cases."""
    acc: dict[int, list] = {}
    for rows in PAPER.values():
        for N, (cases, *_rest, act) in rows.items():
            acc.setdefault(N, []).append((cases, act))
    return {N: sum(c * a for c, a in v) / sum(c for c, _ in v) for N, v in acc.items()}


def naive_cvxpy(cams, pts) -> float:
    """Build the delta = 2 Corollary 1 SDP from scratch with cvxpy and solve it with Clarabel: c*.

    max c s.t. [[L0 - c, L1'/2], [L1/2, L2]] PSD, L = f + sum_k lambda_k g_k (normalised data)."""
    import cvxpy as cp

    from sospoly.analysis.verify import quadratic_parts
    from tritools.model.normalize import normalization_for
    from tritools.model.problem import build_problem

    regions = [Point(p) for p in pts]
    norm = normalization_for(cams, regions)
    prob = build_problem(norm.cameras(cams), norm.regions(regions), "corollary1")
    f0, f1, F2 = quadratic_parts(prob.f, prob.gens)
    parts = [quadratic_parts(g, prob.gens) for g in prob.eq]
    lam = cp.Variable(len(parts))
    c = cp.Variable()
    L0 = f0 + sum(lam[k] * p[0] for k, p in enumerate(parts))
    L1 = f1 + sum(lam[k] * p[1] for k, p in enumerate(parts))
    L2 = F2 + sum(lam[k] * p[2] for k, p in enumerate(parts))
    G = cp.bmat([[cp.reshape(L0 - c, (1, 1), order="C"), cp.reshape(L1, (1, len(f1)), order="C") / 2],
                 [cp.reshape(L1, (len(f1), 1), order="C") / 2, L2]])
    problem = cp.Problem(cp.Maximize(c), [(G + G.T) / 2 >> 0])
    problem.solve(solver=cp.CLARABEL)
    return float(c.value)


def timed(fn, items) -> float:
    """Mean seconds per item of fn(cams, pts) (exceptions count as calls)."""
    if not items:
        return float("nan")
    t0 = time.perf_counter()
    for cams, pts in items:
        try:
            fn(cams, pts)
        except Exception:  # noqa: BLE001 - a failed solve still took its time (e.g. cvxpy SolverError)
            pass
    return (time.perf_counter() - t0) / len(items)


def fast_path_table(groups, repeats=3):
    """N -> (count, certified, best seconds) of verify_points on every track of that N."""
    out = {}
    for N, items in groups.items():
        C = np.array([c for c, _ in items])
        x = np.array([p for _, p in items])
        best, cert = np.inf, 0
        for _ in range(repeats):
            t0 = time.perf_counter()
            b = verify_points(C, x)
            best = min(best, time.perf_counter() - t0)
            cert = int(b.certified.sum())
        out[N] = (len(items), cert, best)
    return out


def example4_theorem1(repeats=3):
    cams, regions = tritools.paper_example(4)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r = tritools.triangulate(cams, regions, "theorem1", 4)
        times.append(time.perf_counter() - t0)
    return times, r


def example5_theorem1(n_cases=8):
    """Theorem 1 delta=4 on Example 5 cases: new data in Example 4's structure (compiled once)."""
    cases = tritools.scene.example5_cases(seed=0, n_points=2, thetas=(0.05, 0.1, 0.15, 0.2), trials=1)[:n_cases]
    times, certified = [], 0
    for case in cases:
        t0 = time.perf_counter()
        r = tritools.triangulate(case.cameras, case.regions, "theorem1", 4)
        times.append(time.perf_counter() - t0)
        certified += r.status == tritools.Status.OPTIMAL
    return times, certified


class InlineExecutor:
    """A concurrent.futures-style executor that runs each task at once in this process (triangulate_many
    would otherwise start a spawn process pool for >= LOCAL_PROCESS_MIN_ITEMS per-point items)."""

    def submit(self, fn, *args, **kw):
        import concurrent.futures as cf

        fut = cf.Future()
        try:
            fut.set_result(fn(*args, **kw))
        except Exception as exc:  # noqa: BLE001 - reported through the future, as an executor does
            fut.set_exception(exc)
        return fut


def sdp_batch_example1(problems):
    """All of Example 1 (``problems``: N -> point problems) through triangulate_many(path="sdp") at delta = 2,
    single process: the batched SDP (tritools.solve.sdp_batch) with per-point fallbacks; per N and whole."""
    paper_s = PAPER_TABLE7["corollary1"][2]        # Table 7: s per point
    print("\n## triangulate_many(problems, 'corollary1', 2, 2, path='sdp', executor=in-process), per N\n")
    print("| N | #tracks | ms/point | #certified | #per-point fallbacks |")
    print("|---|---|---|---|---|")
    for N, probs in problems.items():
        t0 = time.perf_counter()
        res = tritools.triangulate_many(probs, "corollary1", 2, 2, path="sdp", executor=InlineExecutor(),
                                        progress=False)
        t = time.perf_counter() - t0
        fb = sum(not (r.attempts and r.attempts[0].solver == ("ipm-batch:converged",)) for r in res)
        print(f"| {N} | {len(probs)} | {1000 * t / len(probs):.3f} | {sum(r.optimal for r in res)} | {fb} |")
    everything = [p for probs in problems.values() for p in probs]
    t0 = time.perf_counter()
    res = tritools.triangulate_many(everything, "corollary1", 2, 2, path="sdp", executor=InlineExecutor(),
                                    progress=False)
    wall = time.perf_counter() - t0
    n = len(everything)
    cert = sum(r.optimal for r in res)
    print(f"\nWhole Example 1 in one call: {n} tracks, {wall:.2f} s ({1000 * wall / n:.3f} ms/point, "
          f"{wall / n / paper_s:.3f} x the paper's {paper_s} s/point), {cert} certified "
          f"({sum(r.certified_by == 'sdp' for r in res)} by the SDP)")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data-dir", default=None)
    ap.add_argument("--limit", type=int, default=10, help="tracks per N for the per-point methods")
    ap.add_argument("--full", action="store_true", help="all 8956 tracks for every per-point method")
    ap.add_argument("--cvxpy-limit", type=int, default=3, help="tracks per N for the naive cvxpy build")
    ap.add_argument("--skip-memory", action="store_true")
    ap.add_argument("--sdp-batch-only", action="store_true",
                    help="only Example 1 through triangulate_many(path='sdp') (batched delta-2 SDP)")
    args = ap.parse_args(argv)
    groups = load_tracks(args.data_dir)
    problems = {N: [(c, [Point(p) for p in x]) for c, x in items] for N, items in groups.items()}
    sdp_batch_example1(problems)
    if args.sdp_batch_only:
        return
    total = sum(map(len, groups.values()))
    act = paper_act()
    have_colmap = importlib.util.find_spec("pycolmap") is not None

    fast = fast_path_table(groups)
    fast_total = sum(t for _, _, t in fast.values())
    print(f"## Fast path (tritools.solve.fastpath.verify_points, vectorised per N): {total} tracks, "
          f"{sum(c for _, c, _ in fast.values())} certified, {fast_total:.3f} s "
          f"({1000 * fast_total / total:.4f} ms/track; best of 3)\n")

    def sdp(cams, pts):
        return tritools.triangulate(cams, [Point(p) for p in pts], "corollary1", 2, 2, path="sdp")

    def local(method):
        return lambda cams, pts: method(cams, [Point(p) for p in pts])

    methods = [("SDP path", sdp), ("newton", local(B.newton)), ("nms", local(B.nelder_mead)), ("sqp", local(B.sqp)),
               ("dlt", local(B.dlt_baseline))]
    if have_colmap:
        methods.append(("pycolmap", local(B.pycolmap_multiview)))
    warm = groups[min(groups)][0]        # first calls pay imports and cvxpy's set-up: not timed
    timed(naive_cvxpy, [warm])
    for _, fn in methods:
        timed(fn, [warm])
    head = ["N", "#tracks", "fast [ms]", "#sampled"] + [f"{m} [ms]" for m, _ in methods] + \
        ["naive cvxpy [ms]", "paper ACT [ms]", "SDP/fast", "cvxpy/fast", "paper/fast"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    sums = {m: 0.0 for m, _ in methods}
    sums["cvxpy"] = sums["paper"] = 0.0
    for N, items in groups.items():
        sample = items if args.full else items[: args.limit]
        cnt, _, tf = fast[N]
        fast_ms = 1000 * tf / cnt
        row = [str(N), str(cnt), f"{fast_ms:.4f}", str(len(sample))]
        per = {}
        for name, fn in methods:
            per[name] = 1000 * timed(fn, sample)
            sums[name] += per[name] * cnt
            row.append(f"{per[name]:.3f}")
        cv = 1000 * timed(naive_cvxpy, items[: args.cvxpy_limit])
        sums["cvxpy"] += cv * cnt
        pa = 1000 * act.get(N, np.nan)
        sums["paper"] += (pa if np.isfinite(pa) else 0.0) * cnt
        row += [f"{cv:.1f}", f"{pa:.0f}" if np.isfinite(pa) else "-", f"{per['SDP path'] / fast_ms:.0f}",
                f"{cv / fast_ms:.0f}", f"{pa / fast_ms:.0f}" if np.isfinite(pa) else "-"]
        print("| " + " | ".join(row) + " |")
    print(f"\nAll {total} tracks (per-N means x counts): fast {fast_total:.2f} s; " +
          "; ".join(f"{m} {sums[m] / 1000:.1f} s" for m in sums) + " (estimated from the sampled means)")

    everything = [p for probs in problems.values() for p in probs]
    t0 = time.perf_counter()
    res = tritools.triangulate_many(everything, "corollary1", path="auto", progress=False)
    wall = time.perf_counter() - t0
    by = {}
    for r in res:
        by[(r.status.value, r.certified_by)] = by.get((r.status.value, r.certified_by), 0) + 1
    print(f"\n## triangulate_many(path='auto') on all {total} tracks: {wall:.2f} s wall "
          f"(fast path, result objects, and the SDP fallbacks at delta 2 then 4): {by}")

    times, r4 = example4_theorem1()
    print(f"\n## Example 4, Theorem 1 delta=4 (N_LMIVAR {r4.n_lmivar}, {r4.status.value}, gamma {r4.gamma_ub:.3f}): "
          f"first solve {times[0]:.3f} s, later solves " + ", ".join(f"{t:.3f}" for t in times[1:]) + " s")
    t5, c5 = example5_theorem1()
    print(f"   Example 5 cases (same structure, new data): median {np.median(t5):.3f} s, max {max(t5):.3f} s, "
          f"{c5}/{len(t5)} certified")

    if not args.skip_memory:
        import resource
        import tracemalloc

        tracemalloc.start()
        tritools.triangulate_many(everything, "corollary1", path="auto", progress=False)
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        print(f"\n## Peak memory of a full Example 1 run (triangulate_many, path auto): Python allocations "
              f"{peak / 2**20:.1f} MiB (tracemalloc), process max RSS {rss:.0f} MiB (includes this benchmark's data)")


if __name__ == "__main__":
    main()
