"""The camera-only work a single call remembers for the last cameras (tritools.solve.fastpath_cameras, issue #22).

Independent references: the functions it stands in for, called directly on the same data (validate_cameras,
world_frame + WorldFrame.cameras, depths_stack_arrays) -- the same bits for a hit and
a miss, on the adversarial scenes (pixel scales 1e-3..1e6, georeferenced, rescaled, duplicated views), for
cameras seen in turn (A, B, A); bad cameras still raise the ValueError naming the field right after good ones
with the same shape, and nothing a caller does to the arrays it got changes the next call's numbers.
"""
from __future__ import annotations

import numpy as np
import pytest

import tritools
from tritools.model.cameras import depths_stack_arrays, validate_cameras
from tritools.model.frame import world_frame
from tritools.scene import random_scene
from tritools.solve import fastpath_cameras as FC

from .test_stacked_single import SCENES


def _forget():
    for memo in (FC._LAST_VALID, FC._LAST_FRAME, FC._LAST_ROWS):
        memo[0] = None


def _direct(C):
    cams = validate_cameras(C)
    frame = world_frame(cams)
    cams_f = frame.cameras(cams)
    X = np.array([0.3, -0.2, 7.0])
    return (cams, frame.origin, cams_f, depths_stack_arrays(cams_f[None], X[None], "reflected")[0])


def _remembered(C):
    cams = FC.validated_cameras(C)
    frame, cams_f = FC.framed_cameras(cams)
    X = np.array([0.3, -0.2, 7.0])
    return cams, frame.origin, cams_f, FC.depths_one(cams_f, X, "reflected")


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_remembered_camera_work_equals_the_direct_functions(name, C, x):
    other = SCENES[(SCENES.index(next(s for s in SCENES if s[0] == name)) + 1) % len(SCENES)][1]
    _forget()
    for cams in (C, other, C, C, other):                # misses and hits, alternating
        ref = _direct(cams)
        got = _remembered(cams)
        for a, b in zip(got, ref):
            assert a.shape == b.shape and np.array_equal(a, b, equal_nan=True), name


def test_bad_cameras_still_raise_after_good_ones():
    sc = random_scene(3, 1, noise_px=1.0, seed=2)
    C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)[0]
    _forget()
    tritools.triangulate(C, x)                          # remembered
    nan = C.copy()
    nan[1, 0, 2] = np.nan
    flat = C.copy()
    flat[2, 1] = flat[2, 2] * 3.0                       # rank 2
    for bad, msg in ((nan, r"cameras\[1\] contains NaN or inf"), (flat, r"cameras\[2\] has rank < 3"),
                     (np.array([C[0], 2.0 * C[0], -C[0]]), "all equal up to scale"),
                     (C.astype(complex), "cameras must be real numbers"), (C[:, :2], "shape")):
        with pytest.raises(ValueError, match=msg):
            tritools.triangulate(bad, x)
        with pytest.raises(ValueError, match=msg):
            tritools.triangulate(bad, x)                # twice: a bad input is never remembered
    assert tritools.triangulate(C, x).optimal           # the good cameras still work (and were not replaced)


def test_callers_cannot_change_the_remembered_numbers():
    sc = random_scene(4, 1, noise_px=1.0, seed=5)
    C = np.asarray(sc.cameras)
    _forget()
    ref = _direct(C)
    cams = FC.validated_cameras(C)
    frame, cams_f = FC.framed_cameras(cams)
    cams[...] = 0.0                                     # a caller writing into what it got ...
    cams_f[...] = 0.0
    with pytest.raises(ValueError):
        frame.origin[...] = 1.0                         # (read-only)
    for a, b in zip(_remembered(C), ref):               # ... does not change the next call's numbers
        assert np.array_equal(a, b, equal_nan=True)


def test_a_call_with_other_cameras_gives_its_own_answer():
    """Two scenes in turn through the public call: each result equal to the same call with nothing remembered."""
    scenes = [random_scene(N, 2, noise_px=1.0, seed=N) for N in (2, 3, 2)]
    fresh = []
    for sc in scenes:
        _forget()
        fresh.append(tritools.triangulate(np.asarray(sc.cameras), np.asarray(sc.points2d)[1]))
    _forget()
    for sc, ref in zip(scenes + scenes, fresh + fresh):
        got = tritools.triangulate(np.asarray(sc.cameras), np.asarray(sc.points2d)[1])
        assert (got.status, got.optimal, got.certified_by) == (ref.status, ref.optimal, ref.certified_by)
        assert got.gamma_lb == ref.gamma_lb and got.gamma_ub == ref.gamma_ub and np.array_equal(got.X, ref.X)
        assert np.array_equal(got.depths, ref.depths)
