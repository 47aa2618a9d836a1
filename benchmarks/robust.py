"""Certified outlier-robust triangulation (issue #19): ``tritools.triangulate(cameras, x, robust=c)`` on the
CVPR 2023 simulation protocol (Haerenstam-Nielsen, Zeller, Cremers, "Semidefinite Relaxations for Robust
Multiview Triangulation"), beside the exact TLS optimum, pycolmap's LO-RANSAC and the paper's epipolar Shor
relaxation (re-implemented here in cvxpy + Clarabel).

    python benchmarks/robust.py                   # the RESULTS.md run (a few minutes on 2 cores)
    python benchmarks/robust.py --trials 10 --sizes 3 5 7 10 20 30 --peer-max 10 --enumerate-max 10

Protocol: K = [[1012, 0, 1054], [0, 1012, 581], [0, 0, 1]] (2108 x 1162 images), N cameras uniform on the
sphere of radius 2 looking at the origin, the point uniform in [-0.5, 0.5]^3, Gaussian noise of ``noise``
px, a fraction of the views replaced by uniform random image points (outliers), threshold c = 200 px (the
paper's setting).  Columns per (N, outlier fraction, noise), over the trials:

* ``cert``: fraction certified (``optimal``) by tritools; ``t_med`` / ``t_max`` its wall time per point;
* ``=ref``: fraction whose f_TLS(X) reaches the reference optimum (1e-6 relative) -- the reference is the
  minimum over every inlier set S of f_TLS at a local L2 minimiser of S (scipy least squares from the DLT
  of S and from tritools' X: an attained value, so ``=ref`` can only fail if tritools is worse), computed
  while N <= ``--enumerate-max``; ``lb>ref`` counts lower bounds above the reference (must be 0);
* ``inl``: fraction whose inlier set equals the ground truth (the non-corrupted views; an outlier that
  lands within c of the projection counts as an inlier of the truth);
* ``colmap``: pycolmap ``estimate_triangulation`` (LO-RANSAC, reprojection error, max_error = c):
  fraction with the ground-truth inlier set, median excess f_TLS(X_colmap) - f_TLS(X_tritools) in px^2 (> 0:
  tritools' point is better), median time;
* ``shor``: the epipolar relaxation (3N+1 PSD matrix, binary theta_i scaling the homogeneous image
  points, theta_i^2 = theta_i, "at least two inliers"), solved by Clarabel through cvxpy while N <=
  ``--peer-max``: fraction tight by the paper's rank test (sigma_2 / sigma_1 < 1e-4 of the solution
  matrix), median time, and the ratio of its median time to tritools';
* ``cpu_med``, ``shor_cpu``, ``peer/single cpu``: the same medians in CPU seconds of this process
  (``time.process_time``: less sensitive than wall time to other jobs on a shared machine).  These calls are
  interleaved per scene with the reference, pycolmap and the peer, so each starts with caches the others filled;
* ``shor_cpu_all``, ``peer_all/single cpu``: the peer's whole call -- building its cvxpy expressions (the
  (3N+1)-sided matrix variable, the N(N-1)/2 epipolar constraints) and solving -- as its public code pays for every
  point; ``shor_cpu`` counts ``Problem.solve`` alone (cvxpy's compilation and Clarabel), the conservative figure;
* ``cpu_loop``, ``shor_cpu_loop``, ``peer/single loop`` (unless ``--no-own-loop``): the same scenes again, each
  method in its own loop (all of tritools' calls, then all of the peer's; every scene has new cameras, so nothing
  of a call before is reused), median CPU per call: how a caller that triangulates point after point sees it;
* with ``--batch K``: K more scenes of the cell through one ``triangulate_many`` call -- certified count, CPU
  seconds per point (the call's CPU time over K: a mean, so a rare hard scene that needs the branch and bound
  weighs in, unlike the single calls' median), and the peer's median CPU time per point over it (the peer solves
  one point at a time).  The two peer ratios are labelled by what they divide: ``peer/single cpu`` (median over
  median, single calls) and ``peer/batch cpu`` (the peer's median over the batch's mean per point).
"""
from __future__ import annotations

import argparse
import gc
import itertools
import os
import sys
import time
import warnings

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

from tritools.scene import PROTOCOL_IMAGE, PROTOCOL_K, robust_protocol_scene  # noqa: E402

K = PROTOCOL_K
WIDTH, HEIGHT = PROTOCOL_IMAGE
THRESHOLD = 200.0


def scene(N: int, n_out: int, noise: float, rng):
    """Cameras (N, 3, 4), observations (N, 2), the true point, the outlier mask
    (:func:`tritools.scene.robust_protocol_scene`)."""
    return robust_protocol_scene(N, n_out, noise, rng)


def residuals(X, P, obs):
    h = P @ np.append(X, 1.0)
    with np.errstate(all="ignore"):
        d = np.linalg.norm(h[:, :2] / h[:, 2:] - obs, axis=1)
    return np.where(np.isfinite(d) & (h[:, 2] != 0), d, np.inf)


def tls(X, P, obs, c=THRESHOLD):
    return float(np.sum(np.minimum(residuals(X, P, obs) ** 2, c * c)))


def reference(P, obs, starts):
    """Minimum over inlier sets of f_TLS at a local L2 minimiser of the set (an attained TLS value)."""
    from scipy.optimize import least_squares

    from tritools.model.geometry import dlt

    N = len(P)
    best = float(N - 1) * THRESHOLD ** 2
    for k in range(2, N + 1):
        for S in itertools.combinations(range(N), k):
            S = list(S)
            cand = list(starts)
            try:
                cand.append(dlt(P[S], obs[S]))
            except ValueError:
                pass
            for X0 in cand:
                sol = least_squares(lambda X: (lambda h: (h[:, :2] / h[:, 2:] - obs[S]).ravel())(
                    P[S] @ np.append(X, 1.0)), X0, method="lm", xtol=1e-12, ftol=1e-12)
                best = min(best, tls(sol.x, P, obs))
    return best


def pycolmap_estimate(P, obs):
    import pycolmap

    cams, poses = [], []
    for Pi in P:
        Kinv = np.linalg.inv(K)
        Rt = Kinv @ Pi
        cams.append(pycolmap.Camera(model="PINHOLE", width=WIDTH, height=HEIGHT,
                                    params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))
        poses.append(pycolmap.Rigid3d(pycolmap.Rotation3d(Rt[:, :3]), Rt[:, 3]))
    opt = pycolmap.EstimateTriangulationOptions()
    opt.residual_type = pycolmap.TriangulationResidualType.REPROJECTION_ERROR
    opt.ransac.max_error = THRESHOLD
    out = pycolmap.estimate_triangulation(obs, poses, cams, opt)
    return None if out is None else np.asarray(out["xyz"], float)


def shor_epipolar(P, obs, c=THRESHOLD, scale=1 / 1054.0):
    """The CVPR 2023 epipolar relaxation (our cvxpy re-implementation): (tight, wall seconds, CPU seconds of the
    solve, CPU seconds of the whole call -- building the problem's expressions too, as the peer's code does for
    every point)."""
    import cvxpy as cp

    from tritools.model.geometry import fundamental_matrix

    c_all = time.process_time()
    N = len(P)
    S = np.diag([scale, scale, 1.0])
    Ps = S @ P
    o = obs * scale
    c2 = (c * scale) ** 2
    n = 3 * N + 1
    Z = cp.Variable((n, n), symmetric=True)
    one = n - 1
    cost = 0
    cons = [Z >> 0, Z[one, one] == 1]
    for i in range(N):
        a, b, t = 3 * i, 3 * i + 1, 3 * i + 2
        cost += Z[a, a] + Z[b, b] - 2 * (o[i, 0] * Z[a, one] + o[i, 1] * Z[b, one]) \
            + (o[i] @ o[i] - c2) * Z[t, one] + c2
        cons += [Z[t, t] == Z[t, one], Z[a, t] == Z[a, one], Z[b, t] == Z[b, one]]
    for i in range(N):
        for j in range(i + 1, N):
            F = fundamental_matrix(Ps[i], Ps[j])
            cons.append(cp.sum(cp.multiply(F, Z[3 * i:3 * i + 3, 3 * j:3 * j + 3])) == 0)
    cons.append(sum(Z[3 * i + 2, one] for i in range(N)) >= 2)
    prob = cp.Problem(cp.Minimize(cost), cons)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(solver=cp.CLARABEL)
    except cp.error.SolverError:
        return False, time.perf_counter() - t0, time.process_time() - c0, time.process_time() - c_all
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    if Z.value is None:
        return False, seconds, cpu, time.process_time() - c_all
    s = np.linalg.svd(Z.value, compute_uv=False)
    return bool(s[1] < 1e-4 * s[0]), seconds, cpu, time.process_time() - c_all


def run_cell(N, frac, noise, trials, args, rng):
    import tritools

    n_out = int(round(frac * N))
    if N - n_out < 2:
        return None
    row = dict(cert=0, ref=0, ref_n=0, lb_above=0, inl=0, t=[], cpu=[], col_ref=0, col_dx=[], col_t=[], shor=0,
               shor_t=[], shor_cpu=[], shor_all=[], shor_n=0)
    scenes = [scene(N, n_out, noise, rng) for _ in range(trials)]
    for P, obs, X, _out in scenes:
        t0, c0 = time.perf_counter(), time.process_time()
        r = tritools.triangulate(P, obs, robust=THRESHOLD, time_limit=args.time_limit)
        row["t"].append(time.perf_counter() - t0)
        row["cpu"].append(time.process_time() - c0)
        row["cert"] += bool(r.optimal)
        truth = residuals(X, P, obs) < THRESHOLD
        row["inl"] += bool(r.inliers is not None and np.array_equal(r.inliers, truth))
        f_ub = 2 * N * r.gamma_ub ** 2 if r.gamma_ub is not None else np.inf
        ref = None
        if N <= args.enumerate_max:
            ref = reference(P, obs, [X] + ([r.X] if r.X is not None else []))
            row["ref_n"] += 1
            row["ref"] += bool(f_ub <= ref * (1 + 1e-6) + 1e-9)
            row["lb_above"] += bool(r.gamma_lb is not None and 2 * N * r.gamma_lb ** 2 > ref * (1 + 1e-9) + 1e-9)
        if args.pycolmap:
            t0 = time.perf_counter()
            Xc = pycolmap_estimate(P, obs)
            row["col_t"].append(time.perf_counter() - t0)
            row["col_ref"] += bool(Xc is not None and np.array_equal(residuals(Xc, P, obs) < THRESHOLD, truth))
            row["col_dx"].append(tls(Xc, P, obs) - f_ub if Xc is not None else np.inf)
        if N <= args.peer_max:
            tight, sec, cpu, cpu_all = shor_epipolar(P, obs)
            row["shor"] += tight
            row["shor_t"].append(sec)
            row["shor_cpu"].append(cpu)
            row["shor_all"].append(cpu_all)
            row["shor_n"] += 1
    if args.own_loop:
        row.update(own_loops(scenes, N <= args.peer_max, args))
    if args.batch:
        row.update(batch_cell(N, n_out, noise, args))
    return row


def own_loops(scenes, peer: bool, args) -> dict:
    """The cell's scenes again, each method in its own loop (tritools' calls, then the peer's solves): median CPU
    seconds per call of each (module docstring, ``cpu_loop``)."""
    import tritools

    ours = []
    for P, obs, _, _ in scenes:
        c0 = time.process_time()
        tritools.triangulate(P, obs, robust=THRESHOLD, time_limit=args.time_limit)
        ours.append(time.process_time() - c0)
    peers = [shor_epipolar(P, obs)[2] for P, obs, _, _ in scenes] if peer else []
    return dict(cpu_loop=float(np.median(ours)), shor_cpu_loop=float(np.median(peers)) if peers else None)


def _warm_up(args) -> None:
    """One solve of each method on a throw-away scene, so that no timed cell pays the imports and the first
    compilations, and one small batch per view count of the table (its own random stream: the tables are unchanged)."""
    import tritools

    rng = np.random.default_rng(12345)
    P, obs, _, _ = scene(5, 1, 1.0, rng)
    tritools.triangulate(P, obs, robust=THRESHOLD, time_limit=args.time_limit)
    tritools.triangulate(P, obs)
    for N in (2, 3, 5):         # the batch path's first call of a view count compiles and caches its own kernels
        tritools.triangulate_many([scene(N, 1, 5.0, rng)[:2] for _ in range(3)], robust=THRESHOLD,
                                  time_limit=args.time_limit)
    # the sub-problem a few tracks need (Theorem 1 at delta = 4 on three views): its structures' one-time compiles
    # (~10 ms each; 10 minors, or 9 on most clean scenes) and the IPM's first BLAS-thread
    # controller (~12 ms) are paid once per process, here, not by the first timed cell that meets one (a batch of
    # 20 points: +1 ms per point)
    for k in range(6):
        P3, obs3, _, _ = scene(3, k % 2, 1.0 + 4.0 * (k % 2), rng)
        tritools.triangulate(P3, obs3, "theorem1", delta=4, max_delta=4)
    if args.peer_max >= 5:
        shor_epipolar(P, obs)


def batch_cell(N: int, n_out: int, noise: float, args) -> dict:
    """``--batch K``: K more scenes of the cell (their own random stream, so the per-point table is unchanged)
    through one ``tritools.triangulate_many(..., robust=c)`` call: certified count and CPU time per point."""
    import tritools

    rng = np.random.default_rng([args.seed, N, n_out, int(noise * 10)])
    probs = [scene(N, n_out, noise, rng)[:2] for _ in range(args.batch)]
    gc.collect()                # the peer's cvxpy objects of the cell: a collection inside a batch of 20 doubled it
    c0 = time.process_time()
    res = tritools.triangulate_many(probs, robust=THRESHOLD, time_limit=args.time_limit)
    cpu = time.process_time() - c0
    return dict(batch_cert=sum(bool(r.optimal) for r in res), batch_cpu=cpu / len(probs))


def colmap_model(args) -> None:
    """A synthetic COLMAP model (tritools.sfm.synthetic, PINHOLE, 0.5 px noise) with ``--colmap-outliers`` of the
    observations of tracks with >= 4 views moved by 30-80 px, through ``tritools colmap --robust 10`` (the
    library call), beside pycolmap's LO-RANSAC (reprojection error, 10 px) and the plain L2 run."""
    import tempfile
    from pathlib import Path

    from tritools.io.colmap import read_model_arrays
    from tritools.io.colmap.formats import write_model_arrays
    from tritools.sfm import RetriangulationOptions, retriangulate_folder
    from tritools.sfm.pipeline import rotations
    from tritools.sfm.synthetic import synthetic_arrays

    a, truth = synthetic_arrays(n_points=args.colmap_points, n_images=20, camera="PINHOLE", seed=args.seed,
                                max_track=12)
    rng = np.random.default_rng(args.seed)
    lens = np.diff(a.track_offsets)
    long = np.nonzero(lens >= 4)[0]
    n_bad = int(round(args.colmap_outliers * lens.sum()))
    bad_points = rng.choice(long, min(n_bad, len(long)), replace=False)
    injected = {}
    for p in bad_points:
        j = a.track_offsets[p] + rng.integers(lens[p])
        g = int(a.kp_offsets[a.track_image[j]] + a.track_kp[j])
        ang = rng.uniform(0, 2 * np.pi)
        a.kp_xy[g] += rng.uniform(30, 80) * np.array([np.cos(ang), np.sin(ang)])
        injected[int(p)] = g
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_model_arrays(a, tmp / "in", "bin")
        t0, c0 = time.perf_counter(), time.process_time()
        rob = retriangulate_folder(tmp / "in", tmp / "rob", RetriangulationOptions(robust=10.0, progress=False))
        t_rob, c_rob = time.perf_counter() - t0, time.process_time() - c0
        t0, c0 = time.perf_counter(), time.process_time()
        retriangulate_folder(tmp / "in", tmp / "l2", RetriangulationOptions(progress=False))
        t_l2, c_l2 = time.perf_counter() - t0, time.process_time() - c0
        b, c = read_model_arrays(tmp / "rob"), read_model_arrays(tmp / "l2")
    err_rob = np.linalg.norm(b.point_xyz - truth, axis=1)
    err_l2 = np.linalg.norm(c.point_xyz - truth, axis=1)
    removed = {int(g) for g in np.nonzero((a.kp_point3D != -1) & (b.kp_point3D == -1))[0]}
    caught = sum(g in removed for g in injected.values())
    err_col = np.full(a.n_points, np.nan)
    X_col = np.full((a.n_points, 3), np.nan)
    t_col = c_col = np.nan
    if args.pycolmap:
        import pycolmap

        cams = [pycolmap.Camera(model=m, width=int(w), height=int(h), params=p)
                for m, w, h, p in zip(a.camera_models, a.camera_width, a.camera_height, a.camera_params)]
        R = rotations(a.image_qvec)
        poses = [pycolmap.Rigid3d(pycolmap.Rotation3d(R[v]), a.image_tvec[v]) for v in range(a.n_images)]
        opt = pycolmap.EstimateTriangulationOptions()
        opt.residual_type = pycolmap.TriangulationResidualType.REPROJECTION_ERROR
        opt.ransac.max_error = 10.0
        t0, c0 = time.perf_counter(), time.process_time()
        X_col = _pycolmap_points(a, poses, cams, opt)
        t_col, c_col = time.perf_counter() - t0, time.process_time() - c0
        err_col = np.linalg.norm(X_col - truth, axis=1)
        X_ang = _pycolmap_points(a, poses, cams, pycolmap.EstimateTriangulationOptions())
        err_ang = np.linalg.norm(X_ang - truth, axis=1)
    bad = np.zeros(a.n_points, bool)
    bad[list(injected)] = True
    rep = rob.report
    print(f"\nCOLMAP model: {a.n_points} points, {int(lens.sum())} observations, {len(injected)} injected outlier "
          f"observations (30-80 px); robust threshold 10 px")
    print(f"tritools colmap --robust 10: {rep.n_certified}/{rep.n_points} certified, {t_rob:.2f} s wall "
          f"({1e3 * t_rob / a.n_points:.2f} ms/point; CPU {c_rob:.2f} s, {1e3 * c_rob / a.n_points:.2f} ms/point); "
          f"injected removed {caught}/{len(injected)}, other observations removed {len(removed) - caught}; plain L2 "
          f"run {t_l2:.2f} s (CPU {c_l2:.2f} s); pycolmap {t_col:.2f} s (CPU {c_col:.2f} s)")
    _error_classes(err_rob, err_l2, err_col, bad, lens)
    if args.pycolmap:
        print("the same against pycolmap with its default options (angular error, 2 degrees):")
        _error_classes(err_rob, err_l2, err_ang, bad, lens)
    if args.pycolmap:
        _inlier_set_costs(a, b, X_col, bad)


def _pycolmap_points(a, poses, cams, opt) -> np.ndarray:
    """pycolmap ``estimate_triangulation`` on every track of the model arrays ``a`` (NaN where it fails)."""
    import pycolmap

    X = np.full((a.n_points, 3), np.nan)
    for p in range(a.n_points):
        s_, e = a.track_offsets[p], a.track_offsets[p + 1]
        im = a.track_image[s_:e]
        out = pycolmap.estimate_triangulation(a.kp_xy[a.kp_offsets[im] + a.track_kp[s_:e]],
                                              [poses[i] for i in im], [cams[a.image_camera[i]] for i in im], opt)
        if out is not None:
            X[p] = np.asarray(out["xyz"])
    return X


def _error_classes(err_rob, err_l2, err_col, bad, lens) -> None:
    """3D error per point class, paired with pycolmap's on the same points: medians, means, the paired mean
    difference (ours - pycolmap) with its 95% interval (1.96 standard errors), and the points where ours is no
    worse.  A class counts as *worse* only when the whole interval lies above 0: both estimators end at the
    same inlier sets here, so per-point differences are the noise of two estimators of one point (our X is the
    certified L2 optimum of the inlier set, pycolmap's the LO-RANSAC/DLT estimate of it), not a verdict."""
    print("class | points | median 3D error robust | L2 | pycolmap | mean robust | mean pycolmap | "
          "mean diff (95%) | robust <= pycolmap | verdict")
    classes = (("clean", ~bad), ("with outlier", bad), ("clean, 2 views", ~bad & (lens == 2)),
               ("clean, 3-4 views", ~bad & (lens >= 3) & (lens <= 4)), ("clean, >= 5 views", ~bad & (lens >= 5)))
    for name, m in classes:
        ok = m & np.isfinite(err_col)
        if not ok.any():
            print(f"{name} | {int(m.sum())} | {np.median(err_rob[m]) if m.any() else float('nan'):.5f} | "
                  f"{np.median(err_l2[m]) if m.any() else float('nan'):.5f} | - | - | - | - | - | -")
            continue
        d = err_rob[ok] - err_col[ok]
        half = 1.96 * float(np.std(d, ddof=1)) / np.sqrt(d.size) if d.size > 1 else float("inf")
        mean = float(np.mean(d))
        verdict = "worse" if mean - half > 0 else ("better" if mean + half < 0 else "tie")
        print(f"{name} | {int(ok.sum())} | {np.median(err_rob[ok]):.5f} | {np.median(err_l2[ok]):.5f} | "
              f"{np.median(err_col[ok]):.5f} | {np.mean(err_rob[ok]):.5f} | {np.mean(err_col[ok]):.5f} | "
              f"{mean:+.1e} +- {half:.1e} | {int(np.sum(d <= 1e-9))}/{int(ok.sum())} | {verdict}")


def _inlier_set_costs(a, b, X_col, bad) -> None:
    """Per point with an injected outlier: the sum of squared reprojection errors over the observations our
    result kept (its inlier set), at our X and at pycolmap's X -- the L2 problem of the inlier set, of which
    our X is the certified optimum -- and the distance between the two estimates."""
    from tritools.sfm.pipeline import rotations

    R = rotations(a.image_qvec)
    K = [np.array([[p[0], 0, p[2]], [0, p[1], p[3]], [0, 0, 1.0]]) if len(p) == 4 else
         np.array([[p[0], 0, p[1]], [0, p[0], p[2]], [0, 0, 1.0]]) for p in a.camera_params]
    P = [K[a.image_camera[v]] @ np.hstack([R[v], a.image_tvec[v][:, None]]) for v in range(a.n_images)]
    wins, dist = 0, []
    idx = np.nonzero(bad & np.all(np.isfinite(X_col), axis=1))[0]
    for p in idx:
        s_, e = b.track_offsets[p], b.track_offsets[p + 1]
        im, xy = b.track_image[s_:e], b.kp_xy[b.kp_offsets[b.track_image[s_:e]] + b.track_kp[s_:e]]

        def cost(X):
            u = np.array([P[i] @ np.append(X, 1.0) for i in im])
            return float(np.sum((u[:, :2] / u[:, 2:] - xy) ** 2))
        wins += cost(b.point_xyz[p]) <= cost(X_col[p]) * (1 + 1e-9) + 1e-12
        dist.append(np.linalg.norm(b.point_xyz[p] - X_col[p]))
    print(f"with outlier, on our inlier set: L2 cost at our X <= at pycolmap's X in {wins}/{len(idx)} points; "
          f"median |X_ours - X_pycolmap| {np.median(dist):.2e}")


def oxford_tracks(args) -> None:
    """Oxford tracks (--oxford NAME, >= 5 views) with 1-3 observations replaced by random image points."""
    import tritools
    from tritools.io.oxford import DataNotFoundError, load_sequence

    try:
        seq = load_sequence(args.oxford, min_views=5)
    except DataNotFoundError as exc:
        print(f"\nOxford: skipped ({exc})")
        return
    rng = np.random.default_rng(args.seed)
    tracks = [seq.tracks[k] for k in rng.choice(len(seq.tracks), min(args.oxford_tracks, len(seq.tracks)),
                                                 replace=False)]
    n_cert = n_inl = 0
    times = []
    for t in tracks:
        P, x = seq.problem(t)
        x = x.copy()
        k = int(rng.integers(1, 4))
        out = rng.choice(len(x), min(k, len(x) - 2), replace=False)
        lo, hi = x.min(axis=0), x.max(axis=0)
        x[out] = rng.uniform(lo - 100, hi + 100, size=(len(out), 2))
        t0 = time.perf_counter()
        r = tritools.triangulate(P, x, robust=args.oxford_threshold, time_limit=args.time_limit)
        times.append(time.perf_counter() - t0)
        n_cert += bool(r.optimal)
        if r.inliers is not None:
            n_inl += bool(set(np.nonzero(~r.inliers)[0]) >= set(out.tolist()))
    print(f"\nOxford {args.oxford}: {len(tracks)} tracks (>= 5 views) with 1-3 wrong matches, threshold "
          f"{args.oxford_threshold} px: certified {n_cert}/{len(tracks)}, every wrong match an outlier "
          f"{n_inl}/{len(tracks)}, median {np.median(times):.3f} s, max {max(times):.3f} s per track")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[3, 5, 7, 10, 20, 30])
    ap.add_argument("--fractions", type=float, nargs="+", default=[0.0, 0.2, 0.4, 0.6])
    ap.add_argument("--noise", type=float, nargs="+", default=[1.0, 5.0])
    ap.add_argument("--trials", type=int, default=3)
    ap.add_argument("--enumerate-max", type=int, default=7, dest="enumerate_max")
    ap.add_argument("--peer-max", type=int, default=7, dest="peer_max")
    ap.add_argument("--time-limit", type=float, default=10.0, dest="time_limit")
    ap.add_argument("--no-pycolmap", action="store_false", dest="pycolmap")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--colmap-points", type=int, default=300, dest="colmap_points",
                    help="points of the synthetic COLMAP model (0: skip)")
    ap.add_argument("--colmap-outliers", type=float, default=0.1, dest="colmap_outliers",
                    help="fraction of the observations made outliers")
    ap.add_argument("--oxford", default="house", help="Oxford sequence of the wrong-match test ('' to skip)")
    ap.add_argument("--oxford-tracks", type=int, default=50, dest="oxford_tracks")
    ap.add_argument("--oxford-threshold", type=float, default=5.0, dest="oxford_threshold")
    ap.add_argument("--batch", type=int, default=0,
                    help="per cell, this many more scenes through one triangulate_many call (CPU per point)")
    ap.add_argument("--no-own-loop", action="store_false", dest="own_loop",
                    help="skip the second timing of each method in its own loop (cpu_loop columns)")
    ap.add_argument("--skip-sim", action="store_true", dest="skip_sim", help="only the COLMAP and Oxford parts")
    args = ap.parse_args(argv)
    if args.pycolmap:
        try:
            import pycolmap  # noqa: F401
        except ImportError:
            args.pycolmap = False
    if args.colmap_points:
        colmap_model(args)
    if args.oxford:
        oxford_tracks(args)
    if args.skip_sim:
        return 0
    _warm_up(args)
    rng = np.random.default_rng(args.seed)
    head = ("N", "out", "noise", "cert", "t_med[s]", "t_max[s]", "=ref", "lb>ref", "inl", "colmap_inl",
            "colmap_df[px2]", "colmap_t", "shor_tight", "shor_t", "shor/ours", "cpu_med[s]", "shor_cpu[s]",
            "peer/single cpu", "shor_cpu_all[s]", "peer_all/single cpu")
    if args.own_loop:
        head += ("cpu_loop[s]", "shor_cpu_loop[s]", "peer/single loop")
    if args.batch:
        head += ("batch_cert", "batch_cpu/pt[s]", "peer/batch cpu")
    print("\n" + " | ".join(head))
    print(" | ".join("---" for _ in head))
    for N in args.sizes:
        for frac in args.fractions:
            for noise in args.noise:
                r = run_cell(N, frac, noise, args.trials, args, rng)
                if r is None:
                    continue
                n = args.trials
                tm = float(np.median(r["t"]))
                cells = [N, f"{frac:.0%}", noise, f"{r['cert']}/{n}", f"{tm:.3f}", f"{max(r['t']):.3f}",
                         f"{r['ref']}/{r['ref_n']}" if r["ref_n"] else "-", r["lb_above"] if r["ref_n"] else "-",
                         f"{r['inl']}/{n}",
                         f"{r['col_ref']}/{n}" if args.pycolmap else "-",
                         f"{np.median(r['col_dx']):.3g}" if r["col_dx"] else "-",
                         f"{np.median(r['col_t']):.4f}" if r["col_t"] else "-",
                         f"{r['shor']}/{r['shor_n']}" if r["shor_n"] else "-",
                         f"{np.median(r['shor_t']):.3f}" if r["shor_t"] else "-",
                         f"{np.median(r['shor_t']) / tm:.1f}" if r["shor_t"] else "-",
                         f"{np.median(r['cpu']):.4f}",
                         f"{np.median(r['shor_cpu']):.3f}" if r["shor_cpu"] else "-",
                         f"{np.median(r['shor_cpu']) / np.median(r['cpu']):.1f}" if r["shor_cpu"] else "-",
                         f"{np.median(r['shor_all']):.3f}" if r["shor_all"] else "-",
                         f"{np.median(r['shor_all']) / np.median(r['cpu']):.1f}" if r["shor_all"] else "-"]
                if args.own_loop:
                    sl = r["shor_cpu_loop"]
                    cells += [f"{r['cpu_loop']:.4f}", "-" if sl is None else f"{sl:.3f}",
                              "-" if sl is None else f"{sl / r['cpu_loop']:.1f}"]
                if args.batch:
                    cells += [f"{r['batch_cert']}/{args.batch}", f"{r['batch_cpu']:.4f}",
                              f"{np.median(r['shor_cpu']) / r['batch_cpu']:.1f}" if r["shor_cpu"] else "-"]
                print(" | ".join(str(c) for c in cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
