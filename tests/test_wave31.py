"""Wave 31: collinear camera centres (review 31a: forward motion along the optical axis, rectified rigs).

Every plane through the line of collinear centres holds all of them, so Corollary 1's epipolar variety contains the
tuples on the lines of each such plane and its bound is capped by the best one (:func:`pencil_ceiling`) at every
degree; the plan now skips its futile degree-4 steps there and runs Theorem 1's view-clique step up to
:data:`~tritools.solve.plan.EXACT_VARIETY_COLLINEAR_MAX` views.  References: multi-start Levenberg-Marquardt (scipy)
for forward motion, the exact linear least-squares optimum for rectified rigs (tests/test_wave30.py)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
from tritools.model.geometry import fundamental_matrix
from tritools.solve.coplanar import collinear_centres, nearly_collinear_centres, pencil_ceiling, plane_lines_raw

from .test_wave30 import _rectified

K = np.array([[1000.0, 0, 640], [0, 1000, 360], [0, 0, 1]])


def _forward(N: int, seed: int, step: float = 0.3):
    """N cameras with R = I at (0, 0, i step): a straight drive along the optical axis; a point ahead, 1 px noise."""
    rng = np.random.default_rng(seed)
    cams = np.array([K @ np.c_[np.eye(3), [0.0, 0.0, -i * step]] for i in range(N)])
    X = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), (N - 1) * step + rng.uniform(4, 15)])
    h = cams @ np.append(X, 1.0)
    return cams, h[:, :2] / h[:, 2:] + rng.standard_normal((N, 2)), X


def _lm_reference(cams, x, starts) -> float:
    """The best gamma of Levenberg-Marquardt runs from ``starts`` (an independent upper bound of gamma*)."""
    def res(Y):
        h = cams @ np.append(Y, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()
    best = min(np.sum(least_squares(res, s, method="lm", xtol=1e-15, ftol=1e-15).fun ** 2) for s in starts)
    return float(np.sqrt(best / (2 * len(cams))))


def _starts(X, r, seed):
    rng = np.random.default_rng(seed)
    return [X, r.X] + [X + rng.normal(0, 1, 3) for _ in range(6)]


def test_pencil_ceiling_is_an_attained_epipolar_value():
    """The ceiling is the cost of a tuple on the lines of one plane through the centres' line: it satisfies every
    pair's epipolar relation, costs no more than the L2 optimum (the optimum's own plane is in the pencil), and no
    sampled plane of the pencil is cheaper."""
    cams, x, X = _forward(6, 0)
    s = pencil_ceiling(cams, x)
    best = _lm_reference(cams, x, [X])
    assert s is not None and 0 < s < 2 * 6 * best ** 2
    C = np.array([[0.0, 0.0, 0.3 * i] for i in range(6)])
    _, _, Vt = np.linalg.svd(C - C.mean(0))
    a, b = (plane_lines_raw(cams, np.append(n, -n @ C.mean(0))) for n in Vt[1:3])
    F = fundamental_matrix(cams[0], cams[3])

    def feet(t):
        lines = np.cos(t) * a + np.sin(t) * b
        d = np.einsum("ij,ij->i", lines, np.c_[x, np.ones(6)]) / np.linalg.norm(lines[:, :2], axis=1)
        return np.c_[x - d[:, None] * lines[:, :2] / np.linalg.norm(lines[:, :2], axis=1)[:, None], np.ones(6)], d

    def epipolar(u, v):                      # pixels from v to the epipolar line of u
        line = u @ F
        return abs(line @ v) / np.linalg.norm(line[:2])

    costs = []
    for t in np.linspace(0, np.pi, 2000, endpoint=False):
        foot, d = feet(t)
        costs.append(np.sum(d * d))
        assert epipolar(foot[0], foot[3]) <= 1e-6                           # one plane: the rays meet
        assert epipolar(foot[0], feet(t + 0.3)[0][3]) > 1e-3                # two planes of the pencil: they do not
    assert s <= min(costs) * (1 + 1e-9)
    assert collinear_centres(cams) is not None and pencil_ceiling(cams[[0, 1]], x[:2]) is None
    moved = cams.copy()
    moved[2] = K @ np.c_[np.eye(3), [0.5, 0.0, -0.6]]                     # off the line: no pencil
    assert collinear_centres(moved) is None and pencil_ceiling(moved, x) is None


@pytest.mark.parametrize("N,seed", [(5, 1), (7, 2)])
def test_forward_motion_skips_the_futile_corollary1_steps(N, seed):
    """Review 31a: a straight drive of 5-7 views ran Corollary 1 at degree 4 (views, then dense: ~1.5 s at N = 5)
    although its bound sat on the pencil's ceiling, before Theorem 1 certified."""
    cams, x, X = _forward(N, seed)
    r = tritools.triangulate(cams, x)
    assert r.optimal, (r.status, r.message)
    assert not [a for a in r.attempts if a.method == "corollary1" and a.delta == 4]
    ref = _lm_reference(cams, x, _starts(X, r, seed))
    assert r.gamma_lb <= ref * (1 + 1e-9) and r.gamma_ub == pytest.approx(ref, rel=1e-8)


@pytest.mark.parametrize("N,seed", [(9, 1), pytest.param(12, 2, marks=pytest.mark.slow)])
def test_forward_motion_of_9_to_12_views_is_certified(N, seed):
    """Review 31a: a straight drive of 9+ views was never certified by default (the exact-variety views step ran for
    5-8 views only); Theorem 1 at delta = 4 on view cliques certifies it in ~1-2 s."""
    cams, x, X = _forward(N, seed)
    r = tritools.triangulate(cams, x)
    assert r.optimal and r.method == "theorem1", (r.status, r.message)
    ref = _lm_reference(cams, x, _starts(X, r, seed))
    assert r.gamma_lb <= ref * (1 + 1e-9) and r.gamma_ub == pytest.approx(ref, rel=1e-8)


@pytest.mark.slow
@pytest.mark.parametrize("N", [9, 12])
def test_rectified_rigs_of_9_to_12_views(N):
    """Rectified rigs beyond 8 views reach the exact-variety step too (2 of 9 reviewed certified, the others within
    ~1e-6 of the exact optimum instead of 0.2-0.4 px below it); every bound valid against the exact optimum."""
    cams, x, exact = _rectified(N, 2, 0)
    r = tritools.triangulate(cams, x)
    assert r.optimal, (r.status, r.message)
    assert r.gamma_lb <= exact * (1 + 1e-9) and r.gamma_ub == pytest.approx(exact, rel=1e-8)
    for seed in (0, 1):
        cams, x, exact = _rectified(N, seed, seed)
        r = tritools.triangulate(cams, x)
        assert r.gamma_lb <= exact * (1 + 1e-9) and r.gamma_ub == pytest.approx(exact, rel=1e-8)


def test_forward_motion_beyond_the_cap_says_why():
    """Past :data:`~tritools.solve.plan.EXACT_VARIETY_COLLINEAR_MAX` views the point stays not_certified after the
    degree-2 step (no futile degree-4 Corollary 1 steps), with a valid bound and the reason in its message."""
    from tritools.solve.plan import EXACT_VARIETY_COLLINEAR_MAX

    N = EXACT_VARIETY_COLLINEAR_MAX + 2
    cams, x, X = _forward(N, 3)
    r = tritools.triangulate(cams, x)
    assert r.status == "not_certified" and "collinear camera centres" in r.message, r.message
    assert [(a.method, a.delta) for a in r.attempts if a.gamma_lb is not None] == [("corollary1", 2)]
    ref = _lm_reference(cams, x, _starts(X, r, 3))
    assert r.gamma_lb <= ref and r.gamma_ub == pytest.approx(ref, rel=1e-8)


def _drive(N: int, seed: int, jitter: float):
    """A drive of N frames 0.5 m apart along the optical axis, centres jittered by ``jitter`` metres (std)."""
    rng = np.random.default_rng(seed)
    C = np.array([[0.0, 0.0, 0.5 * i] for i in range(N)]) + jitter * rng.standard_normal((N, 3))
    cams = np.array([K @ np.c_[np.eye(3), -c] for c in C])
    X = np.array([rng.uniform(-3, 3), rng.uniform(-2, 2), C[:, 2].max() + rng.uniform(4, 30)])
    h = cams @ np.append(X, 1.0)
    return cams, h[:, :2] / h[:, 2:] + rng.standard_normal((N, 2)), X


def test_nearly_collinear_centres():
    """The views step's trigger: distinct centres within NEAR_COLLINEAR_RTOL of a line; a pure rotation (two frames
    at one centre) counts once; exact collinearity alone makes the pencil's ceiling."""
    cams, _, _ = _drive(8, 0, 1e-4)
    assert nearly_collinear_centres(cams) is not None and collinear_centres(cams) is None
    assert nearly_collinear_centres(_drive(8, 0, 0.05)[0]) is None
    Rz = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])
    turned = K @ np.c_[Rz, -Rz @ [0, 0, 0.5]]                                 # frame 1's centre, turned
    straight = _drive(3, 0, 0.0)[0]
    assert collinear_centres(_drive(4, 0, 0.0)[0]) is not None
    assert collinear_centres(np.concatenate([straight, [turned]])) is None             # coinciding: no pencil
    assert nearly_collinear_centres(np.concatenate([straight, [turned]])) is not None  # ... but the views step
    assert nearly_collinear_centres(_drive(4, 0, 0.0)[0][[0, 1, 1]]) is None          # two distinct centres


@pytest.mark.parametrize("N,seed", [(9, 1), pytest.param(12, 1, marks=pytest.mark.slow)])
def test_nearly_straight_drives_are_certified(N, seed):
    """Review 31a F1: drives with 0.1 mm jitter of 8-12 frames were not certified (0 / 8 per size: their centres
    are not collinear to 1e-6, so no exact-variety step ran, and Corollary 1 stalled 17-20 % below)."""
    cams, x, X = _drive(N, seed, 1e-4)
    r = tritools.triangulate(cams, x)
    assert r.optimal and r.method == "theorem1", (r.status, r.message)
    ref = _lm_reference(cams, x, _starts(X, r, seed))
    assert r.gamma_lb <= ref * (1 + 1e-9) and r.gamma_ub == pytest.approx(ref, rel=1e-8)


def test_discs_too_small_for_floats_fail_alone():
    """Review 31b F2: a disc whose D^-1 overflows is `failed` and the others of its batch get the answers they
    get alone (the CLI case below ended "error: q, A, b must be finite": the stacked solver refuses a non-finite
    stack as a whole)."""
    from tritools.uncertain.discs import uncertainty_discs

    cams, x, X = _drive(4, 5, 0.05)
    C = np.stack([cams, cams, cams])
    xs = np.stack([x, x, x])
    radii = np.array([[1.0] * 4, [1e-160] * 4, [1.0] * 4])
    alone = uncertainty_discs(C[:1], xs[:1], radii[:1], np.stack([X]))[0]
    res = uncertainty_discs(C, xs, radii, np.stack([X, X, X]))
    assert [r.status.value for r in res] == [alone.status.value, "failed", alone.status.value]
    assert alone.status.value == "bounded"
    assert np.allclose(res[0].lo, alone.lo, rtol=1e-9, atol=1e-12) and np.allclose(res[2].hi, alone.hi, rtol=1e-9)


def test_cli_tiny_keypoint_radius_is_a_status_not_an_error(tmp_path, capsys):
    """Review 31b F2: `--keypoint-radius 1e-160` exited 2 with an internal message naming no flag; like 1e-300 and
    1e200 it now writes the model with `failed` uncertainty rows."""
    from tritools.cli.app import main
    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    a, _ = synthetic_arrays(n_points=20, n_images=5, camera="PINHOLE", seed=4)
    write_model_arrays(a, tmp_path / "in", "bin")
    code = main(["colmap", str(tmp_path / "in"), str(tmp_path / "out"), "--max-delta", "2",
                 "--keypoint-radius", "1e-160"])
    assert code == 0, capsys.readouterr().err
    rows = [ln.split() for ln in (tmp_path / "out" / "points3D_uncertainty.txt").read_text().splitlines()
            if not ln.startswith("#")]
    assert len(rows) == 20 and {r[4] for r in rows} == {"failed"}


@pytest.mark.parametrize("radius", [1e-160, 1e160, 1e-300])
def test_circle_names_the_radius(radius):
    """Review 31b F6: `Ellipse.circle(c, 1e160)` blamed `D` (and numpy warned of an overflow)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for cls in (tritools.Ellipse, tritools.EllipseBorder):
            with pytest.raises(ValueError, match="^radius"):
                cls.circle([0.0, 0.0], radius)
