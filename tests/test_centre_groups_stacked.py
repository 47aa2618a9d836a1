"""The stacked camera-centre grouping (issue #22): :func:`tritools.model.constraints.centre_groups` gives exactly the
labels of the pair-by-pair loop :func:`~tritools.model.constraints.centre_groups_loop` (the rule of
``fundamental_matrix`` per pair, the same union order) on random, duplicated, nearly duplicated, rescaled and
georeferenced cameras, and the labels agree with the centres the cameras were built from where those are clear
(an independent reference); deadlines are honoured and bad cameras raise as before."""
from __future__ import annotations

import time

import numpy as np
import pytest

from sospoly.budget import Deadline, TimeLimitReached, deadline_scope
from tritools.model import centres as cm_centres
from tritools.model import constraints as cm
from tritools.model.centres import merged_labels
from tritools.model.constraints import centre_groups, centre_groups_loop
from tritools.scene import random_scene

from tests.test_centres import _camera, _rotation


def _cameras(rng, N: int, *, offset: float = 0.0, pp: float = 320.0, f: float = 800.0, dup: float = 0.3,
             near: float = 0.2, scales=(-3.0, 6.0)) -> tuple[np.ndarray, list]:
    """(cameras (N, 3, 4), their centres): each centre after the first is, with probabilities ``dup`` and ``near``,
    an earlier one exactly or relatively perturbed by 1e-17..1e-6; every camera is rescaled by 10^U(scales)."""
    cs = [rng.normal(size=3) * 5 + offset]
    for _ in range(1, N):
        u = rng.random()
        if u < dup:
            cs.append(cs[rng.integers(len(cs))].copy())
        elif u < dup + near:
            cs.append(cs[rng.integers(len(cs))] * (1 + 10.0 ** rng.uniform(-17, -6) * rng.normal(size=3)))
        else:
            cs.append(rng.normal(size=3) * 5 + offset)
    C = np.array([_camera(f * rng.uniform(0.5, 2), pp, _rotation(rng), c) for c in cs])
    return C * 10.0 ** rng.uniform(*scales, size=(N, 1, 1)), cs


@pytest.mark.parametrize("offset", [0.0, 1e6, 1e7, 1e8])
@pytest.mark.parametrize("pp", [0.0, 320.0, 1e6])
def test_labels_equal_the_loop(offset, pp):
    """Equal labels (values and dtype) on duplicated / nearly duplicated / rescaled / georeferenced cameras."""
    rng = np.random.default_rng(int(offset) % 997 + int(pp) % 13)
    for N in (2, 3, 4, 6, 10, 17, 30):
        for _ in range(3):
            C, _ = _cameras(rng, N, offset=offset, pp=pp, f=float(rng.choice([1.0, 800.0, 1e5])))
            ref = centre_groups_loop(C)
            got = centre_groups(C)
            assert got.dtype == ref.dtype and np.array_equal(got, ref), (N, ref, got)


def test_labels_equal_the_loop_scene_cameras():
    """The generator's cameras (no coincident centres) and the same with views repeated (N up to 40 + 24)."""
    for N in (2, 5, 12, 40):
        C = np.asarray(random_scene(N, 1, seed=N).cameras, float)
        assert np.array_equal(centre_groups(C), centre_groups_loop(C))
        rep = np.concatenate([C, C[::3] * 3.0, C[1::4]])
        assert np.array_equal(centre_groups(rep), centre_groups_loop(rep))


@pytest.mark.slow
def test_labels_equal_the_loop_200_views(monkeypatch):
    """Many views over many blocks of pairs: 200 views (19,900 pairs; the loop's pair-by-pair rule takes ~20 s) in
    blocks of 2^15 entries (12 blocks of 18 rows; a 400-view track takes 6 of 72 at the default size)."""
    rng = np.random.default_rng(400)
    C, _ = _cameras(rng, 200, dup=0.1, near=0.05)
    monkeypatch.setattr(cm_centres, "PAIR_BLOCK_ENTRIES", 2 ** 15)
    assert np.array_equal(centre_groups(C), centre_groups_loop(C))


@pytest.mark.parametrize("offset", [0.0, 1e3])
def test_labels_match_the_true_centres(offset):
    """Independent of the code: exact duplicates share a label, centres ~5 apart never do (N up to 400)."""
    rng = np.random.default_rng(11)
    for N in (3, 40, 400):
        C, cs = _cameras(rng, N, offset=offset, near=0.0)
        label = centre_groups(C)
        key = [tuple(c) for c in cs]
        for i in range(0, N, max(1, N // 40)):
            for j in range(N):
                assert (label[i] == label[j]) == (key[i] == key[j])


def test_undecided_pairs_take_the_per_pair_rule(monkeypatch):
    """With the round-off band made huge every pair goes to the per-pair rule: still the loop's labels."""
    rng = np.random.default_rng(2)
    C, _ = _cameras(rng, 12, offset=1e6)
    calls = []
    real = cm._same_centre_pair
    monkeypatch.setattr(cm_centres, "PAIR_ROUNDOFF_UNITS", 1e30)
    monkeypatch.setattr(cm, "_same_centre_pair", lambda Pi, Pj: calls.append(1) or real(Pi, Pj))
    assert np.array_equal(centre_groups(C), centre_groups_loop(C))
    assert len(calls) == 2 * 66                 # 66 pairs in each of the two calls


def test_small_blocks(monkeypatch):
    """Rows split into blocks of one (the memory bound): the same labels."""
    rng = np.random.default_rng(3)
    C, _ = _cameras(rng, 25)
    monkeypatch.setattr(cm_centres, "PAIR_BLOCK_ENTRIES", 1)
    assert np.array_equal(centre_groups(C), centre_groups_loop(C))


def test_merge_order_is_the_loops():
    """The union replay moves j's class to i's label pair by pair, as ``label[label == label[j]] = label[i]``."""
    rng = np.random.default_rng(4)
    for _ in range(200):
        N = int(rng.integers(2, 12))
        pairs = [(i, j) for i in range(N) for j in range(i + 1, N) if rng.random() < 0.25]
        ref = np.arange(N)
        for i, j in pairs:
            ref[ref == ref[j]] = ref[i]
        assert np.array_equal(merged_labels(N, pairs), ref)


def test_bad_cameras_raise_as_the_loop():
    C = np.asarray(random_scene(4, 1, seed=1).cameras, float).copy()
    C[2, 2] = C[2, 0] + C[2, 1]                             # rank 2
    with pytest.raises(ValueError) as ref:
        centre_groups_loop(C)
    with pytest.raises(ValueError) as got:
        centre_groups(C)
    assert str(got.value) == str(ref.value)
    assert np.array_equal(centre_groups(C[:1]), [0]) and centre_groups(C[:0]).shape == (0,)


def test_deadline_honoured():
    C = np.asarray(random_scene(50, 1, seed=5).cameras, float)
    with deadline_scope(Deadline.after(0.0)):
        with pytest.raises(TimeLimitReached):
            centre_groups(C[:2])
    t = time.process_time()
    centre_groups(C)
    assert time.process_time() - t < 1.0                  # the loop: ~0.4 s at N = 50, ~26 s at N = 400


def _frame_groups_reference(cameras_f, frame):
    """The pair loop frame_centre_groups replaced (its per-view centres, np.linalg.norm per pair)."""
    from tritools.model.frame import RESOLVED_SPREAD_RTOL, _centres

    label = centre_groups_loop(cameras_f)
    if not frame.moved:
        return label
    tol = RESOLVED_SPREAD_RTOL * float(np.linalg.norm(frame.origin))
    cs = [_centres(cameras_f[i:i + 1]) for i in range(len(cameras_f))]
    for i in range(len(cs)):
        for j in range(i + 1, len(cs)):
            if len(cs[i]) and len(cs[j]) and np.linalg.norm(cs[i][0] - cs[j][0]) <= tol:
                label[label == label[j]] = label[i]
    return label


@pytest.mark.parametrize("offset", [1e6, 1e7, 1e8])
def test_frame_groups_equal_the_loop(offset, monkeypatch):
    """Georeferenced cameras (the frame moves): views whose re-centred centres are within the caller's round-off
    are joined exactly as the pair loop joined them (also in blocks of one row)."""
    from tritools.model import frame as fm

    rng = np.random.default_rng(int(offset) % 89)
    for N in (2, 5, 13, 30):
        C, _ = _cameras(rng, N, offset=offset, dup=0.2, near=0.3)
        fr = fm.world_frame(C)
        Cf = fr.cameras(C)
        assert fr.moved
        ref = _frame_groups_reference(Cf, fr)
        assert np.array_equal(fm.frame_centre_groups(Cf, fr), ref)
        monkeypatch.setattr(fm, "CLOSE_PAIR_BLOCK", 1)
        assert np.array_equal(fm.frame_centre_groups(Cf, fr), ref)
        monkeypatch.undo()


def test_relations_equal_the_pair_loop():
    """centre_relations / untied / loose over the groups' members only: the sets and order of the pair loop."""
    from itertools import combinations

    from tritools.model.centres import group_pairs
    from tritools.model.constraints import _pair_homography, centre_relations
    from tritools.model.exact import same_exact_centre

    rng = np.random.default_rng(9)
    for N in (2, 4, 9, 20):
        C, _ = _cameras(rng, N, dup=0.4, near=0.3)
        C[1:] = np.where(rng.random((N - 1, 1, 1)) < 0.3, C[:-1] * 2.0, C[1:])       # exact scaled copies
        g = centre_groups(C)
        all_pairs = list(combinations(range(N), 2))
        assert group_pairs(g) == [(i, j) for i, j in all_pairs if g[i] == g[j]]
        rel = centre_relations(C)
        ref = frozenset((i, j) for i, j in all_pairs if g[i] == g[j]
                        and _pair_homography(C[i], C[j], check=False) is not None and same_exact_centre(C[i], C[j]))
        assert rel.coincident == ref
        assert rel.untied == tuple((i, j) for i, j in all_pairs if g[i] == g[j] and (i, j) not in ref)
        assert all(type(i) is int and type(j) is int for i, j in rel.untied)
