"""Certified per-view uncertainty against the linearised covariance (issue #20).

Bounded noise: every observation is the true projection moved uniformly within a disc of radius r,
and the region of each view is the disc of radius r around the observation, so the true point lies in
the per-view set S (docs/uncertainty.md).  For every point we compare

* ours: the certified box and the radius ``max_distance`` around the L2 estimate X^
  (:func:`tritools.uncertain.uncertainty_discs`, depth intervals from the box);
* the covariance users compute: ``Sigma = sigma^2 (J' J)^-1`` at X^ (J the stacked 2N x 3 Jacobian of
  the projections, sigma = r / 2 the per-coordinate standard deviation of uniform noise in a disc), its
  ellipsoid at the chi-square(3) level 1 - 1e-3 (``--alpha``).

Reported: coverage (fraction of true points inside; ours must be 100 %), size ratio of our radius to
the ellipsoid's largest semi-axis on well-conditioned points (angle >= 5 deg), behaviour per
triangulation-angle bin (unbounded fraction, median true error, radius, covariance semi-axis), time.
Scenes: random 2-4 view rigs at distance 5 with log-uniform baselines (angles ~0.01-40 deg); the
Oxford sequences (if present) with their real cameras and tracks, the L2 point of each track taken as
the truth and re-observed with bounded noise; and the time of the SfM path (``tritools.sfm.quality``,
--keypoint-radius) on a synthetic COLMAP model.

    python benchmarks/uncertainty.py                          # 10000 synthetic points, Oxford, 50k COLMAP model
    python benchmarks/uncertainty.py --points 2000 --colmap-points 0 --oxford-tracks 0
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.stats import chi2

from tritools.model.stacked import dlt_stack, project_stack, refine_points_stack
from tritools.uncertain import UncertaintyOptions, triangulation_angles, uncertainty_discs

BINS = (0.0, 0.1, 0.5, 1.5, 5.0, 180.0)


def look_at(C, target, f=800.0):
    z = target - C
    z = z / np.linalg.norm(z)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    R = np.array([x, np.cross(z, x), z])
    K = np.array([[f, 0.0, 512.0], [0.0, f, 384.0], [0.0, 0.0, 1.0]])
    return K @ np.hstack([R, -R @ C[:, None]])


def synthetic(rng, M, N):
    """M rigs of N cameras at distance ~5 from a point near the origin, baselines log-uniform."""
    cams = np.empty((M, N, 3, 4))
    X = rng.normal(size=(M, 3)) * 0.3
    for m in range(M):
        b = 10 ** rng.uniform(-3, 0.6)
        for i in range(N):
            C = np.array([b * (i - (N - 1) / 2) + rng.normal() * 0.01 * b, rng.normal() * 0.2 * b, -5.0])
            cams[m, i] = look_at(C, X[m] + rng.normal(size=3) * 0.1)
    return cams, X


def observe(rng, cams, X, r):
    """Projections moved uniformly within discs of radius r."""
    u, _, _ = project_stack(cams, X)
    d = rng.normal(size=u.shape)
    d *= (r * np.sqrt(rng.uniform(size=u.shape[:2])) / np.linalg.norm(d, axis=2))[..., None]
    return u + 0.999 * d


def l2_estimates(cams, x):
    X0, ok = dlt_stack(cams, x)
    X, _ = refine_points_stack(cams, x, X0, ok)
    return X


def covariance(cams, X, sigma):
    """sigma^2 (J' J)^-1 per point (M, 3, 3) (inf where J' J is singular)."""
    Xh = np.concatenate([X, np.ones((len(X), 1))], axis=1)
    h = np.einsum("mnij,mj->mni", cams, Xh)
    J = (cams[..., :2, :3] - (h[..., :2] / h[..., 2:3])[..., None] * cams[..., 2:3, :3]) / h[..., 2:3, None]
    J = J.reshape(len(X), -1, 3)
    JtJ = np.einsum("mki,mkj->mij", J, J)
    with np.errstate(all="ignore"):
        try:
            return sigma ** 2 * np.linalg.inv(JtJ)
        except np.linalg.LinAlgError:
            return np.array([sigma ** 2 * np.linalg.pinv(A) for A in JtJ])


def compare(cams, X_true, x, r, alpha, label):
    """Ours vs the covariance ellipsoid on one batch; prints a table, returns a summary dict."""
    M, N = cams.shape[:2]
    Xh = l2_estimates(cams, x)
    t0 = time.perf_counter()
    res = uncertainty_discs(cams, x, r, Xh, UncertaintyOptions(depth_bounds=False))
    dt = time.perf_counter() - t0
    lo = np.array([q.lo for q in res])
    hi = np.array([q.hi for q in res])
    rad = np.array([q.max_distance for q in res])
    status = np.array([q.status.value for q in res])
    err = np.linalg.norm(X_true - Xh, axis=1)
    inside = np.all((lo <= X_true) & (X_true <= hi), axis=1) & (err <= rad)
    S = covariance(cams, Xh, r / 2.0)
    k2 = chi2.ppf(1 - alpha, 3)
    d = X_true - Xh
    with np.errstate(all="ignore"):
        maha = np.einsum("mi,mij,mj->m", d, np.linalg.pinv(S), d)
        semi = np.sqrt(k2 * np.linalg.eigvalsh(S)[:, -1])
    cov_in = maha <= k2
    w = np.linalg.svd(cams.reshape(-1, 3, 4))[2][:, -1].reshape(M, N, 4)        # camera centres
    ang = triangulation_angles(w[..., :3] / w[..., 3:], Xh)
    print(f"\n### {label}: {M} points, {N} views, disc radius {r} px\n")
    counts = dict(zip(*(v.tolist() for v in np.unique(status, return_counts=True))))
    print(f"ours: coverage {inside.mean():.4%} ({np.count_nonzero(~inside)} misses), statuses "
          f"{counts}; covariance ellipsoid (level {1 - alpha}): "
          f"coverage {cov_in.mean():.4%}; time {dt:.2f} s ({1e3 * dt / M:.3f} ms/point)")
    good = (ang >= 5.0) & np.isfinite(rad) & np.isfinite(semi)
    if np.any(good):
        ratio = rad[good] / semi[good]
        print(f"angle >= 5 deg ({good.sum()} points): radius / covariance semi-axis median {np.median(ratio):.2f}, "
              f"p90 {np.quantile(ratio, 0.9):.2f}")
    print("\n| angle [deg] | points | unbounded | ours: coverage | cov: coverage | median 3D error | "
          "median radius (bounded) | median cov semi-axis |")
    print("|---|---|---|---|---|---|---|---|")
    for a, b in zip(BINS[:-1], BINS[1:]):
        sel = (ang >= a) & (ang < b)
        if not np.any(sel):
            continue
        fin = sel & np.isfinite(rad)
        print(f"| {a}-{b} | {sel.sum()} | {np.mean(status[sel] == 'unbounded'):.1%} | {inside[sel].mean():.2%} | "
              f"{cov_in[sel].mean():.2%} | {np.median(err[sel]):.3g} | "
              f"{np.median(rad[fin]) if np.any(fin) else float('inf'):.3g} | {np.median(semi[sel]):.3g} |")
    return {"points": M, "misses": int(np.count_nonzero(~inside)), "seconds": dt}


def run_synthetic(points, r, alpha, seed):
    rng = np.random.default_rng(seed)
    total = {"points": 0, "misses": 0, "seconds": 0.0}
    for N in (2, 3, 4):
        cams, X = synthetic(rng, points // 3, N)
        s = compare(cams, X, observe(rng, cams, X, r), r, alpha, f"synthetic, N = {N}")
        for k in total:
            total[k] += s[k]
    return total


def run_oxford(limit, r, alpha, seed, data_dir=None):
    from tritools.io.oxford import DataNotFoundError, load_sequence

    rng = np.random.default_rng(seed)
    for name in ("merton1", "library", "wadham"):
        try:
            seq = load_sequence(name, data_dir)
        except (DataNotFoundError, OSError) as exc:
            print(f"\n{name}: skipped ({exc})")
            continue
        for N in (2, 3):
            tracks = [t for t in seq.tracks if t.n_views == N][:limit]
            if not tracks:
                continue
            cams = np.array([seq.cameras[list(t.views)] for t in tracks])
            x_real = np.array([t.points2d for t in tracks])
            X = l2_estimates(cams, x_real)                 # taken as the truth, then re-observed
            compare(cams, X, observe(rng, cams, X, r), r, alpha, f"Oxford {name} (real cameras), N = {N}")


def run_colmap(n_points, r):
    from tritools.sfm.pipeline import prepare_geometry
    from tritools.sfm.quality import QualityOptions, point_quality
    from tritools.sfm.synthetic import synthetic_arrays

    a, X = synthetic_arrays(n_points, n_images=60, noise_px=0.3, seed=1)
    geom = prepare_geometry(a)
    t0 = time.perf_counter()
    q = point_quality(a, geom, QualityOptions(keypoint_radius=r))
    dt = time.perf_counter() - t0
    lengths = np.diff(a.track_offsets)
    print(f"\n### SfM path: synthetic COLMAP model, {n_points} points, 60 images, tracks mean "
          f"{lengths.mean():.2f} (max {lengths.max()}), keypoint radius {r} px (Gaussian noise 0.3 px)\n")
    print(f"point_quality (angles + certified uncertainty of every point): {dt:.1f} s on one core "
          f"({1e3 * dt / n_points:.2f} ms/point); statuses {q.summary()['uncertainty_status']}; "
          f"median radius {q.summary()['median_radius']:.4g}")
    err = np.linalg.norm(a.point_xyz - X, axis=1)
    ok = np.isfinite(q.radius)
    print(f"input xyz (truth moved by 0.05): |X - xyz| <= radius for {np.mean(err[ok] <= q.radius[ok]):.2%} of "
          f"the bounded points (not a coverage claim: the noise is Gaussian and the xyz is not an estimate)")


def run_level(trials, seed):
    """Level-set bounds (tau = gamma_UB + 0.5 px) against the certified point itself, per N."""
    import tritools

    rng = np.random.default_rng(seed)
    print("\n### Level sets {X : gamma(X) <= gamma_UB + 0.5}: point regions, noise uniform in +-0.5 px\n")
    print("| N | problems | level bounds [ms] | triangulate [ms] | ratio | median gap / width | "
          "points of L sampled | outside the bounds |")
    print("|---|---|---|---|---|---|---|---|")
    for N in (2, 3, 4, 5):
        tl = tt = 0.0
        gaps, sampled, outside = [], 0, 0
        for _ in range(trials):
            cams, X = synthetic(rng, 1, N)
            cams, X = cams[0], X[0]
            b = 10 ** rng.uniform(-0.5, 0.5)                 # well-conditioned baselines here
            cams = np.array([look_at(np.array([b * (i - (N - 1) / 2), 0.3 * i, -5.0]), X) for i in range(N)])
            x = project_stack(cams[None], X[None])[0][0] + rng.uniform(-0.5, 0.5, (N, 2))
            regs = [tritools.Point(p) for p in x]
            t0 = time.perf_counter()
            opt = tritools.triangulate(cams, regs)
            tt += time.perf_counter() - t0
            tau = opt.gamma_ub + 0.5
            t0 = time.perf_counter()
            res = tritools.uncertainty(cams, regs, level=tau, estimate=opt.X)
            tl += time.perf_counter() - t0
            gaps.append(res.gap_rel)
            P = opt.X + rng.uniform(-1, 1, (4000, 3)) * (res.hi - res.lo)
            inL = P[tritools.gamma(P, cams, regs) <= tau]
            sampled += len(inL)
            outside += int(np.count_nonzero(~np.all((inL >= res.lo) & (inL <= res.hi), axis=1)))
        print(f"| {N} | {trials} | {1e3 * tl / trials:.1f} | {1e3 * tt / trials:.1f} | {tl / tt:.1f} | "
              f"{np.median(gaps):.1e} | {sampled} | {outside} |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=10000, help="synthetic points (split over N = 2, 3, 4)")
    ap.add_argument("--radius", type=float, default=1.0, help="disc radius r in pixels")
    ap.add_argument("--alpha", type=float, default=1e-3, help="covariance ellipsoid level 1 - alpha")
    ap.add_argument("--oxford-tracks", type=int, default=1500, help="tracks per sequence and N (0: skip)")
    ap.add_argument("--colmap-points", type=int, default=50000, help="points of the SfM timing (0: skip)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--level-trials", type=int, default=8, help="level-set problems per N (0: skip)")
    ap.add_argument("--data-dir", default=None, help="Oxford data (default: $TRITOOLS_DATA, ../shared/data/oxford)")
    args = ap.parse_args(argv)
    total = {"points": 0, "misses": 0, "seconds": 0.0}
    if args.points >= 3:
        total = run_synthetic(args.points, args.radius, args.alpha, args.seed)
        print(f"\nsynthetic total: {total['points']} points, {total['misses']} outside their certified set, "
              f"{total['seconds']:.1f} s")
    if args.oxford_tracks:
        run_oxford(args.oxford_tracks, args.radius, args.alpha, args.seed, args.data_dir)
    if args.level_trials:
        run_level(args.level_trials, args.seed)
    if args.colmap_points:
        run_colmap(args.colmap_points, 1.5)
    return total


if __name__ == "__main__":
    main()
