"""Speed of batched robust (TLS) triangulation: ``triangulate_points(..., robust=c)`` on synthetic tracks.

M points in [-1, 1]^3, V = 10 cameras on a circle of radius 6 looking at the origin (f = 800, 1024 x 768), each
point seen by 3..10 random views, 1 px noise, a fraction of the observations (only in tracks of >= 3 views)
replaced by uniform image points; threshold c = 4 px.  Prints ms/point, the certified fraction and how many
injected outliers the inlier sets caught.

    OPENBLAS_NUM_THREADS=1 python benchmarks/robust_speed.py --points 2000 [--profile]
"""
from __future__ import annotations

import argparse
import time

import numpy as np


def make_batch(M: int, V: int = 10, frac: float = 0.1, noise: float = 1.0, seed: int = 0):
    """(cameras (V, 3, 4), points2d (M, V, 2) with NaN where unseen, outlier mask (M, V))."""
    rng = np.random.default_rng(seed)
    K = np.array([[800.0, 0, 512], [0, 800, 384], [0, 0, 1]])
    cams = []
    for a in 2 * np.pi * np.arange(V) / V:
        c = np.array([6 * np.cos(a), 0.8 * np.sin(2 * a), 6 * np.sin(a)])
        z = -c / np.linalg.norm(c)
        x = np.cross([0.0, 1, 0], z)
        x /= np.linalg.norm(x)
        R = np.vstack([x, np.cross(z, x), z])
        cams.append(K @ np.hstack([R, (-R @ c)[:, None]]))
    C = np.array(cams)
    X = rng.uniform(-1, 1, (M, 3))
    Xh = np.hstack([X, np.ones((M, 1))])
    u = np.einsum("vij,mj->mvi", C, Xh)
    x = u[..., :2] / u[..., 2:] + noise * rng.normal(size=(M, V, 2))
    n_vis = rng.integers(3, V + 1, M)
    vis = np.zeros((M, V), bool)
    for m in range(M):
        vis[m, rng.choice(V, n_vis[m], replace=False)] = True
    cand = np.argwhere(vis)
    n_out = int(round(frac * len(cand)))
    out = np.zeros((M, V), bool)
    for m, v in cand[rng.choice(len(cand), n_out, replace=False)]:
        if vis[m].sum() - out[m].sum() > 2:          # keep >= 2 inliers per track
            out[m, v] = True
    x[out] = rng.uniform([0, 0], [1024, 768], (int(out.sum()), 2))
    x[~vis] = np.nan
    return C, x, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2000)
    ap.add_argument("--outliers", type=float, default=0.1)
    ap.add_argument("--threshold", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true")
    args = ap.parse_args(argv)
    import tritools

    C, x, out = make_batch(args.points, frac=args.outliers, seed=args.seed)
    call = lambda: tritools.triangulate_points(C, x, robust=args.threshold)  # noqa: E731
    t, cpu = time.perf_counter(), time.process_time()
    if args.profile:
        import cProfile
        import pstats
        prof = cProfile.Profile()
        res = prof.runcall(call)
        pstats.Stats(prof).sort_stats("cumulative").print_stats(45)
    else:
        res = call()
    dt, dcpu = time.perf_counter() - t, time.process_time() - cpu
    opt, inl = np.asarray(res.optimal), np.asarray(res.inliers)
    print(f"{args.points} points, {int(out.sum())} outlier observations: {1e3 * dt / args.points:.2f} ms/point wall, "
          f"{1e3 * dcpu / args.points:.2f} ms/point CPU, "
          f"certified {int(opt.sum())}/{len(opt)}, outliers caught {int((out & ~inl).sum())}/{int(out.sum())}, "
          f"visible inliers dropped {int((~out & ~inl & np.isfinite(x[..., 0])).sum())}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
