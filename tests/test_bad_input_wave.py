"""Bad input on this wave's new public APIs (robust TLS thresholds, array layouts, batches, uncertainty,
the colmap flags, the sospoly modelling layer): each case once broke the contract -- a ValueError /
TypeError naming the argument, a batch that keeps every point, never a silently wrong certificate."""
from __future__ import annotations

import numpy as np
import pytest

import tritools as tt
from tritools import Status


def _scene(n_views=4, noise=0.5, seed=0):
    """n_views cameras on an arc looking at X = (0.1, -0.2, 5); noisy image points (pixels)."""
    rng = np.random.default_rng(seed)
    X = np.array([0.1, -0.2, 5.0, 1.0])
    K = np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]])
    cams = []
    for i in range(n_views):
        a = 0.3 * (i - n_views / 2)
        R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        C = np.array([2.0 * np.sin(a), 0.1 * i, -1.0])
        cams.append(K @ np.hstack([R, (-R @ C)[:, None]]))
    cams = np.array(cams)
    u = np.einsum("nij,j->ni", cams, X)
    x = u[:, :2] / u[:, 2:] + noise * rng.standard_normal((n_views, 2))
    return cams, x


# ----------------------------------------------------------------------------- robust thresholds
@pytest.mark.parametrize("robust", [np.array([True] * 4), np.array(["1"] * 4), [1.0, None, 2.0, 3.0],
                                    np.array([1 + 1j] * 4)], ids=["bool_array", "str_array", "none", "complex"])
def test_robust_thresholds_of_the_wrong_type_are_refused_by_name(robust):
    cams, x = _scene()
    with pytest.raises(ValueError, match="robust"):
        tt.triangulate(cams, x, robust=robust)
    with pytest.raises(ValueError, match="robust"):
        tt.triangulate_points(cams, x[None], robust=robust)


@pytest.mark.parametrize("c", [1e5, 1e10, 1e160, 1e300])
def test_threshold_far_above_the_residuals_is_the_l2_problem(c):
    """Every view is an inlier, so f_TLS* = L2* (the L2 certificate is the independent reference): the TLS
    certificate must not be loosened by the threshold's scale (it once certified gamma_lb = 0 with gamma_ub
    25 % above the optimum for c = 1e5, and raised a numpy reduction error once c^2 overflowed)."""
    cams, x = _scene()
    x[0] += 80                                     # a gross error, still within c
    ref = tt.triangulate(cams, x)
    assert ref.optimal
    r = tt.triangulate(cams, x, robust=c)
    assert r.optimal and r.status == Status.OPTIMAL and r.inliers.all()
    assert r.gamma_lb <= ref.gamma_ub * (1 + 1e-6) and r.gamma_ub <= ref.gamma_ub * (1 + 1e-6)
    assert r.gamma_lb >= ref.gamma_lb * (1 - 1e-6)
    assert np.allclose(r.X, ref.X, rtol=1e-5, atol=1e-6)


def test_robust_batch_keeps_malformed_problems():
    cams, x = _scene()
    bad = np.full((4, 2), np.nan)
    for robust in (None, 2.0):
        res = tt.triangulate_many([(cams, x), ("not a pair", 1), (cams, bad), (cams, x)], robust=robust)
        assert len(res) == 4
        assert [r.status for r in res][1:3] == [Status.INVALID_INPUT, Status.INVALID_INPUT]
        assert res[0].X is not None and res[3].X is not None


# ----------------------------------------------------------------------------- triangulate_points inputs
def test_visible_entry_that_is_not_finite_is_named():
    cams, x = _scene()
    pts = np.stack([x, x + 1.0])
    pts[1, 2] = np.nan
    for robust in (None, 2.0):
        with pytest.raises(ValueError, match=r"points2d\[1, 2\].*visible\[1, 2\]"):
            tt.triangulate_points(cams, pts, visible=np.ones((2, 4), bool), robust=robust)


@pytest.mark.parametrize("visible", [np.full((2, 4), 0.5), np.full((2, 4), np.nan), np.full((2, 4), "y")])
def test_visible_must_be_boolean(visible):
    cams, x = _scene()
    with pytest.raises(ValueError, match="visible"):
        tt.triangulate_points(cams, np.stack([x, x + 1.0]), visible=visible)


def test_ragged_per_view_list_is_named():
    cams, _ = _scene()
    with pytest.raises(ValueError, match="points2d"):
        tt.triangulate_points(cams, [np.ones((2, 2)), np.ones((3, 2)), np.ones((2, 2)), np.ones((2, 2))])


# ----------------------------------------------------------------------------- uncertainty
def _discs(x, r=2.0):
    return [tt.Ellipse(p, np.eye(2) * r * r) for p in x]


def test_dilation_keyword_keeps_the_other_options():
    """``dilation=`` used to rebuild the options and silently drop depth_bounds / widen_roundoff."""
    from tritools.uncertain.api import _options

    o = _options(tt.UncertaintyOptions(depth_bounds=False, widen_roundoff=False), 1.0)
    assert o.dilation == 1.0 and o.depth_bounds is False and o.widen_roundoff is False


@pytest.mark.parametrize("kw, field", [
    (dict(estimate="abc"), "estimate"), (dict(estimate=object()), "estimate"), (dict(estimate=[True] * 3), "estimate"),
    (dict(dilation=True), "dilation"), (dict(dilation=1j), "dilation"), (dict(dilation=object()), "dilation"),
    (dict(dilation=1e300), "dilation"), (dict(level=1e300), "level")])
def test_uncertainty_bad_arguments_are_named(kw, field):
    cams, x = _scene()
    regions = x if "level" in kw else _discs(x)
    with pytest.raises(ValueError, match=field):
        tt.uncertainty(cams, regions, **kw)


@pytest.mark.parametrize("cameras, estimates, field", [
    ((c for c in [0]), None, "cameras"), (5, None, "cameras"), (None, "abc", "estimates")])
def test_uncertainty_many_bad_arguments_are_named(cameras, estimates, field):
    cams, x = _scene()
    with pytest.raises((TypeError, ValueError), match=field):
        tt.uncertainty_many([cams] if cameras is None else cameras, [_discs(x)], estimates=estimates)


@pytest.mark.parametrize("level", [1e-300, 1e-100, 1e-20])
def test_tiny_level_is_a_superset_of_level_zero(level):
    """{gamma <= tau} grows with tau: exact data give the true point at level 0 (round-off widening); a tiny
    positive level once raised (its dilation squared underflowed) or reported the set empty (a dilation below
    the round-off radius replaced the widening)."""
    cams, _ = _scene(noise=0.0)
    X = np.array([0.1, -0.2, 5.0, 1.0])
    u = np.einsum("nij,j->ni", cams, X)
    x = u[:, :2] / u[:, 2:]
    for tau in (0.0, level):
        r = tt.uncertainty(cams, x, level=tau)
        assert r.status == tt.UncertaintyStatus.BOUNDED, (tau, r.status)
        assert np.all(r.lo <= X[:3] + 1e-9) and np.all(X[:3] - 1e-9 <= r.hi), tau
    r = tt.uncertainty(cams, x, dilation=level)
    assert r.status == tt.UncertaintyStatus.BOUNDED


# ----------------------------------------------------------------------------- colmap quality flags
def test_staged_write_into_a_held_stage_does_not_deadlock(tmp_path):
    """``tritools colmap --max-error/--min-angle/--keypoint-radius`` wrote the filtered model into the stage of
    its folder with another staged write: the second flock of the held stage blocked forever."""
    from tritools.io.atomic import staged_directory

    with staged_directory(tmp_path / "out") as stage:
        with staged_directory(stage) as inner:
            (inner / "a.txt").write_text("x")
    assert (tmp_path / "out" / "a.txt").read_text() == "x"


def test_colmap_quality_filter_finishes(tmp_path):
    import subprocess
    import sys

    from tritools.io.colmap import write_model_arrays
    from tritools.sfm.synthetic import synthetic_arrays

    a, _ = synthetic_arrays(n_points=6, n_images=4, camera="PINHOLE", seed=3)
    write_model_arrays(a, tmp_path / "in", "bin")
    p = subprocess.run([sys.executable, "-m", "tritools", "colmap", str(tmp_path / "in"), str(tmp_path / "out"),
                        "--max-error", "0", "--max-delta", "2"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "0 of 6 points kept" in p.stdout


# ----------------------------------------------------------------------------- sospoly: CBF files
def _good_cbf(tmp_path):
    import sospoly as sp

    prog = sp.SOSProgram(("x",))
    a = prog.scalar("a")
    prog.add_inequality(3 - a)
    prog.add_lmi([[a, 1.0], [1.0, a]])
    prog.minimize(a)
    sp.lower(prog).to_cbf(tmp_path / "good.cbf")
    return (tmp_path / "good.cbf").read_text().splitlines()


@pytest.mark.parametrize("section, new_first_token, needle", [
    ("VAR", "99999999999", "VAR count"), ("VAR", "-5", "VAR count"), ("PSDCON", "5", "PSDCON announces"),
    ("CON", "7", "CON announces"), ("OBJACOORD", None, "out of range"), ("ACOORD", None, "out of range"),
    ("BCOORD", None, "out of range"), ("HCOORD", None, "out of range"), ("DCOORD", None, "out of range")])
def test_malformed_cbf_names_file_and_line(tmp_path, section, new_first_token, needle):
    """Corrupt counts and indices once raised IndexError / MemoryError / numpy errors (or were read silently)."""
    import sospoly as sp

    lines = _good_cbf(tmp_path)
    k = lines.index(section) + (1 if new_first_token is not None else 2)   # the header, or the first entry
    toks = lines[k].split()
    toks[0] = new_first_token if new_first_token is not None else "99999"
    lines[k] = " ".join(toks)
    (tmp_path / "bad.cbf").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"bad\.cbf:{k + 1}: .*{needle}"):
        sp.ConicProblem.from_cbf(tmp_path / "bad.cbf")


def test_cbf_short_entry_and_binary_file_are_named(tmp_path):
    import sospoly as sp

    lines = _good_cbf(tmp_path)
    k = lines.index("ACOORD") + 2
    lines[k] = lines[k].split()[0]
    (tmp_path / "bad.cbf").write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"bad\.cbf:{k + 1}: a ACOORD entry has 3 fields"):
        sp.ConicProblem.from_cbf(tmp_path / "bad.cbf")
    (tmp_path / "bin.cbf").write_bytes(b"\x00\xff\xfe")
    with pytest.raises(ValueError, match=r"bin\.cbf: not a text"):
        sp.ConicProblem.from_cbf(tmp_path / "bin.cbf")


# ----------------------------------------------------------------------------- sospoly: modelling arguments
def _prog():
    import sospoly as sp

    prog = sp.SOSProgram(("x", "y"))
    return prog, prog.scalar("a")


@pytest.mark.parametrize("call, needle", [
    (lambda p, a: p.add_inequality("a"), "add_inequality expr"),
    (lambda p, a: p.add_inequality(None), "add_inequality expr"),
    (lambda p, a: p.add_soc(a, 5), "add_soc xs"),
    (lambda p, a: p.add_soc(None, [a]), "add_soc t"),
    (lambda p, a: p.add_lmi([[None, 0.0], [0.0, a]]), r"add_lmi M\[0\]\[0\]"),
    (lambda p, a: p.minimize("a"), "the objective"),
    (lambda p, a: p.add_dsos(object()), "add_dsos expr"),
    (lambda p, a: p.add_sdsos([1.0]), "add_sdsos expr"),
    (lambda p, a: p.add_dsos(1.0 + a, degree="2"), "degree"),
    (lambda p, a: p.add_sos_matrix([[1.0, 0.0], [0.0, 1.0]], degree="2"), "add_sos_matrix degree"),
    (lambda p, a: p.add_sos_matrix([[1.0, 0.0], [0.0, 1.0]], basis=[[1.5, 0]]), "add_sos_matrix basis"),
    (lambda p, a: p.add_sos_matrix([[1.0, 0.0], [0.0, 1.0]], basis=[[-1, 0]]), "add_sos_matrix basis"),
    (lambda p, a: p.add_sos_matrix([[1.0, 0.0], [0.0, 1.0]], basis=[[1, 0, 0]]), "add_sos_matrix basis"),
    (lambda p, a: p.add_sos_matrix([[1.0, 0.0], [0.0, 1.0]], basis=np.zeros((0, 2), int)), "add_sos_matrix basis"),
    (lambda p, a: p.add_sdsos(1.0 + a, basis="abc"), "basis"),
])
def test_modelling_arguments_are_named(call, needle):
    """Once: the bare 'expected a Polynomial or a real number', numpy's reshape / int() messages, a string
    formatting TypeError for degree='2', and float or negative basis exponents silently truncated / kept."""
    prog, a = _prog()
    with pytest.raises((TypeError, ValueError), match=needle):
        call(prog, a)


def test_minimize_ratios_constraints_and_moment_exponents_are_named():
    import sospoly as sp

    x, y = sp.variables("x y")
    with pytest.raises(TypeError, match=r"minimize_ratios eq\[0\]"):
        sp.minimize_ratios([(x**2 + 1, 1.0 + 0 * x)], eq=["x"])
    with pytest.raises(TypeError, match="minimize_ratios ineq"):
        sp.minimize_ratios([(x**2 + 1, 1.0 + 0 * x)], ineq=x)
    (t,) = sp.variables("t")
    res = sp.minimize((t**2 - 1) ** 2, degree=4)
    (mm,) = res.moment_matrices
    assert abs(mm.moment((2,)) - 1) < 1e-4        # interior-point moments
    for bad in ((1.5,), (-1,), "a", (1, 2)):                  # (1.5,) was read as (1,)
        with pytest.raises(ValueError, match="exponent"):
            mm.moment(bad)
    with pytest.raises(TypeError, match="tol"):
        mm.atoms(-1)
    with pytest.raises(ValueError, match="rel_tol"):
        mm.is_flat(float("nan"))


def test_min_angle_above_180_degrees_is_refused():
    from tritools.sfm.quality import QualityOptions

    with pytest.raises(ValueError, match=r"min_angle.*180"):
        QualityOptions(min_angle=200.0)
    assert QualityOptions(min_angle=180.0).min_angle == 180.0


@pytest.mark.parametrize("model", [None, "model", {}, [], 3, np.zeros(3)])
def test_retriangulate_refuses_a_non_model_by_name(model):
    from tritools.sfm import retriangulate

    with pytest.raises(TypeError, match="model must be"):
        retriangulate(model)


@pytest.mark.parametrize("text, needle", [("1\n1\n100000000\n1\n", "at most"), ("1\n1\n0\n1\n", "non-zero"),
                                          ("100000000000\n1\n2\n", r"\[0, ")])
def test_sdpa_sizes_are_bounded(tmp_path, text, needle):
    """A block of side 1e8 once ran for minutes (the svec index pairs of a 1e8 x 1e8 block)."""
    import sospoly as sp

    (tmp_path / "big.dat-s").write_text(text)
    with pytest.raises(ValueError, match=needle):
        sp.ConicProblem.from_sdpa(tmp_path / "big.dat-s")


def test_regions_that_overflow_in_the_normalised_frame_are_a_numerical_failure():
    """Review 21b F2: a disc holding everything (D = 1e308 I) or a box of half-width 1e-300 (B = 1e300 I) is a valid
    region whose program overflows when built: status numerical_failure naming the overflow, never budget_exceeded
    (the memory budget's status); a Theorem 1 program refused for its size is still budget_exceeded.  The box is
    certified through its centre since wave 40."""
    import numpy as np

    import tritools

    cams = np.array([[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 1]], [[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 1]],
                     [[1, 0, 0, 0], [0, 1, 0, 1], [0, 0, 1, 1]]], float)
    regions = [tritools.Point([0.0, 0.0]), tritools.Ellipse([0.5, 0.0], 1e308 * np.eye(2)),
               tritools.Segment([0.0, 0.5], [0.1, 0.0])]
    r = tritools.triangulate(cams, regions)
    assert r.status == tritools.Status.NUMERICAL_FAILURE and "not representable" in r.message, r.message
    assert not r.optimal
    # the box (half-width 1e-300) is certified through its centre since wave 40 (tritools.solve.stages.subproblem):
    # the point problem's optimum, here by multistart least squares with the segment's exact distance
    from scipy.optimize import least_squares

    def residuals(X):
        u = [(P @ np.append(X, 1.0))[:2] / (P @ np.append(X, 1.0))[2] for P in cams]
        t = np.clip((u[2][0] - 0.0) / 0.1, -1.0, 1.0)
        return np.array([np.linalg.norm(u[0]), np.linalg.norm(u[1]), np.linalg.norm(u[2] - [0.1 * t, 0.5])])
    ref = min(2 * least_squares(residuals, X0, xtol=1e-15, ftol=1e-15, gtol=1e-15).cost
              for X0 in np.random.default_rng(0).normal(scale=2.0, size=(20, 3)))
    ref = np.sqrt(ref / 6)
    regions[1] = tritools.Polytope(1e300 * np.eye(2), [0.0, 0.0])
    r = tritools.triangulate(cams, regions)
    assert r.optimal and r.certified_by == "sub_problem" and r.gamma_lb <= ref and abs(r.gamma_ub - ref) < 1e-9
