"""The scalar twins of :mod:`tritools.model.centres_few` give the stacked functions' numbers bit for bit, and
``fundamental_stack`` on a few cameras (the twins) equals the same stack through the stacked steps."""
import numpy as np
import pytest

import tritools.model.centres_few as cf
from tritools.model.stacked import (centre_vectors, distinct_centres, fundamental_stack, null_vectors,
                                    view_pairs)


def _rotation(rng):
    q, r = np.linalg.qr(rng.standard_normal((3, 3)))
    return q * np.sign(np.diag(r))


def _cameras(rng, n: int, kind: str) -> np.ndarray:
    """n cameras of one kind: generic, shared centres (exact copies, multiples, rotations at one centre), centres
    1e-12 apart, georeferenced (1e7 away), pixel scales 1e-3 / 1e6, entries from 1e-200 to 1e200."""
    K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])
    c_first, R_first = rng.normal(size=3) * 3, _rotation(rng)
    cams = []
    for i in range(n):
        c, R = (c_first, R_first) if i == 0 else (rng.normal(size=3) * 3, _rotation(rng))
        if kind == "shared":
            c, R = c_first, (R if i % 2 else R_first)
        if kind == "near" and i:
            c = c_first + rng.normal(size=3) * 1e-12
        if kind == "georef":
            c = c + np.array([3.2e7, -1.1e7, 4.0e5])
        P = K @ np.hstack([R, (-R @ c)[:, None]])
        if kind == "pixels":
            P = np.diag([1e6, 1e6, 1.0]) @ P if i % 2 else np.diag([1e-3, 1e-3, 1.0]) @ P
        if kind == "extreme":
            P = P * 10.0 ** rng.integers(-200, 200)
        if kind == "shared" and i == n - 1 and i:
            P = -2.5 * cams[0]
        cams.append(P)
    return np.array(cams)


KINDS = ["generic", "shared", "near", "georef", "pixels", "extreme"]


def _same(a, b) -> bool:
    return a.shape == b.shape and np.array_equal(a, b, equal_nan=True)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.filterwarnings("ignore::RuntimeWarning")        # (numpy's minors of 1e200 cameras overflow)
def test_twins_bit_for_bit(kind):
    rng = np.random.default_rng(KINDS.index(kind))
    for _ in range(60):
        C = _cameras(rng, int(rng.integers(2, 6)), kind)
        P = C.tolist()
        assert _same(np.array(cf.null_vectors_few(P)), null_vectors(C))
        c_few = np.array(cf.centre_vectors_few(P))
        c_np = centre_vectors(C)
        assert _same(c_few, c_np)
        I, J = view_pairs(len(C))
        d_np = distinct_centres(c_np[I], c_np[J])
        d_few = np.array([cf.distinct_few(tuple(c_few[i]), tuple(c_few[j])) for i, j in zip(I, J)])
        assert np.array_equal(d_few, d_np)


@pytest.mark.parametrize("kind", KINDS)
def test_fundamental_stack_few_equals_stacked(kind, monkeypatch):
    rng = np.random.default_rng(100 + KINDS.index(kind))
    for _ in range(30):
        N = int(rng.integers(2, 5))
        C = np.array([_cameras(rng, N, kind) for _ in range(int(rng.integers(1, 3)))])
        assert cf.few_distinct(C, *view_pairs(N)) is not None
        with np.errstate(all="ignore"):             # (extreme cameras overflow in F, as every caller allows)
            F, defined = fundamental_stack(C)
            monkeypatch.setattr(cf, "FEW_CAMERAS", 0)
            F_np, defined_np = fundamental_stack(C)
            monkeypatch.undo()
        assert np.array_equal(defined, defined_np)
        assert _same(F, F_np)


def test_shared_centres_found():
    """The kind "shared" holds coincident centres (copies, -2.5 P, rotations about one centre): the twin says so."""
    rng = np.random.default_rng(7)
    C = _cameras(rng, 4, "shared")
    c = cf.centre_vectors_few(C.tolist())
    assert not cf.distinct_few(c[0], c[3])          # -2.5 P: the same centre
    assert not cf.distinct_few(c[0], c[1])          # rotated about the same centre
    assert not cf.distinct_few(c[0], (0.0, 0.0, 0.0, 0.0))


def test_few_distinct_declines_large_or_non_finite():
    rng = np.random.default_rng(3)
    C = _cameras(rng, 3, "generic")[None]
    I, J = view_pairs(3)
    assert cf.few_distinct(np.repeat(C, 3, axis=0), I, J) is None        # 9 cameras > FEW_CAMERAS
    bad = C.copy()
    bad[0, 1, 0, 0] = np.nan
    assert cf.few_distinct(bad, I, J) is None
