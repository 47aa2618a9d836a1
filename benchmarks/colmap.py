"""Benchmark of ``tritools colmap`` on synthetic COLMAP models (issue #15).

For each size and camera model: a seeded synthetic binary model (:func:`tritools.sfm.synthetic.
synthetic_arrays`: ring of images, tracks of consecutive images, realistic noise) is written by one
process; a fresh process pinned to one core (BLAS single-threaded) runs
:func:`tritools.sfm.retriangulate_folder` on it -- streaming in chunks, binary in and out -- and
reports the time of each stage (open: cameras and images; undistort: every track keypoint, one call
per camera; read: points3D streamed and checked; certify: grouping, the solver, gamma, cheirality,
errors; write), the peak RSS of that process, the certified counts, the RMS of gamma (RMS
reprojection error per coordinate, undistorted pixels) over the input and the written points, and
the median 3D error against the true points.  (The synthetic input xyz is the truth moved by
0.05: closer to the truth than the L2 optimum of short-baseline tracks can be, so the 3D error may
grow where gamma -- what is optimised and certified -- falls.)  With pycolmap installed, a third
process triangulates the first ``--pycolmap`` tracks with COLMAP's ``estimate_triangulation``
(LO-RANSAC, reprojection residual) and compares its gamma with ours (certified optima: never worse).

    python benchmarks/colmap.py                                  # 10k and 50k points, PINHOLE and OPENCV
    python benchmarks/colmap.py --points 1000000 --cameras PINHOLE --images 200 --pycolmap 0
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SINGLE_THREAD = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _child(mode: str, **kw) -> dict:
    env = dict(os.environ, **SINGLE_THREAD, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, __file__, "--child", mode, "--args", json.dumps(kw)]
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
    if out.returncode:
        raise RuntimeError(f"{mode} failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def _pin() -> None:
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})


def generate(folder: str, n_points: int, n_images: int, camera: str, noise: float, seed: int) -> dict:
    """Write the synthetic input model and its true points."""
    import numpy as np

    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    t0 = time.perf_counter()
    a, truth = synthetic_arrays(n_points, n_images, camera, noise, seed)
    write_model_arrays(a, Path(folder) / "in", "bin")
    np.save(Path(folder) / "truth.npy", truth)
    return {"seconds": time.perf_counter() - t0, "n_observations": int(a.n_observations),
            "n_keypoints": int(len(a.kp_xy))}


def run(folder: str, chunk_points: int) -> dict:
    """Re-triangulate the model on one core; timings, peak RSS, counts and RMS figures."""
    _pin()
    t_import = time.perf_counter()
    import numpy as np

    from tritools.io.colmap import read_model_arrays
    from tritools.sfm import RetriangulationOptions, retriangulate_folder
    from tritools.sfm.pipeline import point_gammas, prepare_geometry

    t_import = time.perf_counter() - t_import
    res = retriangulate_folder(Path(folder) / "in", Path(folder) / "out", RetriangulationOptions(
        chunk_points=chunk_points))
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024            # KiB on Linux -> MiB
    r = res.report
    a_in = read_model_arrays(Path(folder) / "in")
    a_out = read_model_arrays(Path(folder) / "out")
    truth = np.load(Path(folder) / "truth.npy")
    solved = np.isfinite(r.gamma_ub)

    def rms(v):
        """Root mean square."""
        return float(np.sqrt(np.mean(np.square(v)))) if len(v) else float("nan")
    geom = prepare_geometry(a_out)
    return {"timings": res.timings, "import": t_import, "peak_rss_mib": rss, "n_points": r.n_points,
            "n_certified": r.n_certified, "status": r.status_counts(), "n_behind": r.n_behind,
            "rms_gamma_in": rms(r.gamma_input[solved]), "rms_gamma_out": rms(point_gammas(a_out, geom)[solved]),
            "rms_3d_in": rms(np.linalg.norm(a_in.point_xyz - truth, axis=1)),
            "rms_3d_out": rms(np.linalg.norm(a_out.point_xyz - truth, axis=1)),
            "median_3d_in": float(np.median(np.linalg.norm(a_in.point_xyz - truth, axis=1))),
            "median_3d_out": float(np.median(np.linalg.norm(a_out.point_xyz - truth, axis=1)))}


def compare_pycolmap(folder: str, n: int) -> dict:
    """gamma of pycolmap's estimate_triangulation against ours on the first n tracks."""
    _pin()
    try:
        import pycolmap
    except ImportError:
        return {"skipped": "pycolmap not installed"}
    import numpy as np

    from tritools.io.colmap import read_model_arrays
    from tritools.sfm.pipeline import point_gammas, prepare_geometry, rotations

    a = read_model_arrays(Path(folder) / "in")
    ours = read_model_arrays(Path(folder) / "out")
    cams = [pycolmap.Camera(model=m, width=int(w), height=int(h), params=p)
            for m, w, h, p in zip(a.camera_models, a.camera_width, a.camera_height, a.camera_params)]
    R = rotations(a.image_qvec)
    poses = [pycolmap.Rigid3d(pycolmap.Rotation3d(R[v]), a.image_tvec[v]) for v in range(a.n_images)]
    opt = pycolmap.EstimateTriangulationOptions()
    opt.residual_type = pycolmap.TriangulationResidualType.REPROJECTION_ERROR
    opt.ransac.max_error = 4.0
    n = min(n, a.n_points)
    xyz = a.point_xyz.copy()
    t0 = time.perf_counter()
    for p in range(n):
        s, e = a.track_offsets[p], a.track_offsets[p + 1]
        im = a.track_image[s:e]
        out = pycolmap.estimate_triangulation(a.kp_xy[a.kp_offsets[im] + a.track_kp[s:e]], [poses[i] for i in im],
                                              [cams[a.image_camera[i]] for i in im], opt)
        if out is not None:
            xyz[p] = out["xyz"]
    seconds = time.perf_counter() - t0
    geom = prepare_geometry(a)
    g_col = point_gammas(a, geom, xyz)[:n]
    g_our = point_gammas(a, geom, ours.point_xyz)[:n]
    ok = np.isfinite(g_col) & np.isfinite(g_our)
    return {"n": n, "seconds": seconds, "rms_gamma_pycolmap": float(np.sqrt(np.mean(g_col[ok] ** 2))),
            "rms_gamma_ours": float(np.sqrt(np.mean(g_our[ok] ** 2))),
            "ours_not_worse": int(np.count_nonzero(g_our[ok] <= g_col[ok] + 1e-9)), "compared": int(ok.sum()),
            "max_excess": float(np.max(g_our[ok] - g_col[ok], initial=0.0))}


def main(argv=None) -> int:
    """Run the benchmark and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, nargs="+", default=[10_000, 50_000], help="model sizes (points)")
    ap.add_argument("--cameras", nargs="+", default=["PINHOLE", "OPENCV"], choices=("PINHOLE", "OPENCV"),
                    help="camera models")
    ap.add_argument("--images", type=int, default=30, help="images per model (default 30)")
    ap.add_argument("--noise", type=float, default=0.5, help="keypoint noise in pixels (default 0.5)")
    ap.add_argument("--seed", type=int, default=0, help="random seed")
    ap.add_argument("--chunk-points", type=int, default=100_000, help="points per chunk (default 100000)")
    ap.add_argument("--pycolmap", type=int, default=2000, help="tracks compared with pycolmap (0: none)")
    ap.add_argument("--json", default=None, help="also write the raw results to this JSON file")
    ap.add_argument("--child", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--args", default="{}", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        fn = {"generate": generate, "run": run, "pycolmap": compare_pycolmap}[args.child]
        print(json.dumps(fn(**json.loads(args.args))))
        return 0
    rows, raw = [], []
    for n in args.points:
        for cam in args.cameras:
            with tempfile.TemporaryDirectory(prefix="tritools-colmap-bench-") as d:
                gen = _child("generate", folder=d, n_points=n, n_images=args.images, camera=cam, noise=args.noise,
                             seed=args.seed)
                r = _child("run", folder=d, chunk_points=args.chunk_points)
                pc = _child("pycolmap", folder=d, n=args.pycolmap) if args.pycolmap else {"skipped": "--pycolmap 0"}
            raw.append({"points": n, "camera": cam, "generate": gen, "run": r, "pycolmap": pc})
            t = r["timings"]
            rows.append([f"{n:,}", cam, f"{gen['n_observations']:,}", f"{t['open']:.2f}", f"{t['geometry']:.2f}",
                         f"{t['read']:.2f}", f"{t['solve']:.2f}", f"{t['write']:.2f}", f"{t['total']:.2f}",
                         f"{r['peak_rss_mib']:.0f}", f"{r['n_certified']:,}/{r['n_points']:,}",
                         f"{r['rms_gamma_in']:.3f} -> {r['rms_gamma_out']:.3f}",
                         f"{r['median_3d_in']:.4f} -> {r['median_3d_out']:.4f}",
                         "-" if "skipped" in pc else f"{pc['rms_gamma_pycolmap']:.4f} vs {pc['rms_gamma_ours']:.4f} "
                                                    f"({pc['ours_not_worse']}/{pc['compared']} not worse)"])
            print(f"done: {n} points, {cam}: {t['total']:.1f} s, {r['peak_rss_mib']:.0f} MiB, "
                  f"status {r['status']}", file=sys.stderr)
    head = ["points", "camera", "observations", "open s", "undistort s", "read s", "certify s", "write s", "total s",
            "peak RSS MiB", "certified", "RMS gamma px in -> out", "median 3D err in -> out", "pycolmap vs ours gamma"]
    print(f"python benchmarks/colmap.py {' '.join(argv if argv is not None else sys.argv[1:])}".rstrip())
    print(f"({args.images} images, noise {args.noise} px, seed {args.seed}, binary in/out, one core, "
          f"chunks of {args.chunk_points} points)\n")
    print("| " + " | ".join(head) + " |")
    print("|" + "|".join("---" for _ in head) + "|")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    if args.json:
        Path(args.json).write_text(json.dumps(raw, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
