"""The banded verification (sospoly.analysis.banded, sospoly.analysis.verify_sparse) and the band of view pairs
of the point fast path (tritools.solve.fastpath), against independent references: dense numpy linear algebra,
the dense Lagrangian bound on the same program, a closed-form minimum, and multi-start local minimisation."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import tritools
import tritools.solve.fastpath as fp
from sospoly import DEFAULT_TOLERANCES
from sospoly.analysis.banded import band_cholesky, band_from_dense, band_matvec, band_solve, cholesky_backward_error
from sospoly.analysis.verify import SparseQuadratics, verify_quadratic_batch
from sospoly.analysis.verify_sparse import verify_quadratic_banded_batch
from tritools.scene import random_scene


def _band_matrix(rng, M, n, b, shift):
    B = rng.normal(size=(M, n, n))
    A = B + np.swapaxes(B, 1, 2)
    A = A * (np.abs(np.subtract.outer(np.arange(n), np.arange(n))) <= b)
    return A + shift * np.eye(n)


@pytest.mark.parametrize("b,n", [(0, 4), (1, 1), (2, 7), (5, 12), (9, 6)])
def test_band_routines_match_dense_numpy(b, n):
    rng = np.random.default_rng(b * 10 + n)
    A = _band_matrix(rng, 3, n, b, 4.0 * (b + 2))
    ab = band_from_dense(A, b)
    R, ok = band_cholesky(ab)
    assert ok.all()
    rhs = rng.normal(size=(3, n))
    x = band_solve(R, rhs)
    np.testing.assert_allclose(x, np.linalg.solve(A, rhs[..., None])[..., 0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(band_matvec(ab, rhs), np.einsum("mij,mj->mi", A, rhs), rtol=1e-12, atol=1e-12)
    # the backward-error bound is a bound of -lambda_min for a successful factorisation (here lambda_min > 0)
    assert np.all(cholesky_backward_error(R) < 1e-10)


def test_band_cholesky_flags_indefinite_and_singular_matrices():
    A = np.array([np.diag([1.0, -1e-9, 2.0]), np.diag([1.0, 0.0, 2.0]), np.diag([1.0, 2.0, 3.0])])
    A[0, 0, 1] = A[0, 1, 0] = 0.5
    _, ok = band_cholesky(band_from_dense(A, 1))
    assert ok.tolist() == [False, False, True]


def _chain_program(rng, M, N, noise):
    """min ||v||^2 s.t. the bilinear constraints v_i^T B_k v_j + a_k.(v_i, v_j) + c_k = 0 over a band of
    pairs, in the layout of the epipolar constraints (two variables per 'view')."""
    n = 2 * N
    I, J = np.array([(i, i + d) for i in range(N) for d in (1, 2) if i + d < N]).T
    K = len(I)
    F = rng.normal(size=(M, K, 3, 3)) * np.array([1, 1, 1])
    F[..., 2, 2] = noise * rng.normal(size=(M, K))
    from tritools.model.stacked import epipolar_quadratics

    g0, g1, G2 = epipolar_quadratics(F, N, (I, J))
    return n, K, g0, g1, G2


def test_banded_bound_equals_dense_bound_on_the_same_program():
    """Same program, same candidate: the banded and the dense Lagrangian bounds agree (both are the minimum
    of the Lagrangian at the least-squares KKT multipliers, which are unique here)."""
    rng = np.random.default_rng(3)
    M, N = 6, 9
    n, K, g0, g1, G2 = _chain_program(rng, M, N, 1e-3)
    v = 1e-3 * rng.normal(size=(M, n))                # near 0, where the constraints nearly hold
    args = (np.zeros(M), np.zeros((M, n)), np.broadcast_to(np.eye(n), (M, n, n)), g0, g1, G2, v)
    dense = verify_quadratic_batch(*args, radius=np.ones(M))
    band = verify_quadratic_banded_batch(*args, radius=np.ones(M))
    both = (dense.reason == 0) & (band.reason == 0)
    assert both.sum() >= 3
    np.testing.assert_allclose(band.lower_bound[both], dense.lower_bound[both], rtol=1e-8, atol=1e-10)


def test_banded_bound_on_a_closed_form_minimum():
    """min (v1 - 1)^2 + (v2 - 2)^2 s.t. v1 v2 = 0: the minimum 1 at (0, 2); its multiplier certifies it."""
    f0, f1, F2 = np.array([5.0]), np.array([[-2.0, -4.0]]), np.eye(2)[None]
    G2 = SparseQuadratics(np.array([0, 0]), np.array([0, 1]), np.array([1, 0]), np.array([[0.5, 0.5]]))
    ver = verify_quadratic_banded_batch(f0, f1, F2, np.zeros((1, 1)), np.zeros((1, 1, 2)), G2,
                                        np.array([[0.0, 2.0]]), radius=np.array([3.0]))
    assert ver.certified[0]
    assert ver.lower_bound[0] == pytest.approx(1.0, abs=1e-12) and ver.lower_bound[0] <= 1.0


def _multistart_gamma(C, x, starts=12, seed=0) -> float:
    """Independent attained value: the best reprojection RMS over LM runs from perturbed DLT starts."""
    from tritools.model.geometry import dlt

    rng = np.random.default_rng(seed)
    X0 = dlt(C, x)
    best = np.inf

    def res(X):
        h = C @ np.append(X, 1.0)
        return (h[:, :2] / h[:, 2:] - x).ravel()

    for k in range(starts):
        start = X0 + (0 if k == 0 else 0.3 * rng.normal(size=3))
        r = least_squares(res, start, method="lm")
        best = min(best, float(np.sqrt(np.mean(r.fun ** 2))))
    return best


@pytest.mark.parametrize("N,noise", [(14, 1.0), (30, 3.0), (60, 1.0)])
def test_band_certificates_are_sound_and_used(N, noise, monkeypatch):
    """Tracks of 14-60 views: the band of pairs certifies on its own (the all-pairs fallback is disabled), and
    every certified gamma_LB is below an independent multi-start attained value and meets gamma_UB."""
    sc = random_scene(N, 6, noise_px=noise, seed=N)

    def no_fallback(C, *args):
        raise AssertionError("the all-pairs fallback was used")

    monkeypatch.setattr(fp, "_all_pairs_bounds", no_fallback)
    b = fp.verify_points(np.broadcast_to(sc.cameras, (6,) + sc.cameras.shape), sc.points2d)
    assert b.certified.all()
    for m in range(6):
        ref = _multistart_gamma(np.asarray(sc.cameras), sc.points2d[m])
        assert b.gamma_lb[m] <= ref * (1 + 1e-9) + 1e-12
        assert b.gamma_ub[m] <= ref * (1 + 1e-6) + 1e-9
        assert b.gamma_ub[m] - b.gamma_lb[m] <= 1e-6 * max(1.0, b.gamma_ub[m])


def test_band_failure_falls_back_to_all_pairs_soundly(monkeypatch):
    """A band too narrow for its tracks (width 2, 40 views, 5 px noise: the multipliers carry the KKT residual
    along the chain and the Lagrangian Hessian loses definiteness): those tracks fall back to all pairs; the
    decisions equal the all-pairs-only decisions and every certified gamma_LB stays below an independent
    multi-start attained value."""
    M = 8
    sc = random_scene(40, M, noise_px=5.0, seed=5)
    C, x = np.asarray(sc.cameras), sc.points2d
    used = []
    original = fp._all_pairs_bounds

    def counting(Cs, *args):
        used.append(len(Cs))
        return original(Cs, *args)

    monkeypatch.setattr(fp, "_all_pairs_bounds", counting)
    monkeypatch.setattr(fp, "BAND_WIDTHS", (2,))
    with_band = fp.verify_points(np.broadcast_to(C, (M,) + C.shape), x)
    assert 1 <= sum(used) < M, "the fallback must be exercised on some tracks, not all"
    monkeypatch.setattr(fp, "BAND_MIN_VIEWS", 10 ** 6)
    dense = fp.verify_points(np.broadcast_to(C, (M,) + C.shape), x)
    assert with_band.certified.tolist() == dense.certified.tolist()
    for m in np.nonzero(with_band.certified)[0]:
        assert with_band.gamma_lb[m] <= _multistart_gamma(C, x[m]) * (1 + 1e-9) + 1e-12


def test_single_call_equals_batch_of_one_on_a_long_track():
    sc = random_scene(20, 2, noise_px=1.0, seed=2)
    one = tritools.triangulate(sc.cameras, sc.points2d[0])
    batch = fp.verify_points(np.asarray(sc.cameras)[None], sc.points2d[:1], tolerances=DEFAULT_TOLERANCES)
    assert one.certified_by == "verification" and batch.certified[0]
    np.testing.assert_allclose(one.X, batch.X[0], rtol=1e-12)
    assert one.gamma_lb == pytest.approx(float(batch.gamma_lb[0]), rel=1e-12)


@pytest.mark.parametrize("img_scale,img_shift,world_shift,cam_scale", [(1e-3, 0.0, 0.0, 1.0), (1e3, 1e6, 0.0, 1e-6),
                                                                        (1.0, 0.0, 1e4, 1e6)])
def test_band_certificate_is_invariant_to_units(img_scale, img_shift, world_shift, cam_scale):
    """Pixel coordinates scaled and shifted, georeferenced worlds, rescaled cameras: the problem is the same up to
    the image scale (gamma scales with it), and the band certificate reports the same bounds."""
    N, M = 18, 4
    sc = random_scene(N, M, noise_px=1.0, seed=11)
    C, x = np.asarray(sc.cameras), sc.points2d
    T = np.array([[img_scale, 0, img_shift], [0, img_scale, img_shift], [0, 0, 1.0]])
    H = np.eye(4)
    H[:3, 3] = -world_shift                              # X_new = X + world_shift: P_new = P H
    C2 = cam_scale * np.einsum("ij,njk,kl->nil", T, C, H)
    x2 = img_scale * x + img_shift
    ref = fp.verify_points(np.broadcast_to(C, (M,) + C.shape), x)
    new = fp.verify_points(np.broadcast_to(C2, (M,) + C2.shape), x2)
    assert ref.certified.all() and new.certified.all()
    np.testing.assert_allclose(new.gamma_ub / img_scale, ref.gamma_ub, rtol=1e-6)
    np.testing.assert_allclose(new.gamma_lb / img_scale, ref.gamma_lb, rtol=1e-5)


def test_small_stacks_through_lapack_equal_the_column_loop(monkeypatch):
    """Stacks of at most LAPACK_MAX_STACK problems are factored by dpbtrf one by one: the same factors and solutions
    to round-off as the column loop, the same failures, and the module's backward error bound holds for them
    (checked against the residual R R^T - A in extended precision)."""
    from sospoly.analysis import banded as B

    rng = np.random.default_rng(7)
    for _ in range(60):
        n, M = int(rng.integers(2, 80)), int(rng.integers(1, 4))
        b = int(rng.integers(1, min(n, 6)))
        A = np.zeros((M, n, n))
        for m in range(M):
            X = rng.normal(size=(n, n)) * 10.0 ** rng.uniform(-3, 3, size=(n, 1))
            S = np.triu(np.tril((X + X.T) / 2, b), -b)
            A[m] = S + np.eye(n) * (np.abs(S).sum(axis=1) + 1e-8)
        ab = B.band_from_dense(A, b)
        R1, ok1 = B.band_cholesky(ab)
        rhs = rng.normal(size=(M, n))
        x1 = B.band_solve(R1, rhs)
        with monkeypatch.context() as mp:
            mp.setattr(B, "LAPACK_MAX_STACK", 0)
            R2, ok2 = B.band_cholesky(ab)
            x2 = B.band_solve(R2, rhs)
        assert ok1.all() and ok2.all()
        assert np.abs(R1 - R2).max() <= 1e-13 * np.abs(R2).max()
        assert np.abs(x1 - x2).max() <= 1e-10 * np.abs(x2).max()
        eps = B.cholesky_backward_error(R1)
        for m in range(M):
            L = np.zeros((n, n))
            for d in range(b + 1):
                L[np.arange(d, n), np.arange(n - d)] = R1[m, d, :n - d]
            E = L.astype(np.longdouble) @ L.T.astype(np.longdouble) - A[m].astype(np.longdouble)
            assert np.linalg.norm(E.astype(float), 2) <= eps[m]
        bad = ab.copy()
        bad[0, 0, n // 2] = -1.0                  # indefinite
        bad[-1, 0, 0] = np.nan                    # not finite
        ok = B.band_cholesky(bad)[1]
        assert not ok[0] and not ok[-1]


def test_review17_inputs_of_any_dtype_padding_and_underflow(monkeypatch):
    """Review 17: an int64 / float32 stack factored through LAPACK kept its dtype (a truncated factor with the
    float64 bound); padding rows with b > n were not cleared; near 1e-315 the bound underflowed to 0 below the
    residual (now a term for underflow)."""
    from sospoly.analysis import banded as B

    A = np.array([[[2, 1], [1, 3]]])
    for dtype in (np.int64, np.float32):
        ab = B.band_from_dense(A, 1).astype(dtype)
        R, ok = B.band_cholesky(ab)
        R64, _ = B.band_cholesky(ab.astype(float))
        assert ok[0] and R.dtype == np.float64 and np.array_equal(R, R64)
    ab = np.zeros((1, 5, 2))
    ab[0, 0] = [4.0, 9.0]
    ab[0, 1, 0] = 1.0
    ab[0, 1, 1] = ab[0, 2:, :] = np.nan              # padding of a b = 4 band on n = 2: not part of the matrix
    assert B.band_cholesky(ab)[1].all()
    with monkeypatch.context() as mp:
        mp.setattr(B, "LAPACK_MAX_STACK", 0)
        assert B.band_cholesky(ab)[1].all()
    tiny = np.array([[[3e-315, 1e-315, 0], [1e-315, 3e-315, 1e-315], [0, 1e-315, 3e-315]]])
    R, ok = B.band_cholesky(B.band_from_dense(tiny, 1))
    assert ok[0]
    L = np.diag(R[0, 0]) + np.diag(R[0, 1, :2], -1)
    E = (L @ L.T - tiny[0]).astype(float)
    assert np.linalg.norm(E, 2) <= B.cholesky_backward_error(R)[0] and B.cholesky_backward_error(R)[0] > 0
