"""The named stages of one point (tritools.solve.stages): stage lists as data, fast implementations equal to the
generic ones, one settings object, the per-point deadline in the vectorised stages."""
from __future__ import annotations

import time

import numpy as np
import pytest

import sospoly
import tritools
from sospoly.budget import Deadline
from tritools.model.geometry import refine_l2, validate_cameras
from tritools.model.regions import Ellipse
from tritools.scene import random_scene
from tritools.solve.fastpath import verify_points
from tritools.solve.options import TriangulationOptions, options_from
from tritools.solve.sdp_batch import solve_corollary1_points
from tritools.solve.settings import SolveSettings, stack_deadline
from tritools.solve.stages import (FAST_ALL, FAST_DEFAULT, POINT_STAGES, SDP_IMPLEMENTATIONS, STEP_STAGES,
                                   VERIFY_IMPLEMENTATIONS, AttemptStep, ImplName, Stage, run_point, with_stage)

#: bounds of the same program by two implementations agree to the solver's accuracy in c = 2N gamma^2 units
C_TOL = 1e-7


def _tracks(n_views: int, n_points: int, noise: float, seed: int):
    sc = random_scene(n_views, n_points, noise_px=noise, seed=seed)
    return validate_cameras(sc.cameras), [list(sc.regions(j)) for j in range(n_points)]


def _same(a, b, n_views: int):
    """Same decision, bounds within the solver tolerance (in c units), estimates that agree."""
    assert a.status == b.status and a.optimal == b.optimal
    assert abs(2 * n_views * (a.gamma_lb ** 2 - b.gamma_lb ** 2)) <= C_TOL * max(1.0, 2 * n_views * a.gamma_ub ** 2)
    assert abs(a.gamma_ub - b.gamma_ub) <= 1e-7 * max(1.0, a.gamma_ub)
    np.testing.assert_allclose(a.X, b.X, rtol=1e-5, atol=1e-5 * np.linalg.norm(b.X))


def _multistart_gamma(cams, regions, X0) -> float:
    """An independent upper reference: the best local L2 optimum from perturbed starts (Levenberg-Marquardt)."""
    rng = np.random.default_rng(0)
    best = np.inf
    for k in range(8):
        X = refine_l2(X0 + (0.0 if k == 0 else rng.normal(scale=0.3, size=3)), cams, regions)
        if X is not None:
            best = min(best, float(tritools.gamma(X, cams, regions)))
    return best


def test_stage_lists_are_named_data():
    assert [s.name for s in POINT_STAGES] == ["plan", "verify", "trivial", "sub_problem", "steps", "exact_variety",
                                              "settle", "world_frame", "report"]
    assert [s.name for s in STEP_STAGES] == ["sdp", "estimate", "rigor", "decide", "resolve"]
    assert [i.name for i in VERIFY_IMPLEMENTATIONS] == ["verify-points", "verify-discs", "verify-ellipses",
                                                        "verify-regions", "generic"]
    assert [i.name for i in SDP_IMPLEMENTATIONS] == ["sdp-points", "generic"]
    assert FAST_DEFAULT < FAST_ALL and ImplName.SDP_POINTS not in FAST_DEFAULT   # a single call: the generic SDP
    assert "sdp-points" in FAST_ALL and AttemptStep.SDP in {"sdp"}               # members hash as their strings
    with pytest.raises(ValueError, match="fast: unknown implementation 'sdp-fast'"):
        cams, tracks = _tracks(2, 1, 1.0, seed=1)
        run_point(cams, tracks[0], options_from(None), fast={"sdp-fast"})
    extra = Stage("extra", lambda ctx: None)
    assert [s.name for s in with_stage(POINT_STAGES, extra, before="verify")][1:3] == ["extra", "verify"]
    with pytest.raises(ValueError, match="no stage named 'nope'"):
        with_stage(POINT_STAGES, extra, after="nope")
    with pytest.raises(ValueError, match="already"):
        with_stage(POINT_STAGES, Stage("plan", lambda ctx: None), after="report")


def test_inserted_stages_run_without_touching_the_others():
    """A point stage after ``settle`` and a step stage after ``decide``: each runs, sees what it should, and the
    result is the default pipeline's."""
    cams, tracks = _tracks(3, 1, 2.0, seed=5)
    opts = options_from(None, path="sdp", method="corollary1", delta=2, max_delta=4)
    seen_steps, seen_final = [], []

    def after_decide(ctx, st):
        seen_steps.append((st.step.delta, st.result.status))

    def after_settle(ctx):
        seen_final.append(ctx.best.status)
        ctx.timings["audit"] = 0.0

    stages = with_stage(POINT_STAGES, Stage("audit", after_settle), after="settle")
    step_stages = with_stage(STEP_STAGES, Stage("watch", after_decide), after="decide")
    res = run_point(cams, tracks[0], opts, stages=stages, step_stages=step_stages)
    ref = run_point(cams, tracks[0], opts)
    sdp = [a for a in res.attempts if a.step == AttemptStep.SDP]
    assert [d for d, _ in seen_steps] == [a.delta for a in sdp] and len(sdp) >= 1
    assert [s.value for _, s in seen_steps] == [a.status for a in sdp]
    assert seen_final == [res.status] and "audit" in res.timings
    assert res.status == ref.status and res.gamma_lb == pytest.approx(ref.gamma_lb, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("n_views,noise,seed", [(2, 1.0, 1), (4, 2.0, 2), (6, 0.5, 3)])
def test_fast_and_generic_verification_agree_on_point_tracks(n_views, noise, seed):
    cams, tracks = _tracks(n_views, 3, noise, seed)
    opts = options_from(None)
    for regions in tracks:
        fast = run_point(cams, regions, opts)
        generic = run_point(cams, regions, opts, fast=frozenset())
        assert fast.certified_by == generic.certified_by == "verification"
        _same(fast, generic, n_views)
        assert fast.gamma_lb <= _multistart_gamma(cams, regions, fast.X) * (1 + 1e-9) + 1e-12


@pytest.mark.parametrize("n_views,noise,seed", [(3, 1.0, 4), (5, 3.0, 5)])
def test_fast_and_generic_sdp_agree_on_point_tracks(n_views, noise, seed):
    """The batched delta = 2 SDP as the sdp stage of a single call equals the generic (compiled) SDP."""
    cams, tracks = _tracks(n_views, 3, noise, seed)
    opts = options_from(None, path="sdp", method="corollary1", delta=2, max_delta=2)
    for regions in tracks:
        batched = run_point(cams, regions, opts, fast=FAST_ALL)
        generic = run_point(cams, regions, opts)
        assert [a.step for a in batched.attempts] == [AttemptStep.SDP_BATCH]
        assert [a.step for a in generic.attempts] == [AttemptStep.SDP]
        _same(batched, generic, n_views)


def test_fast_disc_verification_agrees_with_the_sdp():
    """Discs: the vectorised verification and the generic route (the degree-2 SDP: the generic verification does
    not take inequalities) take the same decision with the same bounds."""
    cams, tracks = _tracks(4, 3, 1.5, seed=11)
    opts = options_from(None)
    for regions in tracks:
        discs = [Ellipse(r.center, 0.25 * np.eye(2)) for r in regions]
        fast = run_point(cams, discs, opts)
        generic = run_point(cams, discs, opts, fast=frozenset())
        assert fast.certified_by == "verification" and generic.certified_by in ("sdp", "trivial_bound")
        _same(fast, generic, 4)


def test_settings_one_object_backend_none_is_auto_on_every_path(monkeypatch):
    """backend=None means "auto" on the compiled path and on the free-multiplier (GEVP) path alike."""
    s = SolveSettings.from_options(TriangulationOptions())
    assert s.backend == "auto" and s.auto_backend and s.tolerances is TriangulationOptions().tolerances
    assert SolveSettings.from_options(TriangulationOptions(backend="clarabel")).backend == "clarabel"
    with pytest.raises(TypeError, match="SolveSettings.backend"):
        SolveSettings(None, s.form, s.tolerances, s.deadline)
    with pytest.raises(TypeError, match="SolveSettings.tolerances must be a Tolerances"):
        SolveSettings("auto", s.form, None, s.deadline)
    seen = []
    real = sospoly.solve_psatz

    def spy(psatz, **kw):
        seen.append(kw["backend"])
        return real(psatz, **kw)

    monkeypatch.setattr(sospoly, "solve_psatz", spy)
    cams, tracks = _tracks(2, 1, 1.0, seed=7)
    for multiplier in ("fixed", "free"):
        seen.clear()
        res = tritools.triangulate(cams, tracks[0], "corollary1", 2, 2, path="sdp", multiplier=multiplier)
        assert seen and set(seen) == {"auto"}, (multiplier, seen)
        assert res.gamma_lb is not None and res.gamma_lb <= res.gamma_ub


def test_the_per_point_deadline_reaches_the_vectorised_stages():
    cams, tracks = _tracks(5, 4, 2.0, seed=9)
    C = np.broadcast_to(cams, (4,) + cams.shape).copy()
    x = np.array([[r.center for r in t] for t in tracks])
    past = Deadline(time.monotonic() - 1.0)
    assert verify_points(C, x).certified.all()
    late = verify_points(C, x, deadline=past)
    assert not late.certified.any()                    # no Lagrangian bound was computed after the deadline
    out = solve_corollary1_points(C, x, deadline=past)
    assert not out.done.any() and all("time limit" in r for r in out.reason)
    assert solve_corollary1_points(C, x).done.all()
    # a stack gets the per-point limit once per point
    d = stack_deadline(TriangulationOptions(budget=sospoly.Budget(time_limit=2.0)), 10)
    assert 19.0 < d.remaining() <= 20.0
    assert stack_deadline(TriangulationOptions(budget=sospoly.Budget(time_limit=None)), 10).end is None


def test_a_single_call_stops_at_its_time_limit():
    cams, tracks = _tracks(3, 1, 2.0, seed=12)
    t = time.perf_counter()
    res = tritools.triangulate(cams, tracks[0], path="sdp", time_limit=1e-6)
    assert time.perf_counter() - t < 5.0
    assert res.status == tritools.Status.TIME_LIMIT and not res.optimal
