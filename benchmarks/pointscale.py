"""Point tracks from 2 to 100+ views: the cost per track of certified triangulation, side by side (issue #22).

    python benchmarks/pointscale.py                      # N = 2, 5, 10, 20, 40, 60, 100; 200 points per N
    python benchmarks/pointscale.py --sizes 20 100 --points 50 --noise 1 5

Per N (seeded :func:`tritools.scene.random_scene`, cameras on a sphere, f = 800 px, Gaussian noise):

* ``batch``: ``tritools.triangulate_points`` on all points of that N (one call; vectorised certification
  by verification: all view pairs up to ``BAND_MIN_VIEWS`` views, bands of view pairs beyond), ms per
  track, and the certified fraction;
* ``single``: one ``tritools.triangulate(cameras, points)`` call per point (median ms over ``--single``
  points), and its ratio to the batch's per-track cost;
* ``discs``: ``tritools.triangulate_many`` on the same keypoints as 1 px discs (uncertain keypoints, ``Ellipse(x,
  I)``; certification by verification with region multipliers, tritools.solve.discs), ms per track, the
  certified fraction, and the ratio to ``batch``;
* ``ellipses``: the same with non-circular ellipses (semi-axes 1 and 0.5 px, seeded random orientations;
  tritools.solve.ellipses), ms per track, certified fraction, ratio to ``batch``;
* ``mixed``: views cycling through a point, a 1 px disc and such an ellipse (the vectorised ellipse group with
  D = 0 for points), ms per track, certified fraction, ratio to ``batch``;
* ``scipy-lm``: ``scipy.optimize.least_squares(method="lm")`` on the reprojection residuals from the DLT
  point (no certificate);
* ``pycolmap``: ``pycolmap.triangulate_multi_view_point`` (linear, no certificate; cameras decomposed
  outside the timing), when installed.

``--theorem1 DIR``: ``tritools.triangulate(cameras, points, "theorem1", time_limit=...)`` on ``--tracks`` tracks
of 9-11 views of the Oxford corridor sequence in DIR (the default plan of an explicit Theorem 1 starts with the
degree-2 step on the two-view minors, docs/triangulation.md): status, degree, wall time, and an independent
reference (the best of multi-start LM from perturbed DLT starts) that gamma_LB must not exceed.

``--faces P``: P points per N as 0.4 px segments and as 0.6 x 0.2 px boxes (seeded orientations) through
``triangulate_many`` (the single path per problem): CPU ms per track, certified fraction and the share
certified by verification (tritools.solve.regions_verify with the face multipliers of tritools.solve.faces),
the rest by the SDP.

``--sfm P``: the tracks of a seeded synthetic COLMAP model of P points (:func:`tritools.sfm.synthetic.
synthetic_arrays`, 30 images, tracks of 2-12 views, keypoints undistorted) through ``triangulate_many`` as points
and as 1 px discs (the SfM shape of uncertain keypoints), CPU seconds, certified fractions and their ratio.

Every gamma_LB of a certified point is checked against the attained value of scipy's LM solution
(``lb<=lm``: the largest gamma_LB - gamma(X_lm), <= 0 up to round-off when sound).  Then the growth exponent
a of the batch's per-track time ~ N^a over N = 20..100 (least squares in log-log).  Times are process CPU
time (``time.process_time``, one BLAS thread), the least noisy measure on a shared machine.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import statistics
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import numpy as np  # noqa: E402

import tritools  # noqa: E402
from tritools.model.geometry import dlt  # noqa: E402
from tritools.scene import random_scene  # noqa: E402

SIZES = (2, 5, 10, 20, 40, 60, 100)


def lm_point(C: np.ndarray, x: np.ndarray) -> np.ndarray:
    """scipy's Levenberg-Marquardt on the reprojection residuals, from the DLT point."""
    return lm_from(C, x, dlt(C, x))


def gamma(C: np.ndarray, x: np.ndarray, X: np.ndarray) -> float:
    h = C @ np.append(X, 1.0)
    return float(np.sqrt(np.mean((h[:, :2] / h[:, 2:] - x) ** 2)))


def colmap_setup(C: np.ndarray, x: np.ndarray):
    from tritools.baselines import decompose_camera

    cams, rays = [], []
    for P, p in zip(C, x):
        K, Rt = decompose_camera(P)
        r = np.linalg.solve(K, np.append(p, 1.0))
        cams.append(Rt)
        rays.append(r / np.linalg.norm(r))
    return cams, np.array(rays)


def cpu(fn) -> float:
    t = time.process_time()
    fn()
    return time.process_time() - t


def row(N: int, n_points: int, noise: float, n_single: int, have_colmap: bool, seed: int) -> dict:
    sc = random_scene(N, n_points, noise_px=noise, seed=seed + N)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    out = {"N": N, "noise": noise}
    box = {}
    batch = lambda: box.setdefault("r", tritools.triangulate_points(C, x, layout="points_views"))   # noqa: E731
    out["batch"] = cpu(batch) / n_points * 1e3        # (layout given: --points N at N views is ambiguous)
    res = box["r"]
    out["cert"] = float(np.mean(res.optimal))
    singles = []
    for j in range(min(n_single, n_points)):
        singles.append(cpu(lambda: tritools.triangulate(C, x[j])) * 1e3)
    out["single"] = statistics.median(singles)
    from tritools import Ellipse

    discs = [(C, [Ellipse(p, np.eye(2)) for p in x[j]]) for j in range(n_points)]
    out["discs"] = cpu(lambda: box.setdefault("d", tritools.triangulate_many(discs, progress=False))) \
        / n_points * 1e3
    out["disc_cert"] = float(np.mean([r.optimal for r in box["d"]]))
    for name, probs in region_columns(C, x, seed + N).items():
        out[name] = cpu(lambda: box.__setitem__(name, tritools.triangulate_many(probs, progress=False))) \
            / n_points * 1e3
        out[name + "_cert"] = float(np.mean([r.optimal for r in box[name]]))
    lm = []
    out["lm"] = cpu(lambda: lm.extend(lm_point(C, x[j]) for j in range(n_points))) / n_points * 1e3
    g_lm = np.array([gamma(C, x[j], X) for j, X in enumerate(lm)])
    cert = np.asarray(res.optimal, bool)
    out["lb<=lm"] = float(np.max(np.asarray(res.gamma_lb)[cert] - g_lm[cert])) if cert.any() else float("nan")
    if have_colmap:
        import pycolmap

        setups = [colmap_setup(C, x[j]) for j in range(n_points)]
        out["colmap"] = cpu(lambda: [pycolmap.triangulate_multi_view_point(c, r) for c, r in setups]) \
            / n_points * 1e3
    return out


def region_columns(C: np.ndarray, x: np.ndarray, seed: int) -> dict:
    """The problems of the ``ellipses`` and ``mixed`` columns (module docstring)."""
    from tritools import Ellipse, Point

    rng = np.random.default_rng(seed)
    angles = rng.uniform(0, np.pi, size=x.shape[:2])
    R = np.stack([np.stack([np.cos(angles), -np.sin(angles)], -1), np.stack([np.sin(angles), np.cos(angles)], -1)],
                 -2)
    D = R @ np.diag([1.0, 0.25]) @ np.swapaxes(R, -1, -2)
    ell = [(C, [Ellipse(p, d) for p, d in zip(x[j], D[j])]) for j in range(len(x))]
    kinds = (lambda p, d: Point(p), lambda p, d: Ellipse(p, np.eye(2)), lambda p, d: Ellipse(p, d))
    mixed = [(C, [kinds[(i + j) % 3](p, d) for i, (p, d) in enumerate(zip(x[j], D[j]))]) for j in range(len(x))]
    return {"ellipses": ell, "mixed": mixed}


def face_regions(C: np.ndarray, x: np.ndarray, seed: int) -> dict:
    """The problems of the ``--faces`` table (module docstring): 0.4 px segments and 0.6 x 0.2 px boxes."""
    from tritools import Polytope, Segment

    rng = np.random.default_rng(seed)
    a = rng.uniform(0, np.pi, size=x.shape[:2])
    u = np.stack([np.cos(a), np.sin(a)], -1)
    seg = [(C, [Segment(p, 0.2 * d) for p, d in zip(x[j], u[j])]) for j in range(len(x))]

    def box(p, d):
        B = np.array([[d[0], d[1]], [-d[1], d[0]]]) / np.array([[0.3], [0.1]])
        return Polytope(B, -B @ p)

    boxes = [(C, [box(p, d) for p, d in zip(x[j], u[j])]) for j in range(len(x))]
    return {"segments": seg, "boxes": boxes}


def faces_table(sizes, n_points: int, noise: float, seed: int) -> None:
    """The ``--faces`` table (module docstring)."""
    print(f"\nSegments and boxes ({n_points} points per N, {noise:g} px noise), triangulate_many\n")
    print("| N | region | ms/track | certified | by verification |")
    print("|---:|---|---:|---:|---:|")
    for N in sizes:
        sc = random_scene(N, n_points, noise_px=noise, seed=seed + N)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
        for name, probs in face_regions(C, x, seed + N).items():
            box = {}
            t = cpu(lambda: box.setdefault("r", tritools.triangulate_many(probs, progress=False))) / n_points * 1e3
            res = box["r"]
            cert = np.mean([r.optimal for r in res])
            ver = np.mean([r.certified_by == "verification" for r in res])
            print(f"| {N} | {name} | {t:.2f} | {cert:.1%} | {ver:.1%} |", flush=True)


def sfm_discs(n_points: int, seed: int) -> None:
    """The ``--sfm`` table (module docstring)."""
    from tritools import Ellipse
    from tritools.sfm.pipeline import prepare_geometry
    from tritools.sfm.synthetic import synthetic_arrays

    a, _ = synthetic_arrays(n_points, 30, "PINHOLE", 0.5, seed)
    geom = prepare_geometry(a)
    pts, discs = [], []
    for p in range(a.n_points):
        s, e = a.track_offsets[p], a.track_offsets[p + 1]
        im = a.track_image[s:e]
        C, x = geom.P[im], geom.xy_u[a.kp_offsets[im] + a.track_kp[s:e]]
        pts.append((C, x))
        discs.append((C, [Ellipse(q, np.eye(2)) for q in x]))
    box = {}
    t_pts = cpu(lambda: box.setdefault("p", tritools.triangulate_many(pts, progress=False)))
    t_discs = cpu(lambda: box.setdefault("d", tritools.triangulate_many(discs, progress=False)))
    cp = np.mean([r.optimal for r in box["p"]])
    cd = np.mean([r.optimal for r in box["d"]])
    print(f"\nSynthetic SfM model, {a.n_points} tracks (2-12 views): points {t_pts:.1f} s CPU ({cp:.2%} certified), "
          f"1 px discs {t_discs:.1f} s CPU ({cd:.2%} certified), discs/points {t_discs / t_pts:.1f}\n")


def theorem1_corridor(data_dir: str, n_tracks: int, time_limit: float) -> None:
    from tritools.io.oxford import load_sequence

    seq = load_sequence("corridor", data_dir)
    long = [t for t in seq.tracks if 9 <= t.n_views <= 11]
    pick = long[::max(1, len(long) // n_tracks)][:n_tracks]
    print(f"\nTheorem 1 on corridor tracks with 9-11 views ({len(long)} such tracks; {len(pick)} evenly spaced), "
          f"time_limit={time_limit:g} s\n")
    print("| track | N | status | delta | certified by | gamma_LB | gamma_UB | reference | wall s |")
    print("|---:|---:|---|---:|---|---:|---:|---:|---:|")
    for t in pick:
        C, x = seq.problem(t)
        C, x = np.asarray(C), np.asarray(x)
        t0 = time.perf_counter()
        r = tritools.triangulate(C, x, "theorem1", time_limit=time_limit)
        wall = time.perf_counter() - t0
        rng = np.random.default_rng(0)
        X0 = lm_point(C, x)
        ref = min(gamma(C, x, X) for X in [X0] + [lm_from(C, x, X0 + 0.05 * np.linalg.norm(X0) * rng.normal(size=3))
                                               for _ in range(8)])
        assert r.gamma_lb is None or r.gamma_lb <= ref * (1 + 1e-9), "gamma_LB above an attained value"
        print(f"| {t.track_id} | {t.n_views} | {r.status.value} | {r.delta} | {r.certified_by} | {r.gamma_lb:.6f} | "
              f"{r.gamma_ub:.6f} | {ref:.6f} | {wall:.3f} |", flush=True)


def lm_from(C: np.ndarray, x: np.ndarray, X0: np.ndarray) -> np.ndarray:
    from scipy.optimize import least_squares

    def res(X):
        h = C @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()

    return least_squares(res, X0, method="lm").x


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=list(SIZES))
    ap.add_argument("--points", type=int, default=200)
    ap.add_argument("--single", type=int, default=30, help="points timed through single triangulate() calls")
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--theorem1", metavar="DIR", help="also run Theorem 1 on corridor tracks (Oxford data in DIR)")
    ap.add_argument("--tracks", type=int, default=5)
    ap.add_argument("--sfm", type=int, default=0, metavar="P", help="also a synthetic SfM model of P points (discs)")
    ap.add_argument("--time-limit", type=float, default=180.0)
    ap.add_argument("--faces", type=int, default=0, metavar="P", help="also segments and boxes, P points per N")
    ap.add_argument("--faces-only", action="store_true", help="only the --faces table")
    args = ap.parse_args(argv)
    have_colmap = importlib.util.find_spec("pycolmap") is not None
    if args.faces:
        for noise in args.noise:
            faces_table(args.sizes, args.faces, noise, args.seed)
        if args.faces_only:
            return
    print("| noise px | N | batch ms/track | certified | single ms | single/batch | discs ms/track | discs certified "
          "| discs/batch | ellipses ms | ell. certified | ell./batch | mixed ms | mixed certified | mixed/batch "
          "| scipy-lm ms | pycolmap ms | lb<=lm |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for noise in args.noise:
        rows = []
        for N in args.sizes:
            r = row(N, args.points, noise, args.single, have_colmap, args.seed)
            rows.append(r)
            colmap = f"{r['colmap']:.3f}" if "colmap" in r else "n/a"
            print(f"| {noise:g} | {N} | {r['batch']:.3f} | {r['cert']:.1%} | {r['single']:.2f} | "
                  f"{r['single'] / r['batch']:.1f} | {r['discs']:.3f} | {r['disc_cert']:.1%} | "
                  f"{r['discs'] / r['batch']:.1f} | {r['ellipses']:.3f} | {r['ellipses_cert']:.1%} | "
                  f"{r['ellipses'] / r['batch']:.1f} | {r['mixed']:.3f} | {r['mixed_cert']:.1%} | "
                  f"{r['mixed'] / r['batch']:.1f} | {r['lm']:.3f} | {colmap} | {r['lb<=lm']:.1e} |", flush=True)
        fit = [(r["N"], r["batch"]) for r in rows if 20 <= r["N"] <= 100]
        if len(fit) >= 2:
            a = np.polyfit(np.log([f[0] for f in fit]), np.log([f[1] for f in fit]), 1)[0]
            print(f"\nnoise {noise:g} px: batch time per track ~ N^{a:.2f} over N = {fit[0][0]}..{fit[-1][0]}\n")
    if args.sfm:
        sfm_discs(args.sfm, args.seed)
    if args.theorem1:
        theorem1_corridor(args.theorem1, args.tracks, args.time_limit)


if __name__ == "__main__":
    main()
