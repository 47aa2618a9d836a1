"""Speed of batched robust (TLS) triangulation: ``triangulate_points(..., robust=c)`` on synthetic tracks.

M points in [-1, 1]^3, V = 10 cameras on a circle of radius 6 looking at the origin (f = 800, 1024 x 768), each
point seen by 3..10 random views, 1 px noise, a fraction of the observations (only in tracks of >= 3 views)
replaced by uniform image points; threshold c = 4 px.  Prints ms/point, the certified fraction and how many
injected outliers the inlier sets caught.  With ``--compare``: the same batch also without the parent-frame
sub-bounds (``tritools.solve.robust_bounds.IN_PARENT = False``, every subset verified in its own frame) and
through pycolmap's LO-RANSAC ``estimate_triangulation`` (uncertified; max_error = c), interleaved, CPU time of
this process for each.

    OPENBLAS_NUM_THREADS=1 python benchmarks/robust_speed.py --points 2000 [--profile] [--compare]
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


K = np.array([[800.0, 0, 512], [0, 800, 384], [0, 0, 1]])


def pycolmap_batch(C: np.ndarray, x: np.ndarray, threshold: float) -> int:
    """pycolmap ``estimate_triangulation`` (LO-RANSAC, reprojection error, max_error = threshold) on every track;
    the number of points it returned."""
    import pycolmap

    Kinv = np.linalg.inv(K)
    cam = pycolmap.Camera(model="PINHOLE", width=1024, height=768, params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]])
    poses = [pycolmap.Rigid3d(pycolmap.Rotation3d((Kinv @ P)[:, :3]), (Kinv @ P)[:, 3]) for P in C]
    opt = pycolmap.EstimateTriangulationOptions()
    opt.residual_type = pycolmap.TriangulationResidualType.REPROJECTION_ERROR
    opt.ransac.max_error = threshold
    found = 0
    for obs in x:
        vis = np.nonzero(np.isfinite(obs[:, 0]))[0]
        out = pycolmap.estimate_triangulation(obs[vis], [poses[v] for v in vis], [cam] * len(vis), opt)
        found += out is not None
    return found


def compare(C, x, threshold: float, rounds: int = 2) -> None:
    """CPU ms/point of the batch with and without the parent-frame sub-bounds and of pycolmap, interleaved."""
    import tritools
    import tritools.solve.robust_bounds as rb

    cpu = {"parent frame": [], "per subset": [], "pycolmap": []}
    for _ in range(rounds):
        for name, flag in (("parent frame", True), ("per subset", False)):
            rb.IN_PARENT = flag
            c0 = time.process_time()
            res = tritools.triangulate_points(C, x, robust=threshold)
            cpu[name].append(time.process_time() - c0)
            print(f"  {name}: certified {int(np.sum(res.optimal))}/{len(x)}")
        rb.IN_PARENT = True
        c0 = time.process_time()
        found = pycolmap_batch(C, x, threshold)
        cpu["pycolmap"].append(time.process_time() - c0)
        print(f"  pycolmap: {found}/{len(x)} points")
    med = {k: 1e3 * float(np.median(v)) / len(x) for k, v in cpu.items()}
    print(" | ".join(f"{k} {v:.2f} ms/point CPU" for k, v in med.items()) +
          f" | per subset / parent frame {med['per subset'] / med['parent frame']:.2f}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=2000)
    ap.add_argument("--outliers", type=float, default=0.1)
    ap.add_argument("--threshold", type=float, default=4.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--compare", action="store_true", help="also without the parent-frame sub-bounds, and pycolmap")
    args = ap.parse_args(argv)
    import tritools

    C, x, out = make_batch(args.points, frac=args.outliers, seed=args.seed)
    if args.compare:
        compare(C, x, args.threshold)
        return 0
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
          f"visible inliers dropped {int((~out & ~inl & np.isfinite(x[..., 0])).sum())}, "
          f"branch and bound run for {sum(' 0 nodes' not in str(m) for m in res.message)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
