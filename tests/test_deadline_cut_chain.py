"""A step whose solver's retry chain the caller's deadline cut short (an attempt stopped at it or not started for
lack of time, an earlier answer kept) is ``time_limit``, not ``not_certified`` (review 34b: a robust search took such a
sub-problem as exhausted and stopped "certification out of reach", depending on the machine's load)."""
from __future__ import annotations

import pytest

import tritools
from sospoly.solvers.backends import Attempt, ConicSolution, RawStatus, cut_by_deadline
from sospoly.solvers.solve import ProgramSolution
from tritools import Status
from tritools.scene import random_scene


def _attempt(status, text=""):
    return Attempt("x", status, text, 3, 0.1)


def test_cut_by_deadline_reads_the_attempts():
    assert not cut_by_deadline([_attempt(RawStatus.FAILED), _attempt(RawStatus.ALMOST_SOLVED)])
    assert cut_by_deadline([_attempt(RawStatus.ALMOST_SOLVED), _attempt(RawStatus.TIME_LIMIT, "not started")])
    sol = ConicSolution(RawStatus.ALMOST_SOLVED, None, None, None, None,
                        (_attempt(RawStatus.ALMOST_SOLVED), _attempt(RawStatus.TIME_LIMIT, "MaxTime")))
    assert sol.stopped_for_time
    assert not ConicSolution(RawStatus.SOLVED, None, None, None, None, (_attempt(RawStatus.SOLVED),)).stopped_for_time


def _uncertified():
    """Corollary 1 at delta = 2 alone does not certify this 3-view point (30 px noise): gamma_lb 12.3 < 19.9."""
    sc = random_scene(3, 1, noise_px=30.0, seed=20)
    return sc.cameras, sc.points2d[0]


@pytest.mark.parametrize("cut", [False, True])
def test_a_chain_cut_by_the_deadline_is_a_time_limit(monkeypatch, cut):
    monkeypatch.setattr(ProgramSolution, "stopped_for_time", property(lambda self: cut))
    cams, x = _uncertified()
    res = tritools.triangulate(cams, x, "corollary1", delta=2, max_delta=2, path="sdp")
    assert not res.optimal and res.gamma_lb < res.gamma_ub
    assert res.status == (Status.TIME_LIMIT if cut else Status.NOT_CERTIFIED)
    assert res.attempts[-1].status == res.status.value
