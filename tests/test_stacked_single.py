"""The low-overhead twins of the single-call path (issue #22) give the same bits as what they replace.

* :func:`tritools.model.stacked.norms` vs ``numpy.linalg.norm`` and :func:`tritools.model.stacked.median_rows`
  vs ``numpy.median`` (independent references: numpy itself) on random and adversarial arrays (1e-300..1e300,
  inf, NaN, signed zeros, one column, even and odd lengths);
* the batched camera centres of :mod:`tritools.model.frame` vs the camera-by-camera loop;
* the normalisation of a stack of one remembered for the same data bit for bit, and the remembered copy
  independent of what a caller does with the arrays it got;
* the stacked LM refinement on a stack of one (``scalar=False``) vs the same problem inside a stack of many;
on the adversarial scenes of the project: pixel scales 1e-3..1e6, georeferenced worlds, rescaled cameras,
duplicated views, zero noise.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from tritools.model import frame as F
from tritools.model import magnitude as MG
from tritools.model import normalize as NZ
from tritools.model.stacked import median_rows, norms, refine_points_stack
from tritools.scene import random_scene


def _arrays(rng, shape):
    a = rng.normal(size=shape) * 10.0 ** rng.uniform(-300, 300, size=shape)
    a.flat[rng.integers(0, a.size, size=max(1, a.size // 7))] = 0.0
    return a


@pytest.mark.parametrize("shape, axis", [((5, 3), 1), ((2, 7, 2), 2), ((3, 4, 3, 4), (2, 3)), ((6, 4), -1),
                                         ((1, 1, 3), 2), ((4, 3, 4), (1, 2))])
def test_norms_equal_numpy_bit_for_bit(shape, axis):
    rng = np.random.default_rng(0)
    for _ in range(50):
        a = _arrays(rng, shape)
        with np.errstate(all="ignore"):
            ref = np.linalg.norm(a, axis=axis)
            got = norms(a, axis=axis)
            assert np.array_equal(got, ref, equal_nan=True)
            if not isinstance(axis, tuple):
                assert np.array_equal(norms(a, axis=axis, keepdims=True),
                                      np.linalg.norm(a, axis=axis, keepdims=True), equal_nan=True)
    b = np.array([[np.inf, 1.0], [np.nan, 0.0], [-0.0, 0.0], [1e-320, 0.0]])
    with np.errstate(all="ignore"):
        assert np.array_equal(norms(b, axis=1), np.linalg.norm(b, axis=1), equal_nan=True)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5, 8, 13])
def test_median_rows_equal_numpy_bit_for_bit(n):
    rng = np.random.default_rng(n)
    for k in range(200):
        a = _arrays(rng, (4, n)) if k % 2 else rng.normal(size=(4, n))
        if k % 5 == 0:
            a[rng.integers(0, 4), rng.integers(0, n)] = rng.choice([np.inf, -np.inf, np.nan])
        if k % 7 == 0:
            a[1] = a[1, 0]                      # ties
        with np.errstate(all="ignore"):
            ref = np.median(a, axis=1)
        assert np.array_equal(median_rows(a), ref, equal_nan=True), (a, median_rows(a), ref)
    assert np.all(np.isnan(median_rows(np.zeros((3, 0)))))


def _scenes():
    """(name, cameras (N, 3, 4), points (M, N, 2)) of the adversarial cases."""
    out = []
    for N, noise in ((2, 1.0), (5, 0.0), (10, 1.0), (13, 30.0)):
        sc = random_scene(N, 5, noise_px=noise, seed=N)
        C, x = np.asarray(sc.cameras), np.asarray(sc.points2d)
        out.append((f"N{N}", C, x))
        for pix in (1e-3, 1e6):
            S = np.diag([pix / 800, pix / 800, 1.0])
            out.append((f"N{N}-pix{pix:g}", S @ C, x * pix / 800))
        T = np.eye(4)
        T[:3, 3] = [4e6, -3e6, 1e5]                         # georeferenced: P_geo = P T^-1
        out.append((f"N{N}-geo", C @ np.linalg.inv(T), x))
        scale = np.random.default_rng(N).uniform(1e-4, 1e4, size=N)[:, None, None]
        out.append((f"N{N}-rescaled", C * scale, x))
        out.append((f"N{N}-dup", np.concatenate([C, C[:1]]), np.concatenate([x, x[:, :1]], axis=1)))
    return out


SCENES = _scenes()


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_batched_centres_equal_the_loop(name, C, x):
    with np.errstate(all="ignore"):                         # C * 1e300 overflows in some entries: inf centres dropped
        variants = (C, C * 1e300, C[:, :, ::-1], np.concatenate([C, np.zeros((1, 3, 4))]))
    for cams in variants:
        with np.errstate(all="ignore"):
            assert np.array_equal(F._centres(cams), F._centres_loop(cams), equal_nan=True)


def _fields(st, m=None):
    names = ("scale", "shifts", "origin", "depth", "cameras_n", "Xn", "ok", "resolution", "converged")
    return [np.asarray(getattr(st, f)) if m is None else np.asarray(getattr(st, f))[m] for f in names]


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_stack_of_one_is_remembered_bit_for_bit(name, C, x):
    """The remembered normalisation of a stack of one is the one computed (the stack of one against a stack of
    many -- the scalar LM against the stacked one, up to round-off -- is in tests/test_scalar_twins.py)."""
    M = len(x)
    for m in range(M):
        NZ._LAST_SINGLE[0] = None
        fresh = NZ.normalization_stack(C[None].copy(), x[m:m + 1].copy())
        again = NZ.normalization_stack(C[None].copy(), x[m:m + 1].copy())       # remembered
        for a, b in zip(_fields(fresh), _fields(again)):
            assert np.array_equal(a, b, equal_nan=True)


def test_remembered_normalisation_is_a_private_copy():
    sc = random_scene(4, 2, noise_px=1.0, seed=3)
    C, x = np.asarray(sc.cameras)[None], np.asarray(sc.points2d)[:1]
    NZ._LAST_SINGLE[0] = None
    first = NZ.normalization_stack(C, x)
    keep = [a.copy() for a in _fields(first)]
    for a in _fields(first):
        a[...] = 0                                          # a caller scribbling on its result ...
    second = NZ.normalization_stack(C, x)
    for a, b in zip(_fields(second), keep):
        assert np.array_equal(a, b, equal_nan=True)         # ... does not change the next caller's
    third = NZ.normalization_stack(C, x + 1e-9)             # other data: computed, not remembered
    assert not np.array_equal(third.Xn, keep[5]) or not np.array_equal(third.scale, keep[0])


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_lm_of_one_equals_lm_in_a_stack(name, C, x):
    M = len(x)
    Cs = np.broadcast_to(C / np.abs(C).max(), (M,) + C.shape).copy()
    X0 = np.zeros((M, 3))
    X0[1::2] = 0.3                                          # some start elsewhere: the stack's rows stop apart
    X, ok, conv = refine_points_stack(Cs, x, X0, np.ones(M, bool), return_converged=True)
    for m in range(M):          # (scalar=False: the stacked code on one row; the scalar twin: test_scalar_twins.py)
        X1, ok1, conv1 = refine_points_stack(Cs[m:m + 1], x[m:m + 1], X0[m:m + 1], np.ones(1, bool),
                                             return_converged=True, scalar=False)
        assert np.array_equal(X1[0], X[m], equal_nan=True)
        assert ok1[0] == ok[m] and conv1[0] == conv[m]


@pytest.mark.parametrize("name, C, x", SCENES, ids=[s[0] for s in SCENES])
def test_point_report_equals_its_per_view_reference(name, C, x):
    """The report projects with the point scaled once and takes the depths of validated cameras without a second
    check: the same numbers as project_homogeneous per view and geometry.depths (which validates)."""
    from tritools import Ellipse, Point
    from tritools.model.geometry import depths, gamma, project_homogeneous
    from tritools.solve.report import point_report

    rng = np.random.default_rng(len(x))
    for m in range(len(x)):
        for regions in ([Point(p) for p in x[m]], [Ellipse(p, np.diag([4.0, 1.0])) for p in x[m]]):
            for X in (rng.normal(size=3), np.array([0.0, 0.0, 1e-9]), rng.normal(size=3) * 1e7):
                rep = point_report(X, C, regions)
                Xh = np.append(X, 1.0)[None]
                ref = []
                for P, r in zip(C, regions):
                    u = project_homogeneous(Xh, P)[0]
                    ref.append(float(r.distance(u)) if np.all(np.isfinite(u)) else np.inf)
                assert np.array_equal(rep.residuals, np.array(ref))
                assert np.array_equal(rep.depths, depths(X, C), equal_nan=True)
                assert np.array_equal(point_report(X, C, regions, "reflected").depths, depths(X, C, "reflected"),
                                      equal_nan=True)
                if np.all(np.isfinite(ref)):
                    assert rep.gamma == pytest.approx(gamma(X, C, regions), rel=1e-12)


@pytest.mark.parametrize("n", [1, 2, 3, 4, 7])
def test_nanmedian_rows_equals_numpy(n):
    rng = np.random.default_rng(10 + n)
    for k in range(200):
        a = _arrays(rng, (5, n)) if k % 2 else rng.normal(size=(5, n))
        a[rng.random((5, n)) < 0.3] = np.nan
        if k % 3 == 0:
            a[k % 5] = np.nan                                       # an all-NaN row now and then
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)         # numpy warns on an all-NaN row
            ref = np.nanmedian(a, axis=1)
        assert np.array_equal(MG._nanmedian_rows(a), ref, equal_nan=True)


def test_clip_scale_equals_numpy_clip():
    rng = np.random.default_rng(5)
    s = np.concatenate([10.0 ** rng.uniform(-12, 12, 500), [0.0, -0.0, np.inf, -np.inf, np.nan, 1e-8, 1e8]])
    assert np.array_equal(NZ._clip_scale(s), np.clip(s, *NZ.SCALE_BOUNDS), equal_nan=True)
    assert np.array_equal(np.signbit(NZ._clip_scale(s)), np.signbit(np.clip(s, *NZ.SCALE_BOUNDS)))


def test_singlecall_benchmark_script_runs(capsys):
    """benchmarks/singlecall.py (issue #22's figures) on reduced sizes: one row per track kind, positive times, and
    the ratio column their quotient."""
    import importlib.util
    import pathlib

    path = pathlib.Path(__file__).resolve().parents[1] / "benchmarks" / "singlecall.py"
    spec = importlib.util.spec_from_file_location("singlecall", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    mod.main(["--points", "4", "--repeats", "1", "--calls"])
    rows = [r for r in capsys.readouterr().out.splitlines() if r.startswith("| points") or r.startswith("| 1 px")]
    assert len(rows) == 6                   # points N = 2, 5 (shared and own cameras), 10; discs
    for r in rows:
        single, many, ratio, calls = (float(c) for c in r.strip("|").split("|")[1:])
        assert single > 0 and many > 0 and calls > 100
        assert ratio == pytest.approx(single / many, rel=0.05, abs=0.2)      # (printed rounded)
