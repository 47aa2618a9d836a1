"""Uncertain triangulation with many views (issue #12): the default ``tritools.triangulate`` beside the
paper's dense certificates, on seeded random scenes, and the paper's Examples 2-5 through the default.

    python benchmarks/manyview.py                       # the RESULTS.md run (about 30 min on 2 cores)
    python benchmarks/manyview.py --quick               # N = 3, 4, 10; 3 seeds; no dense degree 4
    python benchmarks/manyview.py --sizes 4 10 --seeds 8 --settings large

Scenes: :func:`tritools.scene.uncertain_problem` (cameras on a sphere of radius 10 around the scene,
focal 800 px, 640 x 480 images), one region per view drawn from point / segment / ellipse / ellipse
border / rotated box ("mixed") or all points ("points"), in two settings:

* ``small`` -- 1 px noise, regions of ~0.5 px (the generator's default);
* ``large`` -- 16 px noise (0.02 f), regions of ~16 px: the regime where the paper's economical degree-2
  certificate rarely certifies and the regions matter.

Columns per (setting, kinds, N), over the seeds:

* ``default``: ``tritools.triangulate(cameras, regions)`` with every default (method auto: Corollary 1 at
  degree 2, then degree 4 dense while the Gram side is at most 45, else the views formulation -- a cyclic
  band of view pairs beside the dense degree-2 certificate; 60 s / 2 GiB budget per point): certified
  fraction, median and max wall time, median and max process CPU time (``time.process_time``: the figure
  to compare on a loaded machine), max peak RSS of the process, median N_LMIVAR of the last step;
* ``deg-2``: the fraction the degree-2 certificate alone certifies (the default's first step; ``--no-deg2``
  skips it);
* ``dense-4``: Corollary 1 at degree 4 with the dense (paper's) certificate under the same budget and a
  ``--dense-time`` limit, run while N <= ``--dense-max`` (above it "not run": the program is sized in
  closed form and exceeds the budget or the time limit by far): certified fraction, median time, and the
  statuses that are not ``optimal``/``not_certified``;
* ``lb<=ref``: every reported gamma_LB is checked against an independent attained value (bounded
  least-squares multistart over X with exact distances to the regions, :func:`reference_gamma`);
  the column shows the largest gamma_LB - reference (<= 0 up to round-off when sound).

Every problem runs in a fresh worker process (``max_tasks_per_child=1``), so the peak RSS (VmHWM) is the
problem's own (it includes the ~150 MB of the interpreter and imports).  A last table fits
time ~ N^a over the sizes of the default column.
"""
from __future__ import annotations

import argparse
import multiprocessing
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

SIZES = (3, 4, 6, 8, 10, 12, 16, 20, 24, 30)
QUICK_SIZES = (3, 4, 10)
SETTINGS = {"small": dict(noise_px=1.0, size_px=0.5), "large": dict(noise_px=16.0, size_px=16.0)}


# ----------------------------------------------------------------------------- reference and one problem
def reference_gamma(cams, regions, X0, starts: int = 24, seed: int = 0) -> float:
    """An attained gamma (an upper bound of gamma*): bounded least squares over X from perturbed starts around
    ``X0`` and the DLT-free true point, with exact point-to-region distances (``Region.closest_point``)."""
    from scipy.optimize import least_squares

    rng = np.random.default_rng(seed)

    def residuals(X):
        h = cams @ np.append(X, 1.0)
        p = h[:, :2] / h[:, 2:]
        return np.concatenate([p[i] - regions[i].closest_point(p[i]) for i in range(len(regions))])

    best = np.inf
    for k in range(starts):
        s = np.asarray(X0, float) + rng.normal(scale=0.02 * (1 + k), size=3)
        try:
            r = least_squares(residuals, s, xtol=1e-14, ftol=1e-14, gtol=1e-14, max_nfev=400)
        except ValueError:
            continue
        if np.all(np.isfinite(r.fun)):
            best = min(best, float(np.sqrt(np.mean(r.fun ** 2))))
    return best


def _peak_rss_mb() -> float:
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmHWM:"):
                    return float(line.split()[1]) / 1024
    except OSError:
        pass
    import resource
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def run_one(job: dict) -> dict:
    """One problem in a fresh process: {'status', 'optimal', 'gamma_lb', 'gamma_ub', 'seconds', 'rss_mb', ...}."""
    import tritools
    from tritools.scene import uncertain_problem

    kinds = "point" if job["kinds"] == "points" else "mixed"
    cams, regs, X = uncertain_problem(job["n"], job["seed"], kinds=kinds, **SETTINGS[job["setting"]])
    t, cpu = time.perf_counter(), time.process_time()
    if job["variant"] == "default":
        r = tritools.triangulate(cams, regs, **({} if job.get("time_limit") is None else
                                                {"time_limit": job["time_limit"]}))
    elif job["variant"] == "deg2":
        r = tritools.triangulate(cams, regs, "corollary1", delta=2)
    else:
        r = tritools.triangulate(cams, regs, "corollary1", delta=4, sparsity="none", time_limit=job["dense_time"])
    secs, cpu = time.perf_counter() - t, time.process_time() - cpu
    out = dict(job, status=r.status.value, optimal=bool(r.optimal), gamma_lb=r.gamma_lb, gamma_ub=r.gamma_ub,
               seconds=secs, cpu_seconds=cpu, rss_mb=_peak_rss_mb(), n_lmivar=r.n_lmivar, delta=r.delta,
               sparsity=r.sparsity)
    if job["variant"] == "default" and r.gamma_lb is not None:
        out["reference"] = min(reference_gamma(cams, regs, X), r.gamma_ub if r.gamma_ub is not None else np.inf)
    return out


# ----------------------------------------------------------------------------- tables
def _fmt(v, spec=".1f", none="-"):
    return none if v is None or (isinstance(v, float) and not np.isfinite(v)) else format(v, spec)


def scene_table(rows: list[dict], sizes, settings, kinds_list, dense_max: int) -> list[str]:
    out = ["| setting | regions | N | default certified | median s | max s | median CPU s | max CPU s | peak RSS MB | "
           "N_LMIVAR | deg-2 certified | dense-4 certified | dense-4 median s | dense-4 other | max lb-ref (px) |",
           "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|---:|"]
    for setting in settings:
        for kinds in kinds_list:
            for n in sizes:
                sel = [r for r in rows if r["setting"] == setting and r["kinds"] == kinds and r["n"] == n]
                d = [r for r in sel if r["variant"] == "default"]
                if not d:
                    continue
                d2 = [r for r in sel if r["variant"] == "deg2"]
                dn = [r for r in sel if r["variant"] == "dense4"]
                secs, cpus = [r["seconds"] for r in d], [r["cpu_seconds"] for r in d]
                lmi = [r["n_lmivar"] for r in d if r["n_lmivar"]]
                gaps = [r["gamma_lb"] - r["reference"] for r in d if r.get("reference") is not None
                        and np.isfinite(r["reference"])]
                other = sorted({r["status"] for r in dn} - {"optimal", "not_certified"})
                dense_cert = f"{sum(r['optimal'] for r in dn)}/{len(dn)}" if dn else \
                    ("not run" if n > dense_max else "-")
                out.append(f"| {setting} | {kinds} | {n} | {sum(r['optimal'] for r in d)}/{len(d)} | "
                           f"{np.median(secs):.1f} | {max(secs):.1f} | {np.median(cpus):.2f} | {max(cpus):.2f} | "
                           f"{max(r['rss_mb'] for r in d):.0f} | "
                           f"{int(np.median(lmi)) if lmi else '-'} | "
                           f"{_fmt_share(d2)} | {dense_cert} | "
                           f"{_fmt(float(np.median([r['seconds'] for r in dn])) if dn else None)} | "
                           f"{', '.join(other) or '-'} | {_fmt(max(gaps) if gaps else None, '.1e')} |")
    return out


def _exponent(rows: list[dict], setting: str, kinds: str, key: str):
    """(a, N_min, N_max) of the least-squares fit log(median ``key``) ~ a log N over N >= 6, or None."""
    pts = {}
    for r in rows:
        if r["variant"] == "default" and r["setting"] == setting and r["kinds"] == kinds and r["n"] >= 6:
            pts.setdefault(r["n"], []).append(r[key])
    if len(pts) < 2:
        return None
    ns = np.array(sorted(pts))
    ts = np.array([np.median(pts[n]) for n in ns])
    return np.polyfit(np.log(ns), np.log(np.maximum(ts, 1e-3)), 1)[0], ns[0], ns[-1]


def fit_table(rows: list[dict]) -> list[str]:
    out = ["| setting | regions | time ~ N^a (default, median wall s per N) | CPU s ~ N^a |", "|---|---|---:|---:|"]
    keys = sorted({(r["setting"], r["kinds"]) for r in rows if r["variant"] == "default"})
    for setting, kinds in keys:
        wall, cpu = _exponent(rows, setting, kinds, "seconds"), _exponent(rows, setting, kinds, "cpu_seconds")
        if wall is not None:
            out.append(f"| {setting} | {kinds} | {wall[0]:.2f} (N = {wall[1]}..{wall[2]}) | {cpu[0]:.2f} |")
    return out


def _fmt_share(rows: list[dict]) -> str:
    return f"{sum(r['optimal'] for r in rows)}/{len(rows)}" if rows else "not run"


def paper_examples_table(example5_cases_n: int) -> list[str]:
    """Examples 2-4 and a sample of Example 5 through the default triangulate, beside the paper's certified
    values (Tables 8-12)."""
    import tritools
    from tritools.scene import example5_cases, paper_example, paper_table

    out = ["| example | default certified | gamma_LB | gamma_UB | paper's certified gamma | method / delta / "
           "sparsity | s |", "|---|---|---:|---:|---:|---|---:|"]
    for k in (2, 3, 4):
        cams, regions = paper_example(k)
        t = time.perf_counter()
        r = tritools.triangulate(cams, regions)
        secs = time.perf_counter() - t
        paper = [row for row in paper_table(k) if row.get("optimal") in (True, "yes", 1)]
        pg = min((row["gamma"] for row in paper if row.get("gamma") is not None), default=None)
        out.append(f"| {k} | {r.optimal} | {_fmt(r.gamma_lb, '.6g')} | {_fmt(r.gamma_ub, '.6g')} | "
                   f"{_fmt(pg, '.6g')} | {r.method} / {r.delta} / {r.sparsity} | {secs:.2f} |")
    if example5_cases_n:
        cases = example5_cases()[:example5_cases_n]
        t = time.perf_counter()
        res = [tritools.triangulate(c.cameras, c.regions) for c in cases]
        secs = time.perf_counter() - t
        out.append(f"| 5 (first {len(cases)} cases) | {sum(r.optimal for r in res)}/{len(res)} | - | - | - | "
                   f"{', '.join(sorted({f'{r.method}/{r.delta}/{r.sparsity}' for r in res}))} | "
                   f"{secs / max(len(res), 1):.3f} per case |")
    return out


# ----------------------------------------------------------------------------- main
def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="N = 3, 4, 10 with 3 seeds and no dense degree 4")
    ap.add_argument("--sizes", type=int, nargs="+", help=f"numbers of views (default {SIZES})")
    ap.add_argument("--seeds", type=int, default=5, help="seeds per (setting, regions, N) (default 5)")
    ap.add_argument("--settings", nargs="+", choices=sorted(SETTINGS), default=["small", "large"],
                    help="noise/region-size settings (default both)")
    ap.add_argument("--kinds", nargs="+", choices=["mixed", "points"], default=["mixed", "points"],
                    help="region kinds (default both)")
    ap.add_argument("--dense-max", type=int, default=4, help="run dense degree 4 up to this N (default 4)")
    ap.add_argument("--dense-time", type=float, default=300.0,
                    help="time limit of one dense degree-4 solve in seconds (default 300)")
    ap.add_argument("--time-limit", type=float, default=None,
                    help="time limit of the default per problem in (wall) seconds (default: the default, 60 s); "
                         "on a loaded machine a larger one lets the CPU column show the cost of a whole solve")
    ap.add_argument("--no-deg2", action="store_true", help="skip the degree-2-only column (halves the run)")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (default 1: timings on one core)")
    ap.add_argument("--example5", type=int, default=100, help="Example 5 cases through the default (default 100)")
    args = ap.parse_args(argv)
    sizes = tuple(args.sizes or (QUICK_SIZES if args.quick else SIZES))
    seeds = 3 if args.quick and args.seeds == 5 else args.seeds
    dense_max = 0 if args.quick else args.dense_max

    jobs = []
    for setting in args.settings:
        for kinds in args.kinds:
            for n in sizes:
                for seed in range(seeds):
                    base = dict(setting=setting, kinds=kinds, n=n, seed=seed, dense_time=args.dense_time,
                                time_limit=args.time_limit)
                    jobs.append(dict(base, variant="default"))
                    if not args.no_deg2:
                        jobs.append(dict(base, variant="deg2"))
                    if n <= dense_max:
                        jobs.append(dict(base, variant="dense4"))
    t0 = time.perf_counter()
    if "forkserver" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["tritools", "scipy.optimize"])     # workers start from imported modules
    else:
        ctx = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=args.jobs, mp_context=ctx, max_tasks_per_child=1) as ex:
        rows = list(ex.map(run_one, jobs))
    lines = [f"# benchmarks/manyview.py ({platform.processor() or platform.machine()}, "
             f"{os.cpu_count()} cores, {args.jobs} worker(s); seeds 0..{seeds - 1}; {time.perf_counter() - t0:.0f} s)",
             "", *scene_table(rows, sizes, args.settings, args.kinds, dense_max), "", *fit_table(rows), ""]
    if not args.quick:
        lines += ["Paper examples through the default:", "", *paper_examples_table(args.example5), ""]
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
