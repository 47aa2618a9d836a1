"""Cheirality: Hartley & Zisserman's depth rule (eq. (6.15)) with the world frame's handedness, in the one
place every in_front judgement uses (tritools.model.cameras.depths / depths_stack).

References are independent of the code: for P = K [R | t] with det K > 0, det R = +1 the depth is the third
coordinate of R X + t; mirroring the world (X -> S X, P -> P diag(S, 1), det S = -1) leaves every image
point unchanged and makes every camera det M < 0 (a reflected frame)."""
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from tritools import Status, depths, triangulate, triangulate_points
from tritools.model.cameras import WorldFrame, depths_stack, world_frame_of
from tritools.model.regions import Point

ROOT = pathlib.Path(__file__).resolve().parents[1]
S = np.diag([1.0, 1.0, -1.0])


def rotation(rng):
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def scene(rng, n_views=4):
    """Right-handed cameras K [R | t] looking at the origin from distance ~10, and a point near the origin."""
    K = np.array([[800.0, 0.5, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])
    Rs = [rotation(rng) for _ in range(n_views)]
    ts = [np.array([0.3, -0.2, 10.0]) + rng.normal(scale=0.1, size=3) for _ in Rs]
    P = np.array([K @ np.hstack([R, t[:, None]]) for R, t in zip(Rs, ts)])
    X = rng.normal(scale=0.5, size=3)
    ref = np.array([(R @ X + t)[2] for R, t in zip(Rs, ts)])       # the depth, independently
    return P, X, ref


def _intrinsics(P):
    """K of each camera K [R | t] built by :func:`scene` (the same K for all)."""
    return [np.array([[800.0, 0.5, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])] * len(P)


def mirrored(P, X):
    return P @ np.diag([1.0, 1.0, -1.0, 1.0]), S @ X


@pytest.mark.parametrize("seed", range(5))
def test_depth_is_the_camera_z_and_invariant_under_any_scale_of_P(seed):
    rng = np.random.default_rng(seed)
    P, X, ref = scene(rng)
    assert np.all(ref > 0)
    np.testing.assert_allclose(depths(X, P), ref, rtol=1e-12)
    k = rng.choice([-1.0, 1.0], size=len(P)) * 10.0 ** rng.uniform(-6, 6, size=len(P))
    np.testing.assert_allclose(depths(X, P * k[:, None, None]), ref, rtol=1e-12)  # P and -P: same camera
    np.testing.assert_allclose(depths(X, -P), ref, rtol=1e-12)
    for Xb in rng.normal(scale=50.0, size=(20, 3)):                     # far points, some behind some cameras
        z = depths(Xb, P)
        Rt = np.array([np.linalg.solve(KK, Q) for KK, Q in zip(_intrinsics(P), P)])
        np.testing.assert_allclose(z, Rt[:, 2] @ np.append(Xb, 1), rtol=1e-9, atol=1e-9)
        np.testing.assert_array_equal(np.sign(depths(Xb, -P)), np.sign(z))


@pytest.mark.parametrize("seed", range(5))
def test_reflected_frame_det_m_negative_depths_in_front(seed):
    rng = np.random.default_rng(seed)
    P, X, ref = scene(rng)
    Pm, Xm = mirrored(P, X)
    assert np.all(np.linalg.det(Pm[:, :, :3]) < 0)
    for Q in (Pm, -Pm):                                  # either sign of every camera
        np.testing.assert_allclose(Q[:, :, :] @ np.append(Xm, 1) / (Q @ np.append(Xm, 1))[:, 2:],
                                   P @ np.append(X, 1) / (P @ np.append(X, 1))[:, 2:], rtol=1e-12)
        np.testing.assert_allclose(depths(Xm, Q, WorldFrame.REFLECTED), ref, rtol=1e-12)
        np.testing.assert_allclose(depths(Xm, Q), -ref, rtol=1e-12)      # right-handed reading: behind
        np.testing.assert_allclose(depths(Xm, Q, "reflected"), ref, rtol=1e-12)


def test_depths_stack_equals_depths_in_both_frames():
    rng = np.random.default_rng(7)
    C, Xs = [], []
    for m in range(6):
        P, X, _ = scene(rng, 3)
        if m % 2:
            P, X = mirrored(P, X)
        C.append(P * rng.choice([-1.0, 1.0], size=3)[:, None, None])
        Xs.append(X + (0 if m < 4 else np.array([0, 0, 30.0])))
    C, Xs = np.array(C), np.array(Xs)
    for frame in WorldFrame:
        stacked = depths_stack(C, Xs, frame)
        one = np.array([depths(X, P, frame) for P, X in zip(C, Xs)])
        np.testing.assert_allclose(stacked, one, rtol=1e-13)
    with pytest.raises(ValueError, match="world_frame"):
        depths(Xs[0], C[0], "left")


def test_world_frame_of_a_reconstruction():
    rng = np.random.default_rng(3)
    P, _, _ = scene(rng, 5)
    Xs = rng.normal(scale=0.5, size=(40, 3))
    C = np.broadcast_to(P, (40,) + P.shape)
    assert world_frame_of(C, Xs) is WorldFrame.RIGHT_HANDED
    Cm = C @ np.diag([1.0, 1.0, -1.0, 1.0])
    assert world_frame_of(Cm, Xs @ S) is WorldFrame.REFLECTED
    flip = rng.choice([-1.0, 1.0], size=5)[:, None, None]               # any camera's sign: same answer
    assert world_frame_of(Cm * flip, Xs @ S) is WorldFrame.REFLECTED
    with pytest.raises(ValueError):
        world_frame_of(np.zeros((1, 1, 3, 4)), np.zeros((1, 3)))


def test_triangulate_judges_in_front_in_the_given_frame_on_both_paths():
    rng = np.random.default_rng(11)
    P, X, _ = scene(rng, 3)
    Pm, Xm = mirrored(P, X)
    x = np.array([(Q @ np.append(Xm, 1))[:2] / (Q @ np.append(Xm, 1))[2] for Q in Pm])
    regions = [Point(p) for p in x]
    r = triangulate(Pm, regions, require_in_front=True, world_frame="reflected")
    assert r.status == Status.OPTIMAL and r.optimal and r.in_front and np.all(r.depths > 0)
    np.testing.assert_allclose(r.X, Xm, atol=1e-6)
    r = triangulate(-Pm, regions, require_in_front=True)                 # right-handed reading: behind
    assert r.status == Status.BEHIND_CAMERA and not r.in_front
    pts = np.broadcast_to(x, (4,) + x.shape).copy()                     # (M=4, V=3, 2)
    out = triangulate_points(Pm, pts, require_in_front=True, world_frame="reflected")
    assert np.all(out.in_front) and np.all(out.status == Status.OPTIMAL.value)
    out = triangulate_points(Pm, pts, require_in_front=True)
    assert not np.any(out.in_front) and np.all(out.status == Status.BEHIND_CAMERA.value)


# ----------------------------------------------------------------------------- real data (Oxford VGG)
@pytest.mark.parametrize("name,stem", [("house", "house"), ("corridor", "bt")])
def test_oxford_reflected_sequences_own_points_are_in_front(name, stem, oxford_data):
    """The datasets' own 3D points (.p3d, one row per track) lie in front of every camera that sees them
    in the sequence's frame, which the loader reads off the tracks as reflected."""
    from tritools.io.oxford import load_sequence

    data = oxford_data
    seq = load_sequence(name, data, min_views=1)
    assert seq.world_frame is WorldFrame.REFLECTED
    assert np.all(np.linalg.det(seq.cameras[:, :, :3]) < 0)
    p3d = np.loadtxt(data / name / f"{stem}.p3d")
    d = np.concatenate([depths(p3d[t.track_id], seq.cameras[list(t.views)], seq.world_frame) for t in seq.tracks])
    assert d.size > 2000 and np.all(d > 0)
    for other in ("library", "wadham"):
        assert load_sequence(other, data).world_frame is WorldFrame.RIGHT_HANDED


@pytest.mark.slow
def test_cli_dataset_house_certifies_in_front(oxford_data):
    data = oxford_data
    run = subprocess.run([sys.executable, "-m", "tritools", "dataset", "house", "--limit", "50", "--require-in-front",
                          "--json", "--data-dir", str(data)], capture_output=True, text=True, cwd=ROOT,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert run.returncode == 0, run.stderr
    total = json.loads(run.stdout)["total"]
    assert total["cases"] == 50 and total["certified"] == 50
    run = subprocess.run([sys.executable, "-m", "tritools", "dataset", "house", "--limit", "10", "--require-in-front",
                          "--world-frame", "right_handed", "--json", "--data-dir", str(data)], capture_output=True,
                         text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert run.returncode == 0 and json.loads(run.stdout)["total"]["certified"] == 0


def test_cli_solve_world_frame(tmp_path):
    """`tritools solve --world-frame reflected` on a mirrored camera pair: certified in front; read as
    right-handed (the default) the same point is behind both cameras."""
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    pair = np.array([K @ np.c_[np.eye(3), [[1.0], [0], [0]]], K @ np.c_[np.eye(3), [[-1.0], [0], [0]]]])
    X = np.array([0.3, 0.2, 5.0])
    x = [(P[:2] @ np.append(X, 1) / (P[2] @ np.append(X, 1))).tolist() for P in pair]
    reflected = -(pair @ np.diag([1.0, 1.0, -1.0, 1.0]))                 # any sign: the same cameras
    path = tmp_path / "p.json"
    path.write_text(json.dumps({"cameras": reflected.tolist(), "regions": x}))
    out = {}
    for frame in ("reflected", "right_handed"):
        run = subprocess.run([sys.executable, "-m", "tritools", "solve", str(path), "--json", "--require-in-front",
                              "--world-frame", frame], capture_output=True, text=True, cwd=ROOT,
                             env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
        assert run.returncode == 0, run.stderr
        doc = json.loads(run.stdout)
        out[frame] = doc[0] if isinstance(doc, list) else doc
    assert out["reflected"]["status"] == "optimal" and out["reflected"]["in_front"] is True
    assert out["right_handed"]["status"] == "behind_camera" and out["right_handed"]["in_front"] is False


def test_colmap_conversion_refuses_a_reflected_frame():
    """COLMAP frames are right-handed: mirrored projections would give a model whose points are all behind
    their cameras, so the conversion refuses them (and accepts the same scene unmirrored)."""
    from tritools.io.colmap import model_from_projections, rotation_from_qvec

    rng = np.random.default_rng(2)
    K0 = np.array([[800.0, 0.0, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])      # COLMAP: no skew
    P = np.array([K0 @ np.c_[rotation(rng), [0.2 * k, 0.1, 8.0]] for k in range(3)])
    Xs = rng.normal(scale=0.5, size=(5, 3))
    tracks = [{v: (P[v] @ np.append(X, 1))[:2] / (P[v] @ np.append(X, 1))[2] for v in range(3)} for X in Xs]
    model = model_from_projections(P, (640, 480), tracks)
    for im in model.images.values():                          # every point in front in COLMAP's own terms
        R, t = rotation_from_qvec(np.array(im.qvec)), np.array(im.tvec)
        for *_, pid in im.points2D:
            assert (R @ np.array(model.points3D[pid].xyz) + t)[2] > 0
    Pm = P @ np.diag([1.0, 1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="reflected"):
        model_from_projections(Pm, (640, 480), tracks)


@pytest.mark.parametrize("path", ["points", "discs", "robust"])
def test_every_single_call_path_judges_in_front_in_the_given_frame(path):
    """The single-call verification of points, the disc verification and the robust search report depths in
    the world frame they are given (a mirrored scene is in front only when read as ``reflected``)."""
    from tritools import Ellipse

    rng = np.random.default_rng(5)
    P, X, _ = scene(rng, 4)
    Pm, Xm = mirrored(P, X)
    x = np.array([(Q @ np.append(Xm, 1))[:2] / (Q @ np.append(Xm, 1))[2] for Q in Pm])
    regions = [Ellipse(p, np.eye(2) / 4.0) for p in x] if path == "discs" else [Point(p) for p in x]
    kw = {"robust": 5.0} if path == "robust" else {}
    r = triangulate(Pm, regions, require_in_front=True, world_frame="reflected", **kw)
    assert r.optimal and r.status == Status.OPTIMAL and r.in_front and np.all(r.depths > 0), (r.status, r.depths)
    r = triangulate(Pm, regions, require_in_front=True, **kw)
    assert r.status == Status.BEHIND_CAMERA and not r.in_front and np.all(r.depths < 0)


def _far_discs(seed: int):
    """Two cameras (baseline 1, f = 800) and discs of 0.5 / 0.3 px around noisy views of a point at depth 1e7: the
    cost-0 set holds points behind both cameras and points in front (the disparity may be made positive inside the
    discs)."""
    import tritools

    P1 = np.diag([800.0, 800, 1]) @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.diag([800.0, 800, 1]) @ np.hstack([np.eye(3), [[-1.0], [0], [0]]])
    cams = np.array([P1, P2])
    rng = np.random.default_rng(seed)
    obs = [tritools.project(np.array([0.3, 0.2, 1e7]), P) + rng.normal(size=2) for P in cams]
    return cams, [tritools.Ellipse.circle(obs[0], 0.5), tritools.Ellipse.circle(obs[1], 0.3)]


def test_uncertain_regions_with_minimisers_in_front_are_not_behind_camera():
    """Review 21b F1: the certified estimate of two discs lay behind both cameras (depth -1554) while cost-0 points
    in front exist; the result is now an in-front minimiser (tritools.solve.front), certified, with gamma_ub the
    gamma of the point reported, and require_in_front keeps OPTIMAL."""
    import tritools

    cams, regs = _far_discs(0)
    for opts in ({}, {"require_in_front": True}):
        r = triangulate(cams, regs, **opts)
        assert r.status == Status.OPTIMAL and r.optimal and r.in_front and np.all(depths(r.X, cams) > 0)
        assert r.gamma_ub == pytest.approx(tritools.gamma(r.X, cams, regs), abs=1e-12)
        assert r.gamma_lb <= r.gamma_ub <= 1e-9


def test_point_regions_with_the_optimum_behind_stay_behind_camera():
    """Point regions: the minimiser is unique, so an optimum behind the cameras stays the answer (behind_camera under
    require_in_front), the in-front search not taken."""
    P1 = np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.hstack([np.eye(3), [[-1.0], [0], [0]]])
    X = np.array([0.2, 0.1, -5.0])                               # behind both cameras
    x = [P @ np.append(X, 1.0) for P in (P1, P2)]
    pts = [Point(h[:2] / h[2]) for h in x]
    r = triangulate(np.array([P1, P2]), pts, require_in_front=True)
    assert r.status == Status.BEHIND_CAMERA and not r.in_front


def test_batches_of_discs_look_for_the_in_front_minimiser_too():
    """The disc batch (triangulate_many's verification stack) hands a certified row behind a camera to the single
    call, which looks for an in-front minimiser: the batch's result equals the single call's (in front, certified)."""
    import tritools

    probs = [_far_discs(s) for s in (0, 1, 2)]
    many = tritools.triangulate_many(probs, progress=False)
    for (cams, regs), rm in zip(probs, many):
        one = triangulate(cams, regs)
        assert (rm.status, rm.optimal, rm.in_front) == (one.status, one.optimal, one.in_front)
        if one.in_front:
            assert np.all(depths(rm.X, cams) > 0)
    assert many[0].in_front and many[0].optimal


def test_the_in_front_search_runs_only_for_cost_zero_optima(monkeypatch):
    """Review 21c F1: the in-front search (tritools.solve.front) ran for every certified region result behind a
    camera and found nothing where the optimum is positive (a unique minimiser): 0.1-0.6 s wasted per call.  It now
    runs only where gamma* = 0 within the rule (the minimisers may form a set); discs around exact projections of a
    point behind with 2 px noise added (positive optimum) do not call it and stay behind."""
    import importlib

    import tritools

    outcome = importlib.import_module("tritools.solve.stages.outcome")
    calls = []
    real = outcome.front_estimate
    monkeypatch.setattr(outcome, "front_estimate", lambda ctx, X: calls.append(1) or real(ctx, X))
    P1 = np.diag([800.0, 800, 1]) @ np.hstack([np.eye(3), np.zeros((3, 1))])
    P2 = np.diag([800.0, 800, 1]) @ np.hstack([np.eye(3), [[-1.0], [0], [0]]])
    P3 = np.diag([800.0, 800, 1]) @ np.hstack([np.eye(3), [[0.0], [-1.0], [0]]])
    cams = np.array([P1, P2, P3])
    X = np.array([0.2, 0.1, -5.0])
    rng = np.random.default_rng(3)
    obs = [tritools.project(X, P) + rng.normal(scale=2.0, size=2) for P in cams]
    r = triangulate(cams, [tritools.Ellipse.circle(o, 0.2) for o in obs])
    assert r.optimal and not r.in_front and r.gamma_ub > 0.1 and calls == []
    cams2, regs2 = _far_discs(0)                                   # cost 0: the search runs and finds a point in front
    assert triangulate(cams2, regs2).in_front and calls
