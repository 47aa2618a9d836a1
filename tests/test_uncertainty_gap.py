"""The box-tightness rule of certified 3D uncertainty (tritools.uncertain.witness.witness_gap), one place for both
the certified box (uncertain.api) and the level-set box (uncertain.level)."""
import numpy as np

from tritools.uncertain.witness import witness_gap


def _w(rows):
    return np.array(rows, float)


def test_bounded_box_gap_and_relative_gap():
    lo, hi = np.zeros(3), np.array([2.0, 4.0, 1.0])
    wl = _w([[0.5, 1, 0.5], [1, 0.0, 0.5], [1, 1, 0.25]])
    wh = _w([[2.0, 1, 0.5], [1, 3.0, 0.5], [1, 1, 1.0]])
    gap, rel, inner, dw = witness_gap(lo, hi, wl, wh, np.zeros(3), True)
    assert gap == 1.0                                   # hi[1] - wh[1, 1]
    assert rel == 0.25                                  # over the largest width 4
    far = np.linalg.norm(wh, axis=1).max()
    assert inner <= far and inner > far * (1 - 1e-14)   # rounded down, never above a witness's distance
    assert np.allclose(dw, wh[1])


def test_missing_witness_of_a_finite_side_is_an_infinite_gap():
    lo, hi = np.zeros(3), np.ones(3)
    wl = _w([[np.nan] * 3, [0.5, 0, 0.5], [0.5, 0.5, 0]])
    wh = _w([[1, 0.5, 0.5], [0.5, 1, 0.5], [0.5, 0.5, 1]])
    gap, rel, _, _ = witness_gap(lo, hi, wl, wh, np.full(3, 0.5), True)
    assert gap == np.inf and rel == np.inf


def test_unbounded_box_never_reports_a_zero_relative_gap_for_a_loose_side():
    lo, hi = np.array([0.0, -np.inf, -np.inf]), np.full(3, np.inf)
    nan = [np.nan] * 3
    wl = _w([[0.1, 0, 0], nan, nan])
    wh = _w([nan, nan, nan])
    gap, rel, _, _ = witness_gap(lo, hi, wl, wh, np.zeros(3), False)
    assert gap == 0.1 and rel == np.inf
    gap, rel, inner, dw = witness_gap(lo, hi, _w([[0.0, 0, 0], nan, nan]), wh, np.zeros(3), False)
    assert gap == 0.0 and rel == 0.0 and inner == 0.0


def test_no_finite_side_and_no_witness():
    inf = np.full(3, np.inf)
    nan = np.full((3, 3), np.nan)
    gap, rel, inner, dw = witness_gap(-inf, inf, nan, nan, np.zeros(3), False)
    assert gap == 0.0 and rel == 0.0 and np.isnan(inner) and np.all(np.isnan(dw))
