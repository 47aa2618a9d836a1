"""Robust (TLS) calls that ran to the time limit in review 6: long protocol tracks with many wrong matches (F5)
and a 7-view mixed-region problem whose L2 path gave up (F6; plain and robust certify since wave 14's
normalisation fix), timed in this checkout and, with ``--other DIR``, in another one (e.g. main) in the same run,
interleaved (process CPU time of each call, one BLAS thread, in a fresh subprocess per call).

Usage: python benchmarks/robust_long.py [--other /work/main] [--seeds 3] [--time-limit 60] [--sizes 60 80 100]
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import pathlib
import subprocess
import sys

log = logging.getLogger("robust_long")

HERE = pathlib.Path(__file__).resolve().parents[1]
F6_DATA = HERE / "tests" / "data" / "robust_regions_futile.json"

#: one call, run in a subprocess: prints a JSON line (status, cpu seconds, gamma bounds, inliers right or None)
CALL = r"""
import json, math, sys, time
import tritools as _t
import numpy as np
import tritools
from tritools.scene import robust_protocol_scene
kind, arg, seed, tl = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4])
right = None
if kind == "protocol":
    N, frac, noise, c = (float(v) for v in arg.split(","))
    N = int(N)
    P, x, X, out = robust_protocol_scene(N, int(round(frac * N)), noise, np.random.default_rng(seed))
    t = time.process_time()
    r = tritools.triangulate(P, x, robust=c, time_limit=tl)
    cpu = time.process_time() - t
    right = bool(np.array_equal(np.asarray(r.inliers, bool), ~out))
else:
    d = json.load(open(arg))
    c = np.array([math.inf if v == "inf" else float(v) for v in d["robust"]])
    t = time.process_time()
    r = tritools.triangulate(np.array(d["cameras"]), d["regions"], robust=None if kind == "plain" else c,
                             time_limit=tl)
    cpu = time.process_time() - t
print(json.dumps({"status": r.status.value, "cpu": cpu, "lb": r.gamma_lb, "ub": r.gamma_ub, "right": right,
                  "module": _t.__file__}))
"""


def run(tree: str, kind: str, arg: str, seed: int, time_limit: float) -> dict:
    """One call in a subprocess importing tritools from ``tree``."""
    env = dict(os.environ, PYTHONPATH=tree, OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, "-c", CALL, kind, arg, str(seed), str(time_limit)], env=env, cwd=tree,
                         capture_output=True, text=True, timeout=time_limit * 3 + 120)   # cwd: "" leads sys.path
    if out.returncode != 0:
        return {"status": f"error: {out.stderr.strip().splitlines()[-1:]}", "cpu": float("nan")}
    return json.loads(out.stdout.strip().splitlines()[-1])


def cases(args) -> list:
    out = [("plain", str(F6_DATA), 0, "F6 region problem, plain L2"),
           ("robust", str(F6_DATA), 0, "F6 region problem, robust=c")]
    for N in args.sizes:
        for seed in range(args.seeds):
            out.append(("protocol", f"{N},0.3,1,5", seed, f"N={N}, 30% wrong, noise 1, c=5, seed {seed}"))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--other", default=None, help="another checkout to time in the same run (e.g. /work/main)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--sizes", type=int, nargs="+", default=[60, 80, 100])
    ap.add_argument("--time-limit", type=float, default=60.0)
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    trees = [("this", str(HERE))] + ([("other", args.other)] if args.other else [])
    header = ["| case | " + " | ".join(f"{n} status | {n} CPU s" for n, _ in trees) + " | inliers right |",
              "|---|" + "---|---|" * len(trees) + "---|"]
    for n, (kind, arg, seed, name) in enumerate(cases(args)):
        res = [run(tree, kind, arg, seed, args.time_limit) for _, tree in trees]    # interleaved per case
        if n == 0:
            log.info("tritools imported from: " + ", ".join(f"{t}: {r.get('module')}" for (t, _), r in
                                                              zip(trees, res)))
            for line in header:
                log.info(line)
        cols = " | ".join(f"{r['status']} | {r['cpu']:.2f}" for r in res)
        log.info(f"| {name} | {cols} | {res[0].get('right')} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
