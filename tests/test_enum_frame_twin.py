"""The scalar twin of the enumeration's frame (:func:`tritools.solve.robust_enum.enum_frame_one`) against the stacked
rule (:func:`~tritools.solve.robust_enum.enum_frames` on a stack of one): the same frames (None on the same data) and
the same normalised cameras up to round-off, on ordinary, noise-free (the floor of rho), georeferenced, rescaled and
degenerate problems."""
import numpy as np
import pytest

from tritools.scene import random_cameras
from tritools.solve.robust_enum import FRAME_SCALAR_MAX_VIEWS, enum_frame, enum_frame_one, enum_frames


def _problem(rng, N, noise=1.0, shift=0.0, pixel=1.0):
    """N cameras of :func:`tritools.scene.random_cameras` in a world moved by ``shift``, pixels times ``pixel``, each
    camera at its own scale, and the noisy projections of a random point."""
    T = np.eye(4)
    T[:3, 3] = -shift                                  # world point X + shift seen as X was
    cams = np.diag([pixel, pixel, 1.0]) @ random_cameras(N, rng) @ T
    cams = cams * rng.uniform(0.5, 2.0, size=(N, 1, 1))
    h = cams @ np.append(rng.normal(size=3) + shift, 1.0)
    return cams, h[:, :2] / h[:, 2:] + rng.normal(scale=noise * pixel, size=(N, 2))


def _assert_same(C, x):
    one = enum_frame_one(C, x)
    frames, Cn = enum_frames(C[None], x[None])
    assert (one is None) == (frames[0] is None)
    if one is None:
        return False
    fr, cn = one
    ref = frames[0]
    assert fr.scale == pytest.approx(ref.scale, rel=1e-13)
    assert fr.depth == pytest.approx(ref.depth, rel=1e-13)
    np.testing.assert_allclose(fr.origin, ref.origin, rtol=1e-13, atol=1e-13 * max(1.0, np.abs(ref.origin).max()))
    np.testing.assert_allclose(cn, Cn[0], rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(fr.shifts, x)
    return True


@pytest.mark.parametrize("N", [2, 3, 5, 7])
@pytest.mark.parametrize("noise, shift, pixel", [(1.0, 0.0, 1.0), (0.0, 0.0, 1.0), (5.0, 1e6, 1.0),
                                                 (1.0, 0.0, 1e-3), (1.0, 0.0, 1e4)])
def test_twin_equals_the_stack(N, noise, shift, pixel):
    rng = np.random.default_rng([N, int(noise), int(np.log10(pixel) + 10), int(shift > 0)])
    framed = sum(_assert_same(*_problem(rng, N, noise, shift, pixel)) for _ in range(10))
    assert framed == 10


def test_degenerate_data_give_none_on_both():
    rng = np.random.default_rng(3)
    C, x = _problem(rng, 3)
    A = C.copy()
    A[1, 2, :3] = 0.0                          # an affine camera: its centre at infinity
    assert enum_frame_one(A, x) is None and not _assert_same(A, x)
    D = C.copy()
    D[:, :, 3] = 0.0                           # every centre at the origin, observations of no common point
    _assert_same(D, x)


def test_dispatch():
    rng = np.random.default_rng(5)
    for N in (3, FRAME_SCALAR_MAX_VIEWS + 1):
        C, x = _problem(rng, N)
        fr, cn = enum_frame(C, x)
        frames, Cn = enum_frames(C[None], x[None])
        assert fr.scale == pytest.approx(frames[0].scale, rel=1e-13)
        np.testing.assert_allclose(cn, Cn[0], rtol=1e-12, atol=1e-14)
