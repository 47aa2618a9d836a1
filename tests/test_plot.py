"""tritools.plot / tritools.cli.plot: Figure 3 and the dataset summary.

The figures are inspected through the artists' gids (``region-i``, ``center-i``,
``projection-i``, ``closest-i``, ``residual-i``, ``image-point-i``): what is drawn must be
``Phi(X, P_i)`` (tritools.model.geometry.project) and ``R_i.closest_point`` of it, and the
dashed residuals must reproduce the certified ``gamma_UB`` (paper eq. (6)).
"""
import argparse
import pathlib
import struct
import sys
from collections import Counter

import numpy as np
import pytest

pytest.importorskip("matplotlib", reason="matplotlib (the optional extra 'plot') is not installed")

from matplotlib.colors import to_rgba  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

from tritools import plot as tplot  # noqa: E402
from tritools.cli import plot as plot_cli  # noqa: E402
from tritools.model.geometry import gamma, project  # noqa: E402
from tritools.model.regions import Ellipse, EllipseBorder, Point, Polytope, Segment  # noqa: E402
from tritools.result import TriangulationResult  # noqa: E402
from tritools.scene import paper_example  # noqa: E402
from tritools.solve.triangulate import triangulate  # noqa: E402

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Plotted coordinates are the very floats computed by project/closest_point (matplotlib stores them
# unchanged), so they must agree to rounding; 1e-12 absolute on O(1) image coordinates.
COORD_ATOL = 1e-12
# Points on a drawn ellipse satisfy (y-c)' D^-1 (y-c) = 1 up to the rounding of cos/sin and the
# Cholesky factor (~1e-15); 1e-9 leaves six decades of margin.
LEVEL_ATOL = 1e-9


@pytest.fixture(scope="module")
def solved():
    """One certified solve per paper example (Theorem 1, delta = 4, as the paper's Figure 3),
    computed on first use and shared by every test of this module."""
    cache = {}

    def get(k):
        if k not in cache:
            cams, regions = paper_example(k)
            cache[k] = (cams, regions, triangulate(cams, regions, "theorem1", delta=4))
        return cache[k]

    return get


def by_gid(fig, gid):
    found = fig.findobj(lambda a: a.get_gid() == gid)
    assert len(found) == 1, f"expected one artist with gid {gid!r}, found {len(found)}"
    return found[0]


def has_gid(fig, gid):
    return bool(fig.findobj(lambda a: a.get_gid() == gid))


def xy(line: Line2D) -> np.ndarray:
    return np.column_stack([line.get_xdata(), line.get_ydata()]).astype(float)


def view_colours(fig, i):
    """The colour of each element of view i, read from the artist's own drawing colour."""
    region = by_gid(fig, f"region-{i}")
    cols = {"region": region.get_edgecolor() if isinstance(region, Patch) else region.get_color(),
            "center": by_gid(fig, f"center-{i}").get_color()}
    if has_gid(fig, f"projection-{i}"):
        cols["projection"] = by_gid(fig, f"projection-{i}").get_markerfacecolor()
        cols["closest"] = by_gid(fig, f"closest-{i}").get_markeredgecolor()
        cols["residual"] = by_gid(fig, f"residual-{i}").get_color()
    return {k: to_rgba(v)[:3] for k, v in cols.items()}


def check_figure(fig, cams, regions, result):
    """Every view: one colour for all its elements, distinct colours across views, the drawn
    projection = project(X, P_i), the drawn closest point = R_i.closest_point(projection), and
    the residual lengths reproduce gamma_UB."""
    N = len(cams)
    colours = []
    d2 = 0.0
    for i, (P, R) in enumerate(zip(cams, regions)):
        cols = view_colours(fig, i)
        assert len(set(cols.values())) == 1, f"view {i} mixes colours: {cols}"
        colours.append(next(iter(cols.values())))
        np.testing.assert_allclose(xy(by_gid(fig, f"center-{i}"))[0], R.center, atol=COORD_ATOL)
        x = project(result.X, P)
        q = R.closest_point(x)
        np.testing.assert_allclose(xy(by_gid(fig, f"projection-{i}"))[0], x, atol=COORD_ATOL)
        np.testing.assert_allclose(xy(by_gid(fig, f"closest-{i}"))[0], q, atol=COORD_ATOL)
        np.testing.assert_allclose(xy(by_gid(fig, f"residual-{i}")), [x, q], atol=COORD_ATOL)
        d2 += float(np.sum((x - q) ** 2))
    assert len(set(colours)) == N, "views must have distinct colours"
    # gamma_UB = sqrt(sum_i d(x_i*, R_i)^2 / (2N)) (eq. (6)) from the drawn segments; both sides use
    # exact distances, so they agree to rounding (1e-9 relative).
    assert np.sqrt(d2 / (2 * N)) == pytest.approx(result.gamma_ub, rel=1e-9, abs=1e-12)
    return colours


def check_region_geometry(fig, i, R):
    art = by_gid(fig, f"region-{i}")
    if isinstance(R, Point):
        np.testing.assert_allclose(xy(art), [R.x], atol=COORD_ATOL)
    elif isinstance(R, Segment):
        np.testing.assert_allclose(xy(art), list(R.endpoints), atol=COORD_ATOL)
    elif isinstance(R, Polytope):
        V = art.get_xy()
        V = V[:-1] if np.allclose(V[0], V[-1]) else V          # matplotlib closes the path
        np.testing.assert_allclose(V, R.vertices, atol=COORD_ATOL)
        assert 0 < art.get_facecolor()[3] < 1, "polytope must be a translucent filled patch"
    elif isinstance(R, EllipseBorder):
        pts = art.get_xy() if isinstance(art, Patch) else xy(art)
        np.testing.assert_allclose(R.level(pts), 1.0, atol=LEVEL_ATOL)
        ang = np.arctan2(*(pts - R.center).T[::-1])
        assert np.ptp(ang) > 6.2, "the whole ellipse must be drawn"
        if isinstance(R, Ellipse):
            assert isinstance(art, Patch) and 0 < art.get_facecolor()[3] < 1
        else:
            assert isinstance(art, Line2D), "an ellipse border is a curve, not a filled patch"


# ----------------------------------------------------------------------------- paper examples
@pytest.mark.parametrize("k", [2, 3, 4])
def test_figure3_paper_example(solved, k):
    cams, regions, res = solved(k)
    assert res.optimal, f"Example {k} must be certified at Theorem 1, delta = 4 (paper Tables 8-10)"
    fig = tplot.figure3(cams, regions, res, title=f"Example {k}")
    colours = check_figure(fig, cams, regions, res)
    for i, R in enumerate(regions):
        check_region_geometry(fig, i, R)
    # the paper's colours: view 1 red, 2 green, 3 blue, 4 violet
    r, g, b = colours[0]
    assert r > g and r > b
    r, g, b = colours[1]
    assert g > r and g > b
    r, g, b = colours[2]
    assert b > r and b > g
    if len(colours) > 3:
        r, g, b = colours[3]
        assert r > g and b > g
    ax = fig.axes[0]
    assert ax.get_aspect() == 1.0
    title = ax.get_title()
    assert f"Example {k}" in title and "certified optimal: yes" in title
    assert f"{res.gamma_lb:.6g}" in title and f"{res.gamma_ub:.6g}" in title
    assert len(ax.get_legend().get_texts()) >= 5                 # the marker legend
    # x_i* read from v* coincide with Phi(X, P_i) here: no extra markers
    assert not any(has_gid(fig, f"image-point-{i}") for i in range(len(cams)))


def png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path} is not a PNG"
    assert data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def test_save_figure3_examples_writes_pngs(solved, tmp_path):
    import matplotlib.image as mpimg

    results = {k: solved(k)[2] for k in (2, 3, 4)}
    paths = tplot.save_figure3_examples(tmp_path / "figs", results=results)
    assert [p.name for p in paths] == [f"figure3_example{k}.png" for k in (2, 3, 4)]
    for k, p in zip((2, 3, 4), paths):
        w, h = png_size(p)
        assert 600 <= w <= 4000 and 400 <= h <= 4000, (w, h)
        img = mpimg.imread(p)[..., :3]
        # every view's colour is present in the picture (within 0.1 per channel of antialiasing)
        for i in range(len(paper_example(k)[0])):
            c = np.array(to_rgba(tplot.view_color(i))[:3])
            assert np.any(np.all(np.abs(img - c) < 0.1, axis=-1)), f"example {k}: no pixel of view {i}'s colour"


def test_save_figure3_examples_rejects_other_examples(tmp_path):
    with pytest.raises(ValueError, match="Examples 2, 3 and 4"):
        tplot.save_figure3_examples(tmp_path, examples=(1,))


# ----------------------------------------------------------------------------- all region types
@pytest.fixture(scope="module")
def mixed_problem():
    cams, _ = paper_example(4)
    X = np.array([-0.9, -0.04, 0.9])
    x = np.array([project(X, P) for P in cams])
    regions = [
        Polytope.box(x[0] + [0.3, 0.1], [0.1, 0.2]),                       # projection outside
        Ellipse(x[1] + [0.05, 0.0], [[0.04, 0.01], [0.01, 0.02]]),         # projection inside
        Segment(x[2] + [0.0, 0.3], [0.2, -0.1]),
        EllipseBorder(x[3] + [-0.2, 0.1], [[0.02, -0.005], [-0.005, 0.01]]),
    ]
    res = TriangulationResult("manual", "no_certificate", X=X, gamma_ub=gamma(X, cams, regions))
    return cams, regions, res


def test_figure3_every_region_type(mixed_problem):
    cams, regions, res = mixed_problem
    fig = tplot.figure3(cams, regions, res)
    check_figure(fig, cams, regions, res)
    for i, R in enumerate(regions):
        check_region_geometry(fig, i, R)
    # inside the filled ellipse the closest point is the projection itself
    np.testing.assert_allclose(xy(by_gid(fig, "closest-1")), xy(by_gid(fig, "projection-1")), atol=COORD_ATOL)
    assert "no certificate" in fig.axes[0].get_title()


def test_figure3_marks_image_points_that_differ(mixed_problem):
    cams, regions, res = mixed_problem
    x = np.array([project(res.X, P) for P in cams])
    moved = x.copy()
    moved[2] += [0.1, -0.05]                # far above IMAGE_POINT_MISMATCH_REL of the plotted extent
    fig = tplot.figure3(cams, regions, TriangulationResult("m", "no_certificate", X=res.X, image_points=moved))
    np.testing.assert_allclose(xy(by_gid(fig, "image-point-2")), [moved[2]], atol=COORD_ATOL)
    assert [has_gid(fig, f"image-point-{i}") for i in range(4)] == [False, False, True, False]
    fig = tplot.figure3(cams, regions, TriangulationResult("m", "no_certificate", X=res.X, image_points=x))
    assert not any(has_gid(fig, f"image-point-{i}") for i in range(4))


def test_figure3_without_estimate_draws_regions_only(mixed_problem):
    cams, regions, _ = mixed_problem
    res = TriangulationResult("theorem1", "solver_failed", message="boom")
    fig = tplot.figure3(cams, regions, res)
    for i in range(4):
        assert has_gid(fig, f"region-{i}") and has_gid(fig, f"center-{i}")
        assert not has_gid(fig, f"projection-{i}") and not has_gid(fig, f"closest-{i}")
    assert "NA" in fig.axes[0].get_title()


def test_figure3_into_given_axes(mixed_problem):
    from matplotlib.figure import Figure

    cams, regions, res = mixed_problem
    fig = Figure()
    ax1, ax2 = fig.subplots(1, 2)
    assert tplot.figure3(cams, regions, res, ax=ax2) is fig
    assert not ax1.lines and ax2.lines


def test_figure3_bad_input(mixed_problem):
    cams, regions, res = mixed_problem
    with pytest.raises(ValueError, match="one region per view"):
        tplot.figure3(cams, regions[:3], res)
    with pytest.raises(TypeError, match="TriangulationResult"):
        tplot.figure3(cams, regions, {"X": [0, 0, 1]})
    with pytest.raises(ValueError, match="image_points"):
        tplot.figure3(cams, regions, TriangulationResult("m", "no_certificate", X=res.X, image_points=np.zeros((3, 2))))
    with pytest.raises(ValueError, match="cameras"):
        tplot.figure3(cams[:, :2], regions, res)
    with pytest.raises(TypeError, match="no drawing rule for region type object"):
        tplot.draw_region(object(), None, "k", "x")


def test_missing_matplotlib_names_the_extra(monkeypatch, mixed_problem):
    cams, regions, res = mixed_problem
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    with pytest.raises(ImportError, match="'plot'"):
        tplot.figure3(cams, regions, res)
    with pytest.raises(ImportError, match="'plot'"):
        tplot.dataset_summary([], [])


# ----------------------------------------------------------------------------- dataset summary
def fake_results():
    """Results with known categories: (N, status, optimal, gamma_ub)."""
    rows = [(2, "optimal", True, 0.01), (2, "optimal", True, 0.5), (2, "not_certified", False, 2.0),
            (3, "optimal", True, 0.02), (3, "solver_failed", None, None), (5, "not_certified", False, 30.0),
            (5, "optimal", True, 0.003)]
    res = [TriangulationResult("corollary1", s, X=None if g is None else [0.0, 0.0, 1.0], gamma_ub=g,
                               gamma_lb=g, optimal=o) for _, s, o, g in rows]
    return res, [n for n, *_ in rows], rows


def test_dataset_summary_counts():
    res, nv, rows = fake_results()
    fig = tplot.dataset_summary(res, nv, title="fake")
    ax_h, ax_b = fig.axes
    hist = fig.findobj(lambda a: a.get_gid() == "gamma-hist")
    assert sum(p.get_height() for p in hist) == 6                  # the six finite gamma_UB
    assert ax_h.get_xscale() == "log"                              # 0.003 .. 30 spans 4 decades
    expected = {"bar-certified": Counter(n for n, s, *_ in rows if s == "optimal"),
                "bar-not-certified": Counter(n for n, s, *_ in rows if s == "not_certified"),
                "bar-failed": Counter(n for n, s, *_ in rows if s == "solver_failed")}
    ticks = [int(t.get_text()) for t in ax_b.get_xticklabels()]
    assert ticks == [2, 3, 5]
    for gid, counts in expected.items():
        bars = fig.findobj(lambda a, gid=gid: a.get_gid() == gid)
        assert [b.get_height() for b in bars] == [counts.get(n, 0) for n in ticks], gid
    assert "certified: 4 of 7" in ax_b.get_title()


def test_dataset_summary_linear_axis_and_no_failures():
    res = [TriangulationResult("c", "optimal", X=[0, 0, 1], gamma_ub=g, gamma_lb=g, optimal=True)
           for g in (0.2, 0.3, 0.5)]
    fig = tplot.dataset_summary(res, [2, 2, 3])
    assert fig.axes[0].get_xscale() == "linear"
    assert not fig.findobj(lambda a: a.get_gid() == "bar-failed")


def test_dataset_summary_bad_input():
    res, nv, _ = fake_results()
    with pytest.raises(ValueError, match="one entry per result"):
        tplot.dataset_summary(res, nv[:-1])
    with pytest.raises(ValueError, match="positive integers"):
        tplot.dataset_summary(res, [2.5] + nv[1:])
    with pytest.raises(TypeError, match=r"results\[0\]"):
        tplot.dataset_summary([{"gamma_ub": 1}], [2])


# ----------------------------------------------------------------------------- command line
def run_cli(argv):
    ap = argparse.ArgumentParser(prog="tritools")
    plot_cli.register(ap.add_subparsers(dest="command", required=True))
    args = ap.parse_args(argv)
    return args.func(args)


def test_cli_figure3_one_command(solved, tmp_path, capsys, monkeypatch):
    # The handler solves with the paper's setting (Theorem 1, delta = 4); the solve itself is the
    # shared certified one, so the test checks the command's wiring without a second SDP.
    ttri = sys.modules["tritools.solve.triangulate"]      # the package re-exports a function of the same name
    calls = []

    def cached(cams, regions, method, delta=None, **kw):
        calls.append((method, delta))
        k = next(k for k in (2, 3, 4) if np.array_equal(paper_example(k)[0], cams))
        return solved(k)[2]

    monkeypatch.setattr(ttri, "triangulate", cached)
    out = tmp_path / "figures"
    assert run_cli(["figure3", "--out", str(out), "--examples", "2", "4"]) == 0
    assert calls == [("theorem1", 4), ("theorem1", 4)]
    printed = capsys.readouterr().out.split()
    assert printed == [str(out / "figure3_example2.png"), str(out / "figure3_example4.png")]
    for p in printed:
        png_size(pathlib.Path(p))
    assert not (out / "figure3_example3.png").exists()
    with pytest.raises(SystemExit):
        run_cli(["figure3", "--examples", "1"])                  # argparse: invalid choice


def test_cli_plot_dataset(oxford_data, tmp_path, capsys):
    root = oxford_data
    out = tmp_path / "library.png"
    assert run_cli(["plot-dataset", "library", "--data-dir", str(root), "--limit", "6", "--out", str(out)]) == 0
    png_size(out)
    assert "/6 certified" in capsys.readouterr().out
    assert run_cli(["plot-dataset", "nosuch", "--data-dir", str(root)]) == 2
    assert "not found" in capsys.readouterr().err
    assert run_cli(["plot-dataset", "library", "--data-dir", str(root), "--limit", "-1"]) == 2


def test_cli_registers_the_plot_commands():
    cli = pytest.importorskip("tritools.cli.app", reason="tritools.cli.app (the CLI helper's module) not present")
    assert "tritools.cli.plot" in cli.SUBCOMMAND_MODULES
    choices = next(a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert {"figure3", "plot-dataset"} <= set(choices)
