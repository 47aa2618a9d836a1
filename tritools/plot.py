"""Plots of triangulation results: the paper's Figure 3 and a dataset summary.

Figure 3 of Chesi (2026) shows, for Examples 2-4 and one colour per view ``i``,
the admissible region ``R_i``, the image projection ``x_i* = Phi(X*, P_i)`` of the
estimate (paper eq. (4)) and the closest point of ``R_i`` to ``x_i*`` (the point
realising ``d(x_i*, R_i)`` of paper eq. (7)).  The squared lengths of the dashed
segments ``x_i* -> closest point`` sum to ``2N gamma(X*)^2`` (paper eq. (6)).

matplotlib is an optional dependency (extra ``plot``); it is imported inside the
functions.  Figures are built with :class:`matplotlib.figure.Figure` (no pyplot
state), so they can be created in loops and saved without a display.

Every artist carries a stable ``gid`` (``region-i``, ``center-i``, ``projection-i``,
``closest-i``, ``residual-i``, ``image-point-i``; 0-based view index ``i``) so
that tests and scripts can find them with
``fig.findobj(lambda a: a.get_gid() == "projection-0")``.
"""
from __future__ import annotations

import functools
import os
import sys
from pathlib import Path
from collections.abc import Mapping, Sequence

import numpy as np

from .model.geometry import image_points
from .model.geometry import validate_cameras
from .model.regions import Ellipse, EllipseBorder, Point, Polytope, Region, Segment, as_regions
from .io.atomic import atomic_path, new_folders
from .result import Status, TriangulationResult

__all__ = ["figure3", "draw_region", "require_matplotlib", "dataset_summary", "save_figure3_examples", "view_color",
           "VIEW_COLORS", "IMAGE_POINT_MISMATCH_REL", "ELLIPSE_SAMPLES", "FIGURE3_DPI", "LOG_RANGE_RATIO"]

#: Colours of views 1, 2, 3, 4 as in the paper's Figure 3 (red, green, blue, violet), then more.
VIEW_COLORS = ("#d62728", "#2ca02c", "#1f77b4", "#9467bd", "#ff7f0e", "#8c564b", "#e377c2", "#17becf",
               "#7f7f7f", "#bcbd22")
#: ``result.image_points`` (the ``x_i*`` read from ``v*``) are drawn as well when they differ from
#: ``Phi(X, P_i)`` by more than this fraction of the plotted extent (below it they coincide visually).
IMAGE_POINT_MISMATCH_REL = 2e-3
#: Points on an ellipse outline (enough for a smooth curve at print resolution).
ELLIPSE_SAMPLES = 361
#: Resolution of the saved Figure 3 PNGs.
FIGURE3_DPI = 150

_EXTRA_MSG = ("tritools.plot needs matplotlib, the optional extra 'plot': "
              "pip install 'sospoly-tritools[plot]' (or pip install matplotlib)")


# ----------------------------------------------------------------------------- matplotlib access
def require_matplotlib():
    """Import matplotlib lazily; select the Agg backend when there is no display."""
    try:
        import matplotlib
    except ImportError as exc:
        raise ImportError(_EXTRA_MSG) from exc
    headless = sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                         or os.environ.get("WAYLAND_DISPLAY"))
    if headless and "matplotlib.pyplot" not in sys.modules and not os.environ.get("MPLBACKEND"):
        matplotlib.use("Agg")
    return matplotlib


def _new_figure(figsize):
    require_matplotlib()
    from matplotlib.figure import Figure

    return Figure(figsize=figsize, layout="constrained")


def view_color(i: int) -> str:
    """Colour of view ``i`` (0-based), cycling through :data:`VIEW_COLORS`."""
    return VIEW_COLORS[int(i) % len(VIEW_COLORS)]


# ----------------------------------------------------------------------------- region outlines
def _ellipse_outline(region: EllipseBorder, samples: int = ELLIPSE_SAMPLES) -> np.ndarray:
    """Points ``x^ + L (cos t, sin t)`` with ``L L' = D``: the set ``(y-x^)' D^-1 (y-x^) = 1``."""
    L = np.linalg.cholesky(np.asarray(region.D, dtype=float))
    t = np.linspace(0.0, 2.0 * np.pi, samples)
    return region.center + np.column_stack([np.cos(t), np.sin(t)]) @ L.T


@functools.singledispatch
def draw_region(region: Region, ax, color, gid: str, label: str | None = None):
    """Draw ``region`` on ``ax`` with its true geometry; returns the artist.

    Dispatches on the region type; a new :class:`~tritools.model.regions.Region` subclass
    is supported with ``@draw_region.register``.
    """
    raise TypeError(f"draw_region: no drawing rule for region type {type(region).__name__}; "
                    f"register one with @tritools.plot.draw_region.register")


@draw_region.register
def _(region: Point, ax, color, gid, label=None):
    (line,) = ax.plot([region.x[0]], [region.x[1]], linestyle="none", marker="+", markersize=16,
                      markeredgewidth=2.2, color=color,
                      gid=gid, label=label, zorder=3)
    return line


@draw_region.register
def _(region: Segment, ax, color, gid, label=None):
    a, b = region.endpoints
    (line,) = ax.plot([a[0], b[0]], [a[1], b[1]], linestyle="-", linewidth=2.2, color=color,
                      solid_capstyle="butt", gid=gid, label=label, zorder=2)
    return line


def _filled_polygon(vertices, ax, color, gid, label):
    """A closed polygon with a translucent fill of ``color`` (filled regions)."""
    from matplotlib.patches import Polygon

    patch = Polygon(np.asarray(vertices), closed=True, edgecolor=color, linewidth=1.8, gid=gid, label=label,
                    zorder=1)
    patch.set_facecolor(_translucent(color))
    ax.add_patch(patch)
    return patch


@draw_region.register
def _(region: Polytope, ax, color, gid, label=None):
    return _filled_polygon(region.vertices, ax, color, gid, label)


@draw_region.register
def _(region: EllipseBorder, ax, color, gid, label=None):
    P = _ellipse_outline(region)
    (line,) = ax.plot(P[:, 0], P[:, 1], linestyle="-", linewidth=1.8, color=color, gid=gid, label=label,
                      zorder=2)
    return line


@draw_region.register
def _(region: Ellipse, ax, color, gid, label=None):
    return _filled_polygon(_ellipse_outline(region)[:-1], ax, color, gid, label)


def _translucent(color, alpha: float = 0.18):
    from matplotlib.colors import to_rgba

    r, g, b, _ = to_rgba(color)
    return (r, g, b, alpha)


# ----------------------------------------------------------------------------- Figure 3
def _check_inputs(cameras, regions, result):
    C = validate_cameras(cameras)
    R = as_regions(regions, len(C))
    if not isinstance(result, TriangulationResult):
        raise TypeError(f"result must be a TriangulationResult, got {type(result).__name__}")
    if result.image_points is not None and result.image_points.shape != (len(C), 2):
        raise ValueError(f"result.image_points must have shape ({len(C)}, 2) to match the cameras, "
                         f"got {result.image_points.shape}")
    return C, R


def _fmt(v) -> str:
    return "NA" if v is None else f"{v:.6g}"


def _title(result: TriangulationResult, title: str | None) -> str:
    head = f"{title}\n" if title else ""
    method = result.method + (f", $\\delta$ = {result.delta}" if result.delta is not None else "")
    if result.optimal is None:
        cert = "no certificate"
    else:
        cert = "certified optimal: yes" if result.optimal else "certified optimal: no"
    return (f"{head}{method}: $\\gamma_{{LB}}$ = {_fmt(result.gamma_lb)}, "
            f"$\\gamma_{{UB}}$ = {_fmt(result.gamma_ub)}, {cert}")


def _marker_legend_handles():
    from matplotlib.lines import Line2D

    k = dict(linestyle="none", color="0.25")
    return [
        Line2D([], [], marker="+", markersize=12, markeredgewidth=2, **k, label=r"region $\{\hat x_i\}$ (point)"),
        Line2D([], [], linestyle="-", color="0.25", label="region (segment / ellipse / polytope)"),
        Line2D([], [], marker="x", markersize=6, markeredgewidth=1.3, **k, label="region centre"),
        Line2D([], [], marker="o", markersize=7, **k, label=r"$x_i^* = \Phi(X^*, P_i)$"),
        Line2D([], [], marker="s", markerfacecolor="none", markersize=8, **k, label="closest point of $R_i$"),
        Line2D([], [], linestyle="--", color="0.25", label=r"$d(x_i^*, R_i)$"),
    ]


def figure3(cameras, regions, result: TriangulationResult, ax=None, title: str | None = None):
    """Figure 3 of the paper for one problem: regions, centres, ``x_i*`` and closest points.

    For each view ``i`` (colour :func:`view_color`): the region ``R_i`` with its true
    geometry (:func:`draw_region`), its centre (``x``), the projection
    ``x_i* = Phi(X, P_i)`` of the result's estimate (``o``, paper eq. (4)), the closest
    point ``argmin_{y in R_i} ||x_i* - y||`` (square, paper eq. (7)) and the dashed
    segment between them, whose lengths ``d_i`` satisfy
    ``gamma_UB = sqrt(sum_i d_i^2 / (2N))`` (paper eq. (6)).  When ``result.image_points``
    (the ``x_i*`` read from ``v*``) differ visibly from ``Phi(X, P_i)`` they are drawn too
    (triangles, ``image-point-i``).  Without an estimate (``result.X is None``) only
    the regions and centres are drawn.

    Parameters
    ----------
    cameras : array (N, 3, 4)
    regions : N regions (:class:`~tritools.model.regions.Region`, dicts or 2-vectors)
    result : TriangulationResult
    ax : matplotlib Axes, optional
        Draw into this axes (its figure is returned); default: a new figure.
    title : str, optional
        First title line; the second gives gamma_LB, gamma_UB and the certificate.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ImportError
        matplotlib is missing (install the extra ``plot``).
    ValueError, TypeError
        Bad cameras/regions/result (the message names the argument).
    """
    C, R = _check_inputs(cameras, regions, result)
    if ax is None:
        fig = _new_figure((8.4, 5.6))
        ax = fig.add_subplot()
    else:
        require_matplotlib()
        fig = ax.figure
    proj = None
    if result.X is not None and np.all(np.isfinite(result.X)):
        proj = image_points(result.X, C)
    view_handles = []
    extent_pts = [r.center for r in R]
    for i, region in enumerate(R):
        view_handles.append(_draw_view(ax, i, region, None if proj is None else proj[i], extent_pts))
    marker_handles = _marker_legend_handles()
    if proj is not None and result.image_points is not None:
        marker_handles += _draw_image_points(ax, result.image_points, proj, extent_pts)
    _finish_axes(ax, _title(result, title), view_handles, marker_handles)
    return fig


def _draw_view(ax, i: int, region: Region, x, extent_pts: list):
    """View i of :func:`figure3`: its region and centre and, when its projection ``x`` = x_i* is finite, x_i*,
    the closest point of the region and the residual segment between them (both appended to
    ``extent_pts``).  Returns the region's legend handle."""
    color = view_color(i)
    label = f"view {i + 1}: {region.kind.replace('_', ' ')}"
    handle = draw_region(region, ax, color, f"region-{i}", label=label)
    c = region.center
    ax.plot([c[0]], [c[1]], linestyle="none", marker="x", markersize=6, markeredgewidth=1.3, color=color,
            gid=f"center-{i}", zorder=4)
    if x is None or not np.all(np.isfinite(x)):
        return handle
    q = region.closest_point(x)
    extent_pts += [x, q]
    ax.plot([x[0], q[0]], [x[1], q[1]], linestyle="--", linewidth=1.2, color=color, gid=f"residual-{i}",
            zorder=3)
    ax.plot([x[0]], [x[1]], linestyle="none", marker="o", markersize=7, color=color,
            markeredgecolor="white", markeredgewidth=0.8, gid=f"projection-{i}", zorder=6)
    ax.plot([q[0]], [q[1]], linestyle="none", marker="s", markersize=10, markerfacecolor="none",
            markeredgecolor=color, markeredgewidth=1.6, color=color, gid=f"closest-{i}", zorder=5)
    return handle


def _draw_image_points(ax, points, proj, extent_pts: list) -> list:
    """The x_i* read from v* (``points``) that differ from Phi(X, P_i) (``proj``) by more than
    ``IMAGE_POINT_MISMATCH_REL`` of the drawing's extent (triangles); their legend handle when any is drawn."""
    pts = np.array(extent_pts)
    span = float(np.max(np.ptp(pts, axis=0))) or 1.0
    shown = False
    for i in range(len(proj)):
        v = points[i]
        if np.all(np.isfinite(proj[i])) and np.linalg.norm(v - proj[i]) > IMAGE_POINT_MISMATCH_REL * span:
            ax.plot([v[0]], [v[1]], linestyle="none", marker="^", markersize=7, markerfacecolor="none",
                    markeredgecolor=view_color(i), color=view_color(i), gid=f"image-point-{i}", zorder=6)
            shown = True
    if not shown:
        return []
    from matplotlib.lines import Line2D

    return [Line2D([], [], linestyle="none", marker="^", markerfacecolor="none", color="0.25",
                   label=r"$x_i^*$ read from $v^*$")]


def _finish_axes(ax, title: str, view_handles: list, marker_handles: list) -> None:
    """Equal aspect, grid, labels, the title and the two legends (views, markers) right of the axes."""
    ax.set_aspect("equal", adjustable="datalim")
    ax.autoscale_view()
    ax.margins(0.08)
    ax.grid(True, linewidth=0.4, alpha=0.5)
    ax.set_xlabel("image coordinate 1")
    ax.set_ylabel("image coordinate 2")
    ax.set_title(title, fontsize=10)
    leg_views = ax.legend(handles=view_handles, loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8,
                          title="views", title_fontsize=8, borderaxespad=0.0)
    ax.add_artist(leg_views)
    ax.legend(handles=marker_handles, loc="lower left", bbox_to_anchor=(1.02, 0.0), fontsize=8,
              title="markers", title_fontsize=8, borderaxespad=0.0)


def save_figure3_examples(out_dir, examples: Sequence[int] = (2, 3, 4), *, method: str = "theorem1",
                          delta: int = 4, results: Mapping[int, TriangulationResult] | None = None,
                          dpi: int = FIGURE3_DPI) -> list[Path]:
    """Solve the paper's Examples (2, 3, 4) and write ``figure3_example{k}.png`` into ``out_dir``.

    The default, Theorem 1 with ``delta = 4``, is the setting of the paper's Figure 3
    (all three examples are certified at it).  ``results`` may supply already computed
    results keyed by example number (they are then not solved again).

    Returns
    -------
    list of Path
        The written files, in the order of ``examples``.
    """
    from .scene import paper_example
    from .solve.triangulate import triangulate

    require_matplotlib()
    examples = [int(k) for k in examples]
    for k in examples:
        if k not in (2, 3, 4):
            raise ValueError(f"examples: Figure 3 covers Examples 2, 3 and 4, got {k}")
    out = Path(out_dir)
    results = dict(results or {})
    paths = []
    with new_folders(out):          # a folder created here is removed again if nothing could be written
        for k in examples:
            cams, regions = paper_example(k)
            res = results.get(k)
            if res is None:
                res = triangulate(cams, regions, method, delta=delta)
            fig = figure3(cams, regions, res, title=f"Figure 3 ({'abc'[k - 2]}): Example {k}")
            path = out / f"figure3_example{k}.png"
            with atomic_path(path) as tmp:
                fig.savefig(tmp, dpi=dpi)
            paths.append(path)
    return paths


# ----------------------------------------------------------------------------- dataset summary
#: gamma_UB histograms use a log x-axis when max/min over the positive values exceeds this.
LOG_RANGE_RATIO = 100.0


def _summary_categories(results) -> np.ndarray:
    """0 = certified optimal, 1 = estimate without certificate, 2 = no estimate (failure)."""
    cat = np.empty(len(results), dtype=int)
    for j, r in enumerate(results):
        if r.status == Status.OPTIMAL and r.optimal:
            cat[j] = 0
        elif r.X is not None and r.gamma_ub is not None and np.isfinite(r.gamma_ub):
            cat[j] = 1
        else:
            cat[j] = 2
    return cat


def dataset_summary(results: Sequence[TriangulationResult], n_views: Sequence[int], *, title: str | None = None,
                    bins: int = 30):
    """Summary of a batch: histogram of ``gamma_UB`` and certified counts per number of views N.

    Left: histogram of the finite ``gamma_UB`` values (log-spaced bins and a log x-axis
    when all are positive and span more than :data:`LOG_RANGE_RATIO`).  Right: per N,
    stacked bars of the results that are certified optimal (``gid`` ``bar-certified``),
    not certified (an estimate without certificate, ``bar-not-certified``) and failed
    (no estimate, ``bar-failed``; drawn only if any).

    Parameters
    ----------
    results : sequence of TriangulationResult
    n_views : sequence of int, same length
        Number of views of each problem.
    """
    results = list(results)
    for j, r in enumerate(results):
        if not isinstance(r, TriangulationResult):
            raise TypeError(f"results[{j}] must be a TriangulationResult, got {type(r).__name__}")
    try:
        nv = np.array(list(n_views), dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError("n_views must be a sequence of integers") from exc
    if nv.shape != (len(results),):
        raise ValueError(f"n_views must have one entry per result ({len(results)}), got shape {nv.shape}")
    if not np.all(np.isfinite(nv)) or np.any(nv != np.round(nv)) or np.any(nv < 1):
        raise ValueError("n_views must hold positive integers")
    if int(bins) != bins or bins < 1:
        raise ValueError(f"bins must be a positive integer, got {bins!r}")
    nv = nv.astype(int)
    fig = _new_figure((10.0, 4.2))
    ax_h, ax_b = fig.subplots(1, 2)
    g = np.array([np.nan if r.gamma_ub is None else r.gamma_ub for r in results], dtype=float)
    g = g[np.isfinite(g)]
    if len(g):
        pos = g[g > 0]
        log = len(pos) == len(g) and pos.max() / pos.min() > LOG_RANGE_RATIO
        edges = np.geomspace(pos.min(), pos.max(), int(bins) + 1) if log else int(bins)
        _, _, patches = ax_h.hist(g, bins=edges, color="#1f77b4", edgecolor="white", linewidth=0.5)
        patches_gid = "gamma-hist"
        for p in patches:
            p.set_gid(patches_gid)
        if log:
            ax_h.set_xscale("log")
    else:
        ax_h.text(0.5, 0.5, "no finite $\\gamma_{UB}$", transform=ax_h.transAxes, ha="center", va="center")
    ax_h.set_xlabel(r"$\gamma_{UB}$ (RMS reprojection error)")
    ax_h.set_ylabel("points")
    ax_h.set_title(f"$\\gamma_{{UB}}$ of {len(g)} estimates", fontsize=10)

    cat = _summary_categories(results)
    Ns = np.unique(nv)
    counts = np.array([[np.sum((nv == n) & (cat == c)) for n in Ns] for c in range(3)])
    pos_x = np.arange(len(Ns))
    bottom = np.zeros(len(Ns))
    spec = [(0, "certified", "#2ca02c", "bar-certified"), (1, "not certified", "#ff7f0e", "bar-not-certified"),
            (2, "failed", "#7f7f7f", "bar-failed")]
    for c, label, color, gid in spec:
        if c == 2 and counts[2].sum() == 0:
            continue
        bars = ax_b.bar(pos_x, counts[c], bottom=bottom, color=color, label=label)
        for b in bars:
            b.set_gid(gid)
        bottom += counts[c]
    ax_b.set_xticks(pos_x, [str(n) for n in Ns])
    ax_b.set_ylim(0, max(1.0, float(bottom.max(initial=0.0))) * 1.12)
    ax_b.set_xlabel("number of views N")
    ax_b.set_ylabel("points")
    ax_b.set_title(f"certified: {int(counts[0].sum())} of {len(results)}", fontsize=10)
    if len(results):
        ax_b.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    return fig
