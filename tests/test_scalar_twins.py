"""The scalar (M = 1) twins of the single-call path (issue #22) against the stacked code they stand in for.

A twin runs the same mathematics on one problem with plain small arrays (no einsum, no stacked broadcasting), so
it cannot give the same bits as the vectorised code; these tests state how close it must be:

* :func:`tritools.model.stacked.refine_point` vs :func:`tritools.model.stacked.refine_points_stack` (forced
  vectorised): the same ``ok`` / ``converged`` flags, the same L2 cost at the end (relative 1e-10, or the
  round-off of the coordinates at zero noise: both are local minimisers, reached along differently rounded
  paths) and X within 1e-6 max(1, |X|) (the minimiser's conditioning: the cost is flat along the depth);
* :func:`tritools.model.stacked.damped_step_one` vs :func:`tritools.model.stacked.damped_step` (relative 1e-9 of
  the step, singular systems through the pseudo-inverse alike);
* :func:`sospoly.analysis.verify_quadratic_batch` on a stack of one (its scalar twin) vs the same program in a
  stack of two (the stacked code): the same reason and decision, bounds within 1e-9 relative (or 1e-12 of f(v^));
* the normalisation of a stack of one vs the same problem in a stack of many;
* one ``triangulate()`` vs the same track in ``triangulate_many``: the same status and certificate, bounds
  within 1e-9 relative.

On the adversarial scenes of the project (pixel scales 1e-3..1e6, georeferenced worlds, rescaled cameras,
duplicated views, zero noise, points behind cameras) and bad numbers (inf/NaN refused the same way).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import tritools
from tritools.model import normalize as NZ
from sospoly.analysis import SparseQuadratics, verify_quadratic_batch
from tritools.model.stacked import damped_step, damped_step_one, refine_point, refine_points_stack
from tritools.scene import random_scene

from .test_stacked_single import SCENES, _fields


def _cost(C, xhat, X):
    """sum_i ||Phi(X, P_i) - x^_i||^2 computed independently (homogeneous division, no shared code)."""
    h = np.einsum("nij,j->ni", C, np.append(X, 1.0))
    return float(np.sum((h[:, :2] / h[:, 2:] - xhat) ** 2))


def _starts(M):
    rng = np.random.default_rng(M)
    return [np.zeros((M, 3)), np.full((M, 3), 0.3), rng.normal(scale=2.0, size=(M, 3))]


def _behind(C, x):
    """The same data with the cameras of views 0 negated: the same projections, every depth of view 0 negative."""
    C = C.copy()
    C[0] *= -1.0
    return C, x


CASES = SCENES + [(name + "-behind", *_behind(C, x)) for name, C, x in SCENES[:6]]


@pytest.mark.parametrize("name, C, x", CASES, ids=[s[0] for s in CASES])
def test_scalar_lm_equals_the_stacked_lm(name, C, x):
    M = len(x)
    Cs = np.broadcast_to(C / np.abs(C).max(), (M,) + C.shape).copy()
    for X0 in _starts(M):
        X, ok, conv = refine_points_stack(Cs, x, X0, np.ones(M, bool), return_converged=True, scalar=False)
        for m in range(M):
            X1, ok1, conv1 = refine_point(Cs[m], x[m], X0[m])
            assert (ok1, conv1) == (ok[m], conv[m]), (m, X0[m])
            if ok[m]:
                c, c1 = _cost(Cs[m], x[m], X[m]), _cost(Cs[m], x[m], X1)
                floor = 2 * len(x[m]) * (64 * np.finfo(float).eps * max(1.0, np.abs(x[m]).max())) ** 2     # round-off
                assert c1 == pytest.approx(c, rel=1e-10, abs=floor)
                assert np.linalg.norm(X1 - X[m]) <= 1e-6 * max(1.0, np.linalg.norm(X[m]))
            # the stack of one dispatches to the twin by default, with the stack's shapes
            Xd, okd, convd = refine_points_stack(Cs[m:m + 1], x[m:m + 1], X0[m:m + 1], np.ones(1, bool),
                                                 return_converged=True)
            assert Xd.shape == (1, 3) and np.array_equal(Xd[0], X1) and (okd[0], convd[0]) == (ok1, conv1)


def test_scalar_lm_refuses_bad_numbers_like_the_stack():
    sc = random_scene(3, 1, noise_px=1.0, seed=1)
    C, x = np.asarray(sc.cameras) / 1e3, np.asarray(sc.points2d)[0]
    centre = np.linalg.svd(C[0])[2][-1]
    bad = [("nan camera", np.where(np.arange(12).reshape(3, 4) == 5, np.nan, 1.0) * C, x, np.zeros(3)),
           ("inf point", C, np.where([[True, False], [False, False], [False, False]], np.inf, x), np.zeros(3)),
           ("nan start", C, x, np.array([np.nan, 0.0, 0.0])),
           ("start at a centre", C, x, centre[:3] / centre[3]),
           ("not ok", C, x, np.zeros(3))]
    for name, Cb, xb, X0 in bad:
        ok_in = name != "not ok"
        with np.errstate(all="ignore"):
            X, ok, conv = refine_points_stack(Cb[None], xb[None], X0[None], np.array([ok_in]), return_converged=True,
                                              scalar=False)
            X1, ok1, conv1 = refine_point(Cb, xb, X0, ok_in)
        assert (ok1, conv1) == (ok[0], conv[0]), name
        assert ok1 == (name == "inf point"), name       # (an infinite target: no step is ever accepted, X stays)
        if ok1:
            assert np.array_equal(X1, X[0]) and np.array_equal(X1, X0), name


def test_scalar_damped_step_equals_the_batched_solve():
    rng = np.random.default_rng(7)
    for k in range(300):
        J = rng.normal(size=(2 * (2 + k % 9), 3)) * 10.0 ** rng.uniform(-6, 6)
        if k % 10 == 0:
            J[:, 2] = J[:, 0]                              # rank-deficient J^T J (the damping keeps it regular)
        JtJ, g, mu = J.T @ J, J.T @ rng.normal(size=len(J)), 10.0 ** rng.uniform(-12, 12)
        ref = damped_step(JtJ[None], g[None], np.array([mu]))[0]
        got = damped_step_one(JtJ, g, mu)
        # two backward-stable solves of one system differ by up to ~cond(A) u (the BLAS kernel decides which digits)
        A = JtJ + mu * (1 + np.trace(JtJ)) / 3 * np.eye(3)
        tol = max(1e-9, 64 * np.finfo(float).eps * np.linalg.cond(A))
        assert np.linalg.norm(got - ref) <= tol * np.linalg.norm(ref) + 1e-300, k
    zero = damped_step_one(np.zeros((3, 3)), np.ones(3), 0.0)       # exactly singular: the pseudo-inverse (0)
    ref = damped_step(np.zeros((1, 3, 3)), np.ones((1, 3)), np.zeros(1))[0]
    assert np.array_equal(zero, ref) and np.all(zero == 0)


def _solve3_loop(A, g):
    """The loop form of tritools.model.stacked.solve3 (whole rows eliminated): the reference of the unrolled code."""
    A = [list(A[0]) + [g[0]], list(A[1]) + [g[1]], list(A[2]) + [g[2]]]
    for k in range(3):
        p = k
        for i in range(k + 1, 3):
            if abs(A[i][k]) > abs(A[p][k]):
                p = i
        if A[p][k] == 0.0:
            return None
        A[k], A[p] = A[p], A[k]
        for i in range(k + 1, 3):
            f = A[i][k] / A[k][k]
            A[i] = [a - f * b for a, b in zip(A[i], A[k])]
    x2 = A[2][3] / A[2][2]
    x1 = (A[1][3] - A[1][2] * x2) / A[1][1]
    return [(A[0][3] - A[0][1] * x1 - A[0][2] * x2) / A[0][0], x1, x2]


def test_unrolled_solve3_equals_the_elimination_loop_bit_for_bit():
    """solve3 (unrolled, only the entries later steps read) gives the loop's numbers exactly: every pivot order
    (ties keep the first row), zero pivots at each column (None), random scales."""
    from tritools.model.stacked import solve3

    rng = np.random.default_rng(11)
    cases = [np.diag([1.0, 2.0, 3.0]), np.ones((3, 3)), np.zeros((3, 3)), np.array([[0, 1, 0], [1, 0, 0], [0, 0, 1.0]]),
             np.array([[1.0, 2, 3], [1.0, 5, 1], [-1.0, 2, 0]]), np.array([[0.0, 0, 1], [0.0, 1, 0], [0.0, 1, 1]]),
             np.array([[2.0, 1, 1], [4.0, 2, 2], [1.0, 0, 1]]), np.array([[1.0, 1, 1], [1.0, 1, 1], [1.0, 1, 2]])]
    for k in range(2000):
        A = rng.normal(size=(3, 3)) * 10.0 ** rng.uniform(-8, 8, size=(3, 1))
        if k % 7 == 0:
            A[rng.integers(3)] = A[rng.integers(3)] * rng.choice([1.0, -1.0])      # equal magnitudes: tied pivots
        cases.append(np.round(A, int(rng.integers(0, 3))) if k % 5 == 0 else A)
    for A in cases:
        g = rng.normal(size=3)
        got, ref = solve3(A.tolist(), g.tolist()), _solve3_loop(A.tolist(), g.tolist())
        assert (got is None) == (ref is None), A
        if ref is not None:
            assert np.array_equal(np.array(got), np.array(ref), equal_nan=True), A


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_stack_of_one_normalises_as_a_stack_of_many_up_to_round_off(name, C, x):
    """The stack of one runs the scalar LM: every field of the normalisation as in a stack of many, the masks
    exactly, the numbers within 1e-7 relative (the image scale comes from the refined point's residual); the
    refined point Xn itself at the same cost (relative 1e-7) and within 1e-4: on a georeferenced world normalised
    without re-centring (the per-point path re-centres first) both LMs stop by the step rule on a flat valley
    short of the minimum (another run lowers the cost by up to 6%, the stacked code's behaviour, not the twin's),
    at points 1e-6 apart, and whether each calls that converged may differ there."""
    M = len(x)
    many = NZ.normalization_stack(np.broadcast_to(C, (M,) + C.shape).copy(), x)
    for m in range(M):
        NZ._LAST_SINGLE[0] = None
        one = NZ.normalization_stack(C[None].copy(), x[m:m + 1].copy())
        for name_, a, b in zip(("scale", "shifts", "origin", "depth", "cameras_n", "Xn", "ok", "resolution",
                                "converged"), _fields(one), _fields(many, slice(m, m + 1))):
            if name_ == "converged" and "geo" in name:
                continue        # LM's step rule on the flat valley of a world normalised without re-centring
            if a.dtype == bool:
                assert np.array_equal(a, b), name_
            elif name_ == "Xn":
                assert np.allclose(a, b, rtol=1e-4, atol=1e-4), name_
                if one.ok[0]:
                    c1, c = (_cost(st.cameras_n[0], np.zeros((C.shape[0], 2)), a[0]) for st, a in ((one, a), (one, b)))
                    assert c1 == pytest.approx(c, rel=1e-7, abs=1e-24)
            else:
                assert np.allclose(a, b, rtol=1e-7, atol=1e-7 * max(1.0, float(np.max(np.abs(b))))), name_


def _variants(C, x):
    """(cameras, points, pixel scale, rtol of the bounds) of one scene at pixel scales 1e-3..1e6, in a georeferenced
    world, with a duplicated view and with view 0's camera negated (every depth in it negative: the optimum behind
    that camera).  Georeferenced: rtol 1e-5 and the certificate's path not compared, as on main before the twins
    (a single call re-centres the world frame and certifies by verification, the batch verifies in the caller's
    frame, falls back to its SDP, and gamma's round-off at |origin| 5e6 differs by ~2e-6, ~1e-8 px at zero noise)."""
    out = []
    for pix in (1.0, 1e-3 / 800, 1e6 / 800):
        S = np.diag([pix, pix, 1.0])
        out.append((S @ C, x * pix, pix, 1e-9))
    T = np.eye(4)
    T[:3, 3] = [4e6, -3e6, 1e5]
    out.append((C @ np.linalg.inv(T), x, 1.0, 1e-5))
    out.append((np.concatenate([C, C[:1]]), np.concatenate([x, x[:, :1]], axis=1), 1.0, 1e-9))
    out.append((*_behind(C, x), 1.0, 1e-9))
    return out


@pytest.mark.parametrize("N, noise, seed", [(2, 1.0, 0), (3, 0.0, 1), (5, 1.0, 2), (5, 30.0, 3), (10, 1.0, 4)])
def test_one_call_decides_as_the_batch(N, noise, seed):
    sc = random_scene(N, 12, noise_px=noise, seed=seed)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
    for Cp, xp, pix, rtol in _variants(C, x):
        geo = rtol > 1e-9
        many = tritools.triangulate_many([(Cp, xp[j]) for j in range(len(xp))], progress=False)
        for j, b in enumerate(many):
            a = tritools.triangulate(Cp, xp[j])
            assert (a.status, a.optimal, a.in_front) == (b.status, b.optimal, b.in_front)
            assert a.certified_by == b.certified_by or geo
            floor = (1e-7 if geo else 1e-12) * pix         # (geo: the projections' round-off at |origin| 5e6)
            assert a.gamma_ub == pytest.approx(b.gamma_ub, rel=rtol, abs=floor)
            assert a.gamma_lb == pytest.approx(b.gamma_lb, rel=rtol, abs=floor)
            assert a.gamma_lb <= a.gamma_ub
            assert np.allclose(a.X, b.X, rtol=1e-6, atol=1e-6 * max(1.0, float(np.max(np.abs(b.X)))))


def _programs():
    """(f0, f1, F2, g0, g1, G2 sparse, v, radius) of one program each: the epipolar programs of the scenes at their
    refined points (certified, the common case), the same at perturbed points (gaps, indefinite Hessians), and
    random dense quadratic programs."""
    from tritools.model.stacked import epipolar_quadratics, fundamental_stack, project_stack

    out = []
    for _name, C, x in SCENES[::3]:
        st = NZ.normalization_stack(np.broadcast_to(C, (len(x),) + C.shape).copy(), x)
        u, _, _ = project_stack(st.cameras_n, st.Xn)
        F, _ = fundamental_stack(st.cameras_n)
        N = C.shape[0]
        g0, g1, G2 = epipolar_quadratics(F, N)
        for m in range(len(x)):
            for shift in (0.0, 0.05):
                v = u[m].ravel() + shift
                one = SparseQuadratics(G2.k, G2.i, G2.j, G2.vals[m:m + 1])
                out.append((0.0, np.zeros(2 * N), np.eye(2 * N), g0[m], g1[m], one, v, 1.0 + np.linalg.norm(v)))
    rng = np.random.default_rng(11)
    for k in range(40):
        n, K = 2 + k % 6, k % 4
        A = rng.normal(size=(n, n))
        F2 = A @ A.T if k % 3 else A + A.T
        G = rng.normal(size=(1, K, n, n))
        G = (G + np.swapaxes(G, 2, 3)) / 2
        out.append((rng.normal(), rng.normal(size=n), F2, rng.normal(size=K), rng.normal(size=(K, n)),
                    SparseQuadratics.from_dense(G), rng.normal(size=n), None if k % 2 else 3.0))
    return out


def test_scalar_lagrangian_bound_equals_the_stacked_one():
    from sospoly import DEFAULT_TOLERANCES

    reasons = set()
    for f0, f1, F2, g0, g1, G2, v, radius in _programs():
        two = SparseQuadratics(G2.k, G2.i, G2.j, np.concatenate([G2.vals, G2.vals]))
        rad2 = None if radius is None else np.array([radius, radius])
        ref = verify_quadratic_batch(np.array([f0, f0]), np.array([f1, f1]), np.array([F2, F2]), np.array([g0, g0]),
                                     np.array([g1, g1]), two, np.array([v, v]), radius=rad2)
        got = verify_quadratic_batch(np.array([f0]), f1[None], F2[None], g0[None], g1[None], G2, v[None],
                                     radius=None if radius is None else np.array([radius]))
        assert len(got) == 1 and got.multipliers.shape == (1, len(g0))
        assert got.reason[0] == ref.reason[0] and got.certified[0] == ref.certified[0]
        reasons.add(int(ref.reason[0]))
        assert got.upper_bound[0] == pytest.approx(ref.upper_bound[0], rel=1e-12, abs=1e-300)
        if ref.reason[0] == 0:
            assert got.lower_bound[0] == pytest.approx(ref.lower_bound[0], rel=1e-9,
                                                       abs=1e-12 * max(1.0, abs(ref.upper_bound[0])))
            assert DEFAULT_TOLERANCES.certified(got.lower_bound[0], got.upper_bound[0]) == got.certified[0]
        else:
            assert np.isnan(got.lower_bound[0]) and np.isnan(ref.lower_bound[0])
        np.testing.assert_allclose(got.multipliers[0], ref.multipliers[0], rtol=1e-7,
                                   atol=1e-9 * max(1.0, float(np.abs(ref.multipliers).max(initial=0.0))))
    assert reasons >= {0, 1}                                    # bounded and rejected programs both compared


def test_null_vectors_are_the_signed_minors_bit_for_bit():
    """The four minors at once (one gather, small stacks) and minor by minor (large stacks) give the bits of the
    cofactor expansion written out, and a_k = (-1)^k det(P without column k) as LAPACK's determinant to 1e-12."""
    from tritools.model.stacked import null_vectors

    def det3(P, cols):
        (a00, a01, a02), (a10, a11, a12), (a20, a21, a22) = ([P[..., r, c] for c in cols] for r in range(3))
        return a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)

    rng = np.random.default_rng(5)
    for shape in ((3, 4), (6, 3, 4), (4, 5, 3, 4), (300, 2, 3, 4)):       # (the last: minor by minor)
        P = rng.normal(size=shape) * 10.0 ** rng.uniform(-80, 80, size=shape[:-2] + (1, 1))
        a = null_vectors(P)
        ref = np.stack([det3(P, (1, 2, 3)), -det3(P, (0, 2, 3)), det3(P, (0, 1, 3)), -det3(P, (0, 1, 2))], axis=-1)
        assert np.array_equal(a, ref)
        dets = np.stack([np.linalg.det(np.delete(P, k, axis=-1)) * (-1) ** k for k in range(4)], axis=-1)
        assert np.allclose(a, dets, rtol=1e-12, atol=0)


def test_sigma_max_2x3_equals_the_svd():
    """The closed form of the pixel scales' largest singular value against LAPACK's SVD: 4 ulp-level relative
    agreement over scales 1e-300..1e300, rank-one, nearly rank-one, unbalanced rows and zero matrices."""
    from tritools.model.stacked import sigma_max_2x3

    rng = np.random.default_rng(17)
    B = rng.normal(size=(6000, 2, 3)) * 10.0 ** rng.uniform(-300, 300, size=(6000, 1, 1))
    B[:500, 1] = 3.0 * B[:500, 0]                                   # rank one
    B[500:1000, 1] = B[500:1000, 0] * (1 + 1e-12)                   # nearly
    B[1000:1500, 0] *= 1e-9                                         # unbalanced rows
    B[1500:1600] = 0.0
    ref = np.linalg.svd(B, compute_uv=False)[:, 0]
    with np.errstate(all="raise"):                                  # nothing overflows or underflows on the way
        got = sigma_max_2x3(B)
    assert np.array_equal(got[ref == 0], ref[ref == 0])
    nz = ref > 0
    assert np.max(np.abs(got[nz] - ref[nz]) / ref[nz]) <= 4e-15
    with np.errstate(invalid="ignore"):
        bad = sigma_max_2x3(np.array([[[np.nan, 0, 0], [0, 1, 0]], [[np.inf, 0, 0], [0, 1, 0]]]))
    assert not np.isfinite(bad).any()                               # propagated, never a finite scale


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_dlt_and_pixel_scales_equal_their_references(name, C, x):
    """dlt_stack (rows formed without Hartley's similarity, which cancels) against the scalar Hartley-normalised
    :func:`tritools.model.geometry.dlt` (its own SVD), and pixel_scales against the SVD formula written out."""
    from tritools.model.geometry import PointAtInfinityError, dlt
    from tritools.model.stacked import dlt_stack, pixel_scales

    M = len(x)
    Cs = np.broadcast_to(C, (M,) + C.shape).copy()
    X, ok = dlt_stack(Cs, x)
    # georeferenced cameras (|centre| ~ 5e6): the eigenvector of A^T A squares their conditioning, ~1e-4 relative
    # error before and after this change (the LM refines from it; a single call re-centres the world first)
    check_dlt = not name.endswith("-geo")
    for m in range(M if check_dlt else 0):
        try:
            ref = dlt(C, x[m])
        except (PointAtInfinityError, ValueError):
            assert not ok[m] or not np.isfinite(X[m]).all() or np.linalg.norm(X[m]) > 1e8
            continue
        assert ok[m]
        np.testing.assert_allclose(X[m], ref, rtol=1e-7, atol=1e-9 * max(1.0, float(np.abs(ref).max())))
    B = C[None, :, :2, :3] - x[:, :, :, None] * C[None, :, 2:3, :3]
    ref_ps = np.linalg.svd(B, compute_uv=False)[..., 0] / np.linalg.norm(C[:, 2, :3], axis=-1)
    np.testing.assert_allclose(pixel_scales(Cs, x), ref_ps, rtol=1e-14)


@pytest.mark.parametrize("name, C, x", SCENES[:8], ids=[s[0] for s in SCENES[:8]])
def test_single_call_report_equals_points_report_stack(name, C, x):
    """A single call reports gamma(X) and the residuals computed by verify_checked instead of projecting again:
    they must be the bits of :func:`tritools.solve.report.points_report_stack` on the same cameras and X."""
    from tritools.solve.fastpath import stack_point_problems, verify_checked
    from tritools.solve.report import points_report_stack
    from sospoly import DEFAULT_TOLERANCES

    Cs, xs, ok = stack_point_problems(np.broadcast_to(C, (len(x),) + C.shape), x, "test")
    b = verify_checked(Cs, xs, ok, DEFAULT_TOLERANCES)
    g, res, _ = points_report_stack(Cs[b.ok], xs[b.ok], b.X[b.ok])
    assert np.array_equal(b.gamma_at_X[b.ok], g) and np.array_equal(b.residuals[b.ok], res)


def test_report_stage_record_equals_replace():
    """The report stage sets timings and attempts without validating the result again: the same result as
    ``dataclasses.replace`` (every field in the JSON form), and a new object."""
    import dataclasses

    from tritools.result import Attempt
    from tritools.solve.stages.outcome import with_record

    sc = random_scene(3, 1, noise_px=1.0, seed=2)
    res = tritools.triangulate(np.asarray(sc.cameras), np.asarray(sc.points2d)[0])
    att = res.attempts + (Attempt("x", 2, "verified", 0.0, 1.0, "verification", "dense", (), 0.1),)
    got = with_record(res, {"total": 1.0}, att)
    assert got is not res and got == dataclasses.replace(res, timings={"total": 1.0}, attempts=att)
    assert res.timings != {"total": 1.0}                        # the original is untouched
    mixed = with_record(res, {}, (dataclasses.asdict(att[0]),))  # a dict attempt: the validating path
    assert mixed.attempts == (att[0],)


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_gauss_newton_polish_one_equals_the_stack(name, C, x):
    """The polish of a stack of one (scalar twin) against the stacked step, on the normalised data of the verification
    from a perturbed refined point: the cost after it within 1e-8 relative (one step of a system of condition up to
    ~1e13 from 1e-6 off the minimiser, georeferenced; or the coordinates' round-off), never
    above the cost before, and X within 1e-6 max(1, |X|)."""
    from tritools.model.stacked import gauss_newton_polish

    M = len(x)
    st = NZ.normalization_stack(np.broadcast_to(C, (M,) + C.shape).copy(), x)     # the data the polish sees
    Cs, x = st.cameras_n, np.zeros_like(x)
    X0 = st.Xn + 1e-6 * np.random.default_rng(M).normal(size=(M, 3))
    # (in raw georeferenced cameras the normalised point can sit ~1e9 out, a system conditioned beyond comparison
    # of two roundings: compared where |X| is O(1), as in the re-centred frame of a single call)
    ok = st.ok & (np.abs(X0).max(axis=1) < 1e3)
    stacked = gauss_newton_polish(Cs, x, X0, ok)
    for m in range(M):
        one = gauss_newton_polish(Cs[m:m + 1], x[m:m + 1], X0[m:m + 1], ok[m:m + 1])[0]
        if not ok[m]:
            continue
        c0, c1, c2 = _cost(Cs[m], x[m], X0[m]), _cost(Cs[m], x[m], one), _cost(Cs[m], x[m], stacked[m])
        floor = 1e-20 * max(1.0, float(np.abs(x[m]).max())) ** 2
        assert c1 <= c0 * (1 + 1e-12) + floor and c2 <= c0 * (1 + 1e-12) + floor
        assert c1 == pytest.approx(c2, rel=1e-8, abs=floor)
        np.testing.assert_allclose(one, stacked[m], rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(stacked[m]).max())))


def _decide_values():
    """c values around the rule's edges: zero, signed zero, round-off, the gap tolerance, large, negative, NaN, inf."""
    base = [0.0, -0.0, 1e-300, 1e-12, 1e-7, 1e-6, 9.99e-7, 1.000001e-6, 2e-6, 0.5, 1.0, 1.0 + 1e-6, 1.0 - 1e-6, 3.0,
            1e6, 1e300, -1e-9, -1.0, np.nan, np.inf, -np.inf]
    rng = np.random.default_rng(3)
    return base + list(rng.normal(size=12) * 10.0 ** rng.uniform(-10, 3, size=12))


def test_decide_one_equals_decide_bit_for_bit():
    """The scalar decision rule against the vectorised one (the reference of every path): the same status, the same
    flag and the same reported lower bound (bits, NaN alike), over every pair of edge values, two tolerance settings,
    resolutions 0..inf and NaN and several view counts; likewise the decision on the reported numbers."""
    from sospoly import DEFAULT_TOLERANCES, Tolerances
    from tritools.solve.decide import decide, decide_one, decide_reported, decide_reported_one

    vals = _decide_values()
    lo = np.repeat(vals, len(vals))
    up = np.tile(vals, len(vals))
    for tol in (DEFAULT_TOLERANCES, Tolerances(gap_abs=1e-9, gap_rel=1e-4)):
        for N in (2, 5, 13):
            for res in (0.0, 1e-10, 1e-8, 0.3, np.inf, np.nan):
                status, optimal, lower = decide(lo, up, tol, N, np.full(len(lo), res))
                for k in range(len(lo)):
                    s1, o1, l1 = decide_one(lo[k], up[k], tol, N, res)
                    assert (s1.value, o1) == (status[k], optimal[k]), (lo[k], up[k], tol, N, res)
                    assert np.array_equal(l1, lower[k], equal_nan=True), (lo[k], up[k])
                for scale in (1.0, 3e-4, 2e5):
                    g_lo, g_up = np.abs(lo) / 7, np.abs(up) / 7
                    with np.errstate(over="ignore"):            # (c of gamma 1e300: inf, as in the scalar twin)
                        rep = decide_reported(g_lo, g_up, tol, N, scale, res)
                    for k in range(0, len(lo), 3):
                        assert decide_reported_one(g_lo[k], g_up[k], tol, N, scale, res) == rep[k], (g_lo[k], g_up[k])


def _batch_row(b, m):
    return {f: np.asarray(getattr(b, f))[m] for f in ("certified", "ok", "X", "gamma_lb", "gamma_at_X", "image_points",
                                                      "c_lower", "c_upper", "scale", "trivial", "residuals")}


@pytest.mark.parametrize("name, C, x", CASES, ids=[s[0] for s in CASES])
def test_verify_one_equals_the_stacked_verification(name, C, x):
    """The scalar verification of one problem (:func:`tritools.solve.fastpath.verify_one`) against the stacked code
    on the same problem inside a stack of many (the batch path): the same flags (certified, trivial, ok), bounds and
    gamma(X) within 1e-9 relative (or 1e-12 of the pixel scale's round-off), the world point within 1e-6, the
    residuals and image points within 1e-9 relative.  The twin must take the common path on these scenes (it is
    None only where the stacked code would flag the problem), and a stack of one dispatches to it by default."""
    from sospoly import DEFAULT_TOLERANCES
    from tritools.model.geometry import validate_cameras
    from tritools.solve.fastpath import stack_point_problems, verify_checked, verify_one

    geo = "-geo" in name
    Cv = validate_cameras(C)
    M = len(x)
    Cs, xs, ok = stack_point_problems(np.broadcast_to(Cv, (M,) + Cv.shape), x, "test")
    ref = verify_checked(Cs, xs, ok, DEFAULT_TOLERANCES)
    used = 0
    for m in range(M):
        NZ._LAST_SINGLE[0] = None
        one = verify_one(Cv, x[m], DEFAULT_TOLERANCES)
        if one is None:
            continue
        used += 1
        a, b = _batch_row(one, 0), _batch_row(ref, m)
        for f in ("certified", "ok", "trivial"):
            assert a[f] == b[f] or geo, (f, m)
        if geo:               # raw georeferenced cameras (a single call re-centres first): valid bounds only
            assert a["gamma_lb"] <= a["gamma_at_X"] or np.isnan(a["gamma_lb"])
            continue
        scale_px = 1e-12 * max(1.0, float(np.abs(x[m]).max()))
        for f in ("gamma_lb", "gamma_at_X"):
            assert a[f] == pytest.approx(b[f], rel=1e-9, abs=scale_px, nan_ok=True), (f, m)
        assert a["gamma_lb"] <= a["gamma_at_X"] or np.isnan(a["gamma_lb"])
        for f in ("residuals", "image_points"):
            np.testing.assert_allclose(a[f], b[f], rtol=1e-9, atol=scale_px)
        np.testing.assert_allclose(a["X"], b["X"], rtol=1e-6, atol=1e-6 * max(1.0, float(np.abs(b["X"]).max())))
        NZ._LAST_SINGLE[0] = None
        d = verify_checked(Cs[m:m + 1], xs[m:m + 1], ok[m:m + 1], DEFAULT_TOLERANCES)
        NZ._LAST_SINGLE[0] = None
        again = verify_one(Cv, x[m], DEFAULT_TOLERANCES)
        assert all(np.array_equal(_batch_row(d, 0)[f], _batch_row(again, 0)[f], equal_nan=True) for f in a)
    from tritools.solve.fastpath import BAND_MIN_VIEWS

    assert used >= (M + 1) // 2 or geo if C.shape[0] < BAND_MIN_VIEWS else used == 0, used


def test_verify_one_leaves_the_special_cases_to_the_stacked_code():
    """Off the common path the twin gives None and the stack of one decides with the stacked code: all views at one
    centre (a rotating camera), the DLT point at infinity (parallel rays), non-finite numbers, an expired deadline."""
    from sospoly import DEFAULT_TOLERANCES
    from sospoly.budget import Deadline
    from tritools.solve.fastpath import verify_checked, verify_one

    sc = random_scene(3, 1, noise_px=1.0, seed=4)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)[0]
    R = np.array([[np.cos(0.2), -np.sin(0.2), 0], [np.sin(0.2), np.cos(0.2), 0], [0, 0, 1]])
    rot = np.array([C[0], R @ C[0], R.T @ C[0]])                      # one centre, three views
    assert verify_one(rot, x, DEFAULT_TOLERANCES) is None
    NZ._LAST_SINGLE[0] = None
    b = verify_checked(rot[None], x[None], np.ones(1, bool), DEFAULT_TOLERANCES)
    NZ._LAST_SINGLE[0] = None
    ref = verify_checked(rot[None], x[None], np.ones(1, bool), DEFAULT_TOLERANCES, scalar=False)
    assert all(np.array_equal(_batch_row(b, 0)[f], _batch_row(ref, 0)[f], equal_nan=True) for f in _batch_row(b, 0))
    with np.errstate(all="ignore"):
        assert verify_one(C, np.where(np.arange(6).reshape(3, 2) == 1, np.nan, x), DEFAULT_TOLERANCES) is None
    assert verify_one(C, x, DEFAULT_TOLERANCES, deadline=Deadline.after(0.0)) is None


def test_tolerances_scalar_rule_equals_the_vectorised_rule():
    """sospoly.Tolerances.gap_tolerance_one / certified_relatively_one: the one certificate rule, scalar twins."""
    from sospoly import DEFAULT_TOLERANCES, Tolerances

    rng = np.random.default_rng(5)
    for tol in (DEFAULT_TOLERANCES, Tolerances(gap_abs=1e-3, gap_rel=1e-4)):
        for up in [0.0, -0.0, 1e-300, 0.5, 1.0, -3.0, 1e300, *rng.normal(size=20) * 10.0 ** rng.integers(-9, 9, 20)]:
            for scale in (1.0, 0.25, 1024.0):
                assert tol.gap_tolerance_one(up, scale) == float(tol.gap_tolerance(up, scale))
            lo = up - tol.gap_rel * abs(up) * rng.choice([0.5, 1.0, 2.0])
            assert tol.certified_relatively_one(lo, up) == bool(tol.certified_relatively(lo, up))
            # within a share of the gap: the rule of Tolerances(gap_rel=share gap_rel)
            half = Tolerances(gap_abs=tol.gap_abs, gap_rel=0.5 * tol.gap_rel)
            assert tol.certified_relatively_one(lo, up, 0.5) == bool(half.certified_relatively(lo, up))


def test_tolerances_certified_one_and_contradicts_one_equal_the_vectorised_rule():
    """sospoly.Tolerances.certified_one / contradicts_one (a single robust call's decision): equal to certified /
    contradicts on every pair, at the gap's edge, with inf, NaN and None."""
    from sospoly import DEFAULT_TOLERANCES, Tolerances

    rng = np.random.default_rng(6)
    inf, nan = math.inf, math.nan
    for tol in (DEFAULT_TOLERANCES, Tolerances(gap_abs=1e-3, gap_rel=1e-4)):
        ups = [0.0, 1e-300, 0.5, 1.0, -3.0, 1e300, inf, -inf, nan,
               *rng.normal(size=20) * 10.0 ** rng.integers(-9, 9, 20)]
        for up in ups:
            for scale in (1.0, 0.25, 1024.0, 4e4):
                gap = tol.gap_tolerance_one(up, scale) if math.isfinite(up) else 1.0
                for lo in (up, up - gap, up - 2 * gap, up + gap, up + 2 * gap, np.nextafter(up - gap, -inf),
                           -inf, inf, nan, 0.0):
                    assert tol.certified_one(lo, up, scale) == bool(tol.certified(lo, up, scale)), (lo, up, scale)
                    assert tol.contradicts_one(lo, up, scale) == bool(tol.contradicts(lo, up, scale)), (lo, up, scale)
        assert tol.certified_one(None, 1.0) is False and tol.contradicts_one(1.0, None) is False


def test_gamma_lower_one_equals_gamma_lower_bit_for_bit():
    """tritools.solve.decide.gamma_lower_one (a single robust result's report) gives gamma_lower's numbers exactly:
    bounds and resolutions over 600 orders of magnitude, gamma_UB infinite or NaN, non-finite or zero scales."""
    from tritools.solve.decide import gamma_lower, gamma_lower_one

    rng = np.random.default_rng(12)
    inf, nan = math.inf, math.nan
    vals = [0.0, 1e-300, 1e-12, 0.5, 3.0, 1e10, 1e300, inf, nan]
    for _ in range(3000):
        g = float(rng.choice(vals)) if rng.random() < 0.2 else float(rng.random() * 10.0 ** rng.integers(-300, 300))
        up = float(rng.choice(vals)) if rng.random() < 0.3 else g * float(1 + rng.random())
        sc = float(rng.choice([1.0, 1.0, 0.0, 2.5, 1e-200, inf]))
        res = float(rng.choice(vals)) if rng.random() < 0.3 else float(rng.random() * 10.0 ** rng.integers(-20, 20))
        with np.errstate(all="ignore"):
            ref = float(gamma_lower(g, up, sc, res))
        got = gamma_lower_one(g, up, sc, res)
        same = got == ref and math.copysign(1, got) == math.copysign(1, ref)
        assert same or (math.isnan(got) and math.isnan(ref)), (g, up, sc, res, got, ref)
