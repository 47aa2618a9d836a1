"""The camera check (validate_cameras and its vectorised twin camera_problems): conditioning
before the rank test, scale invariance, overflow, distinctness, non-numeric input; depths and
depths_stack; fundamental matrices of coincident centres and of extreme scales."""
import time

import numpy as np
import pytest

from tritools.model.geometry import (CAMERA_RANK_RTOL, CameraIssue, camera_center, camera_problems,
                                     camera_rank_ratio, cameras_all_equal, depths, depths_stack,
                                     fundamental_matrices, fundamental_matrix, image_points, project,
                                     validate_cameras)

RNG = np.random.default_rng(31)


def rotation():
    Q, R = np.linalg.qr(RNG.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    return Q if np.linalg.det(Q) > 0 else -Q


def pixel_camera(f=1e3, pp=1e6, t=None):
    K = np.array([[f, 0.0, pp], [0.0, f, pp], [0.0, 0.0, 1.0]])
    t = RNG.normal(size=3) + [0, 0, 5.0] if t is None else np.asarray(t, float)
    return K @ np.c_[rotation(), t]


def conditioned_reference(P):
    """sigma_3 / sigma_1 after the explicit left factor T (translation) and row scaling, by SVD."""
    P = P / np.abs(P).max()
    r3 = P[2]
    a, b = P[0] @ r3 / (r3 @ r3), P[1] @ r3 / (r3 @ r3)
    Q = np.array([[1, 0, -a], [0, 1, -b], [0, 0, 1.0]]) @ P
    Q = Q / np.linalg.norm(Q, axis=1, keepdims=True)
    s = np.linalg.svd(Q, compute_uv=False)
    return s[2] / s[0]


def error_of(fn):
    try:
        fn()
    except ValueError as exc:
        return str(exc)
    return None


# ---------------------------------------------------------------- the rank rule
def test_pixel_camera_is_accepted_although_raw_svd_says_rank_2():
    P = pixel_camera()
    raw = np.linalg.svd(P, compute_uv=False)
    assert raw[2] / raw[0] < CAMERA_RANK_RTOL                  # the issue: refused before conditioning
    assert camera_rank_ratio(P) > 0.1
    C = validate_cameras([P, pixel_camera()])
    assert C.shape == (2, 3, 4)
    assert camera_problems(C[None]).valid.tolist() == [True]
    assert np.isfinite(camera_center(P)).all()


def test_rank_ratio_matches_the_svd_of_the_explicitly_conditioned_matrix():
    cams = [RNG.normal(size=(3, 4)) for _ in range(50)] + [pixel_camera(f=RNG.uniform(10, 1e4),
                                                                         pp=RNG.uniform(0, 1e7)) for _ in range(50)]
    ratio = camera_rank_ratio(np.array(cams))
    ref = np.array([max(conditioned_reference(P), conditioned_reference(P[:, :3])) for P in cams])
    assert np.allclose(ratio, ref, rtol=1e-7, atol=0)
    # the rule is invariant under image translations and scalings (left factors) and P -> k P
    for P in cams[:20]:
        T = np.array([[RNG.uniform(0.1, 10), 0, RNG.normal() * 1e3], [0, RNG.uniform(0.1, 10), RNG.normal()],
                      [0, 0, 1.0]])
        assert camera_rank_ratio(T @ P) == pytest.approx(camera_rank_ratio(P), rel=1e-6)
        assert camera_rank_ratio(-3e200 * P) == pytest.approx(camera_rank_ratio(P), rel=1e-12)


@pytest.mark.parametrize("offset", [1e5, 1e6, 4e7, 1e8])
@pytest.mark.parametrize("pp", [0.0, 1e5, 1e6])
def test_georeferenced_cameras_have_rank_3(offset, pp):
    """K [R | -R (C + T)] has rank 3 exactly; with |T| ~ 1e5-1e8 (a georeferenced world) every row is dominated by
    its fourth entry, which the image-side conditioning alone does not remove (review 8 F3: refused at |T| >= 1e7
    with a 1e6 px principal point).  The SVD of the explicitly conditioned left block is the reference."""
    T = offset * np.array([1.0, -0.5, 0.025])
    cams = []
    for _ in range(4):
        R = rotation()
        C = RNG.normal(size=3) * 10
        K = np.array([[800.0, 0, pp], [0, 800.0, pp], [0, 0, 1]])
        cams.append(K @ np.c_[R, -R @ (C + T)])
    validate_cameras(cams)
    ratio = camera_rank_ratio(np.array(cams))
    ref = np.array([conditioned_reference(P[:, :3]) for P in cams])
    assert np.all(ratio >= ref * (1 - 1e-7)) and np.all(ratio > 1e-3)


@pytest.mark.parametrize("make", [
    lambda P: np.vstack([np.zeros(4), P[1], P[2]]),
    lambda P: np.vstack([P[0], np.zeros(4), P[2]]),
    lambda P: np.vstack([P[0], P[1], np.zeros(4)]),
    lambda P: np.vstack([P[0], P[1], P[0] + P[1]]),
    lambda P: np.vstack([P[0], P[1], 2.0 * P[0] - 0.5 * P[1]]),
    lambda P: np.vstack([3.0 * P[2], P[1], P[2]]),
    lambda P: np.vstack([P[0], -2.0 * P[2], P[2]]),
    lambda P: np.outer([1.0, 2.0, 3.0], P[0]),
    lambda P: np.zeros((3, 4)),
], ids=["row1=0", "row2=0", "row3=0", "row3=row1+row2", "row3=comb", "row1=3row3", "row2=-2row3", "rank1", "zero"])
def test_genuinely_rank_deficient_cameras_are_refused(make):
    for P in (RNG.normal(size=(3, 4)), pixel_camera()):
        bad = make(P)
        assert np.linalg.matrix_rank(bad / np.abs(bad).max() if bad.any() else bad, tol=1e-9) < 3
        msg = error_of(lambda: validate_cameras([P, bad]))
        assert msg is not None and msg.startswith("cameras[1] has rank < 3"), msg
        cp = camera_problems(np.array([[P, bad]]))
        assert cp.valid.tolist() == [False] and cp.reason[0] == CameraIssue.RANK and cp.view[0] == 1


@pytest.mark.parametrize("k", [1e300, -1e300, 1e-300, -1e-300, 1e-310])
def test_scale_invariance(k):
    C = np.array([pixel_camera(), RNG.normal(size=(3, 4)), pixel_camera(f=50.0, pp=300.0)])
    V = validate_cameras(k * C)
    assert np.array_equal(V, k * C)
    assert camera_problems((k * C)[None]).valid.tolist() == [True]
    if abs(k) >= 1e-300:
        assert np.allclose(camera_rank_ratio(k * C), camera_rank_ratio(C), rtol=1e-12)


def test_overflow_to_inf_is_refused_naming_nan_or_inf():
    C = 1e300 * np.array([pixel_camera(), pixel_camera()])
    with np.errstate(over="ignore"):
        big = C * 1e10
    assert not np.all(np.isfinite(big))
    msg = error_of(lambda: validate_cameras(big))
    assert "NaN or inf" in msg and msg.startswith("cameras[0]")
    cp = camera_problems(big[None])
    assert cp.reason[0] == CameraIssue.NOT_FINITE and cp.view[0] == 0


def test_all_equal_up_to_scale_is_overflow_safe():
    P = pixel_camera()
    for C in ([P, -P], [P, 1e300 * P, -1e-300 * P], [1e300 * P, 1e300 * P]):
        assert "all equal up to scale" in error_of(lambda: validate_cameras(C))
        cp = camera_problems(np.array(C)[None])
        assert cp.reason[0] == CameraIssue.ALL_EQUAL and cp.view[0] == -1
        assert validate_cameras(C, require_distinct=False).shape == (len(C), 3, 4)
    assert not cameras_all_equal(np.array([P, 1e300 * pixel_camera()]))
    assert cameras_all_equal(np.array([P]))


def test_coincident_centres_are_valid_input():
    P, Q = pixel_camera(), pixel_camera()
    dup = np.array([P, P.copy(), Q])                            # a repeated view
    assert validate_cameras(dup).shape == (3, 3, 4)
    H = np.diag([2.0, 3.0, 1.0]) @ rotation()                   # same centre, another camera
    rotated = np.array([P, H @ P])
    assert validate_cameras(rotated).shape == (2, 3, 4)
    assert camera_problems(np.array([dup[:2].tolist() + [Q.tolist()], rotated.tolist() + [Q.tolist()]])).valid.all()
    # F is undefined for such a pair: the pair raises, fundamental_matrices can skip it
    with pytest.raises(ValueError, match="same camera centre"):
        fundamental_matrix(P, H @ P)
    with pytest.raises(ValueError, match=r"cameras 0 and 1: .*same camera centre"):
        fundamental_matrices(dup)
    Fs = fundamental_matrices(dup, skip_coincident=True)
    assert set(Fs) == {(0, 2), (1, 2)}
    assert np.allclose(Fs[(0, 2)], Fs[(1, 2)])


@pytest.mark.parametrize("cams,match", [
    (np.zeros((2, 3, 4), dtype=complex), "cameras must be real numbers, got complex128"),
    ([[[1j] * 4] * 3] * 2, "cameras must be real numbers, got complex128"),
    (np.ones((2, 3, 4), dtype=bool), "cameras must be real numbers, got bool"),
    (np.full((2, 3, 4), "1"), "cameras must be real numbers, got str"),
    (np.array([[[1.0] * 4] * 3, [[None] * 4] * 3], dtype=object), "cameras must be real numbers, got object"),
    ([np.eye(3, 4), None], "cameras must be a numeric array"),
    ("abc", "cameras must be real numbers, got str"),
    ([np.eye(3, 4), np.eye(3)], "cameras must be a numeric array"),
])
def test_non_numeric_cameras_are_named(cams, match):
    with pytest.raises(ValueError, match=match):
        validate_cameras(cams)
    with pytest.raises(ValueError, match=match):
        camera_problems(cams)


# ---------------------------------------------------------------- twins agree
def adversarial_stack(M=400, N=3):
    out = []
    for m in range(M):
        C = np.array([pixel_camera() if RNG.random() < 0.5 else RNG.normal(size=(3, 4)) for _ in range(N)])
        kind = m % 10
        i = int(RNG.integers(N))
        if kind == 1:
            C[i, 2] = C[i, 0] + C[i, 1]
        elif kind == 2:
            C[i, int(RNG.integers(3))] = 0.0
        elif kind == 3:
            C[i, 0] = 7.0 * C[i, 2] + 10.0 ** -RNG.uniform(5, 14) * RNG.normal(size=4)   # near the threshold
        elif kind == 4:
            C = np.array([RNG.choice([-1, 1]) * 10.0 ** RNG.uniform(-300, 300) * C[0] for _ in range(N)])
        elif kind == 5:
            C[i, int(RNG.integers(3)), int(RNG.integers(4))] = RNG.choice([np.nan, np.inf, -np.inf])
        elif kind == 6:
            C = C * 10.0 ** RNG.uniform(-300, 300, size=(N, 1, 1))
        elif kind == 7:
            C[i] = C[(i + 1) % N]                                          # a repeated view: valid
        elif kind == 8:
            C[i, 1] = C[i, 0] * RNG.uniform(0.5, 2) + 1e-9 * RNG.normal(size=4)
        out.append(C)
    return np.array(out)


@pytest.mark.parametrize("require_distinct", [True, False])
def test_validate_cameras_and_camera_problems_agree(require_distinct):
    S = adversarial_stack()
    cp = camera_problems(S, require_distinct=require_distinct)
    assert cp.valid.shape == (len(S),) and cp.reason.dtype == np.int8
    codes = {"NaN or inf": CameraIssue.NOT_FINITE, "rank < 3": CameraIssue.RANK, "all equal": CameraIssue.ALL_EQUAL}
    seen = set()
    for m, C in enumerate(S):
        msg = error_of(lambda: validate_cameras(C, min_views=1, require_distinct=require_distinct))
        assert (msg is None) == bool(cp.valid[m]), (m, msg)
        if msg is None:
            assert cp.reason[m] == CameraIssue.OK and cp.view[m] == -1
            continue
        code = next(v for k, v in codes.items() if k in msg)
        seen.add(code)
        assert cp.reason[m] == code, (m, msg)
        if code != CameraIssue.ALL_EQUAL:
            assert msg.startswith(f"cameras[{cp.view[m]}]")
    assert seen == ({CameraIssue.NOT_FINITE, CameraIssue.RANK, CameraIssue.ALL_EQUAL} if require_distinct
                    else {CameraIssue.NOT_FINITE, CameraIssue.RANK})
    assert 0.3 < cp.valid.mean() < 0.9


def test_camera_problems_is_vectorised():
    S = np.array([[pixel_camera() for _ in range(3)] for _ in range(50)])
    S = np.tile(S, (2000, 1, 1, 1))                                        # 10^5 problems
    t0 = time.perf_counter()
    cp = camera_problems(S)
    assert time.perf_counter() - t0 < 10.0
    assert cp.valid.all() and cp.valid.shape == (100_000,)


def test_camera_problems_shapes():
    with pytest.raises(ValueError, match=r"cameras must have shape \(M, N, 3, 4\)"):
        camera_problems(np.zeros((3, 3, 4)))
    cp = camera_problems(np.zeros((0, 3, 3, 4)))
    assert cp.valid.shape == (0,)


# ---------------------------------------------------------------- depths
def test_depths_equal_camera_frame_z_and_are_scale_invariant():
    R, t = rotation(), RNG.normal(size=3)
    K = np.array([[800.0, 0.5, 320.0], [0.0, 790.0, 240.0], [0.0, 0.0, 1.0]])      # det K > 0
    P = K @ np.c_[R, t]
    X = RNG.normal(size=(20, 3)) * 3
    z = (X @ R.T + t)[:, 2]
    Q = pixel_camera()
    d = depths(X, np.array([P, -7.0 * P, 1e300 * P, 1e-300 * P, Q]))
    for k in range(4):
        assert np.allclose(d[:, k], z, rtol=1e-12, atol=1e-12)
    assert np.all(np.sign(d[:, 0]) == np.sign(z))
    # an independent formula for Q: z-coordinate of X in Q's frame via its decomposition Q = K' [R' | t']
    M = Q[:, :3]
    k3 = np.linalg.norm(M[2])
    assert np.allclose(d[:, 4], (X @ Q[2, :3] + Q[2, 3]) / k3 * np.sign(np.linalg.det(M)))
    assert depths(X[0], [P, Q]).shape == (2,)
    assert np.isfinite(depths([1e300, -1e300, 1e300], [P, Q])).all()


def test_depth_of_an_affine_camera_is_nan():
    A = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])       # m3 = 0, rank 3
    d = depths([1.0, 2.0, 3.0], [np.eye(3, 4), A])
    assert d[0] == 3.0 and np.isnan(d[1])


def test_depths_stack_equals_depths():
    S = np.array([[pixel_camera() if RNG.random() < 0.5 else RNG.normal(size=(3, 4)) for _ in range(4)]
                  for _ in range(300)])
    S = S * 10.0 ** RNG.uniform(-200, 200, size=(300, 4, 1, 1))
    X = RNG.normal(size=(300, 3)) * 10.0 ** RNG.uniform(-3, 3, size=(300, 1))
    D = depths_stack(S, X)
    assert D.shape == (300, 4)
    ref = np.array([depths(X[m], S[m]) for m in range(300)])
    assert np.allclose(D, ref, rtol=1e-13, atol=0)
    # and against the definition on unscaled cameras
    S0 = S / np.abs(S).max(axis=(2, 3), keepdims=True)
    w = np.einsum("mnj,mj->mn", S0[:, :, 2, :], np.c_[X, np.ones(300)])
    ref2 = w * np.sign(np.linalg.det(S0[:, :, :, :3])) / np.linalg.norm(S0[:, :, 2, :3], axis=2)
    assert np.allclose(D, ref2, rtol=1e-10, atol=0)
    with pytest.raises(ValueError, match=r"X must have shape \(300, 3\)"):
        depths_stack(S, X[:5])
    with pytest.raises(ValueError, match="X must be real numbers, got complex128"):
        depths_stack(S, X + 0j)


# ---------------------------------------------------------------- projection and F at extreme scales
def test_projection_and_fundamental_matrix_at_extreme_scales():
    P, Q = pixel_camera(), pixel_camera()
    X = RNG.normal(size=(10, 3))
    x = project(X, P)
    assert np.array_equal(project(X, 2.0 ** 900 * P), x)             # scaling by a power of two: same bits
    assert np.allclose(project(X, 1e300 * P), x, rtol=1e-14)
    Xh = np.c_[X, np.ones(10)] * 1e300                                 # the same points, homogeneous at 1e300
    h = Xh / 1e300 @ P.T
    assert np.allclose(h[:, :2] / h[:, 2:], x, rtol=1e-12)
    assert np.allclose(image_points(X, [P, 1e-300 * Q])[:, 1], project(X, Q), rtol=1e-12)
    F = fundamental_matrix(P, Q)
    for kp, kq in [(1e300, 1e-300), (-1e200, 3.0), (1e-300, 1e-300)]:
        G = fundamental_matrix(kp * P, kq * Q)
        assert min(np.abs(G - F).max(), np.abs(G + F).max()) < 1e-9
    # pixel cameras: the epipolar constraint holds relative to the sizes involved
    xi = np.c_[project(X, P), np.ones(10)]
    xj = np.c_[project(X, Q), np.ones(10)]
    res = np.einsum("ka,ab,kb->k", xi, F, xj) / (np.linalg.norm(xi, axis=1) * np.linalg.norm(xj, axis=1))
    assert np.max(np.abs(res)) < 1e-10
    # unnormalised F scales as k_i^2 / k_j
    F0 = fundamental_matrix(P, Q, normalize=False)
    F1 = fundamental_matrix(4.0 * P, 2.0 * Q, normalize=False)
    assert min(np.abs(F1 - 8 * F0).max(), np.abs(F1 + 8 * F0).max()) <= 1e-12 * np.abs(F1).max()


def test_exactly_rank_2_cameras_whose_conditioning_lifts_the_ratio_are_refused():
    """Review 8b F3: row 3 = 4 row 2 + row 1 with integer entries < 2^53 (exactly rank 2 as floats): the
    conditioning lifts sigma3/sigma1 to ~5e-8 by round-off; below EXACT_RANK_BELOW the rank is decided in rationals."""
    from tritools.model.cameras import exactly_rank_deficient

    r1 = np.array([3.0, -6.0, 7.0, 4.0])
    r2 = np.array([3695536540.0, -1252677480.0, 3378079560.0, 3334729820.0])
    bad = np.stack([r1, r2, 4 * r2 + r1])
    assert exactly_rank_deficient(bad) and not exactly_rank_deficient(pixel_camera())
    assert camera_rank_ratio(bad) == 0.0 and camera_rank_ratio(bad[None])[0] == 0.0
    msg = error_of(lambda: validate_cameras([pixel_camera(), bad]))
    assert msg is not None and msg.startswith("cameras[1] has rank < 3"), msg
    near = bad.copy()
    near[2, 3] += 1.0                                   # rank 3 exactly (if badly conditioned): kept as computed
    assert not exactly_rank_deficient(near)
