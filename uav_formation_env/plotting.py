"""Figures of episodes (matplotlib, Agg; no pyplot state): trajectories, and the paper's Figs. 5-9.

Every function takes plain arrays (nothing of the simulator), draws on a fresh
:class:`matplotlib.figure.Figure` with an Agg canvas, writes a PNG if ``path`` is given and
returns the figure. Variants are given as ``{label: array}`` mappings, drawn in insertion order.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.gridspec import SubplotSpec
from matplotlib.patches import Circle, Rectangle

from uav_formation_env.config import Scenario

DPI = 120
VARIANT_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")
ZOOM_REACH = 2.0  # an obstacle's zoom panel spans +-ZOOM_REACH detection radii around its centre
ZOOM_LABEL = "zoom O{}"  # Axes.get_label() of the zoom panel of obstacle O{1, 2, ...}


def _figure(rows: int = 1, cols: int = 1, size: tuple[float, float] = (7, 6), **kwargs):
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False, **kwargs)
    return fig, axes


def _save(fig: Figure, path: str | Path | None) -> Figure:
    if fig.get_layout_engine() is None:
        fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=DPI)
    return fig


def draw_obstacles(ax: Axes, scenario: Scenario) -> None:
    """Obstacles (filled) and their safety circles (dashed) on a top-view axis."""
    avoidance = scenario.avoidance
    for obstacle in avoidance.obstacles:
        ax.add_patch(Circle(obstacle.center, obstacle.radius, color="0.35", alpha=0.8))
        ax.add_patch(
            Circle(
                obstacle.center,
                avoidance.safety_radius(obstacle),
                fill=False,
                linestyle="--",
                color="0.35",
            )
        )


def _uav_color(i: int) -> str:
    return f"C{i % 10}"


def _draw_paths(ax: Axes, positions: np.ndarray, scenario: Scenario, legend: bool = True) -> None:
    draw_obstacles(ax, scenario)
    for i in range(positions.shape[1]):
        ax.plot(
            positions[:, i, 0], positions[:, i, 1], lw=1.0, color=_uav_color(i), label=f"UAV{i + 1}"
        )
        ax.plot(positions[0, i, 0], positions[0, i, 1], "o", ms=3, color="k")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(loc="best", fontsize=7)


def detection_radius(scenario: Scenario, index: int) -> float:
    """d^o of obstacle ``index``: the distance from its centre at which avoidance starts [m]."""
    obstacle = scenario.avoidance.obstacles[index]
    return obstacle.radius + scenario.avoidance.detection_margin


def zoom_half_width(scenario: Scenario, index: int) -> float:
    """Half the side of obstacle ``index``'s zoom window: :data:`ZOOM_REACH` x d^o [m]."""
    return ZOOM_REACH * detection_radius(scenario, index)


def draw_obstacle_zoom(ax: Axes, positions: np.ndarray, scenario: Scenario, index: int) -> None:
    """Zoom panel of one obstacle: the paths within :func:`zoom_half_width` of its centre.

    Draws the obstacle disc, its safety circle R_s (dashed) and its detection circle d^o
    (dotted), every UAV's path in the colours of the main panel, and in the title the closest
    approach of any UAV to the centre (``closest``). The axis gets the label
    ``ZOOM_LABEL.format(index + 1)``.

    Args:
        ax: the panel.
        positions: (T, N, 3) positions [m].
        scenario: for the obstacles and the margins.
        index: obstacle index (0-based).
    """
    avoidance = scenario.avoidance
    obstacle = avoidance.obstacles[index]
    cx, cy = obstacle.center
    half = zoom_half_width(scenario, index)
    draw_obstacles(ax, scenario)
    ax.add_patch(
        Circle(
            obstacle.center,
            detection_radius(scenario, index),
            fill=False,
            linestyle=":",
            lw=0.8,
            color="0.55",
        )
    )
    for i in range(positions.shape[1]):
        ax.plot(positions[:, i, 0], positions[:, i, 1], lw=1.0, color=_uav_color(i))
    title = f"O{index + 1} zoom (±{half:g} m)"
    distance = np.hypot(positions[..., 0] - cx, positions[..., 1] - cy)
    if np.isfinite(distance).any():
        closest, r_safe = np.nanmin(distance), avoidance.safety_radius(obstacle)
        title += f"\nclosest {closest:.1f} m, R_s {r_safe:g} m"
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy - half, cy + half)
    ax.set_aspect("equal")
    ax.tick_params(labelsize=6.5)
    ax.grid(alpha=0.3)
    ax.set_title(title, fontsize=7.5)
    ax.set_label(ZOOM_LABEL.format(index + 1))


def _mark_zoom_windows(ax: Axes, scenario: Scenario) -> None:
    """Outline each obstacle's zoom window on the main panel, named O1, O2, ..."""
    for o, obstacle in enumerate(scenario.avoidance.obstacles):
        half = zoom_half_width(scenario, o)
        cx, cy = obstacle.center
        ax.add_patch(
            Rectangle((cx - half, cy - half), 2 * half, 2 * half, fill=False, lw=0.6, color="0.6")
        )
        ax.text(cx - half, cy + half, f" O{o + 1}", fontsize=7, color="0.4", va="bottom")


def zoom_axes(fig: Figure) -> list[Axes]:
    """The obstacle zoom panels of a figure (axes labelled like :data:`ZOOM_LABEL`)."""
    prefix = ZOOM_LABEL.split("{")[0]
    return [ax for ax in fig.axes if ax.get_label().startswith(prefix)]


ZOOMS_PER_ROW = 3  # zoom panels per row under a main panel (4 from 4 obstacles on)


def _zoom_grid(n_obstacles: int) -> tuple[int, int]:
    """(rows, slots per row) of the zoom panels under a main panel."""
    if n_obstacles == 0:
        return 0, 0
    cols = ZOOMS_PER_ROW if n_obstacles <= ZOOMS_PER_ROW else ZOOMS_PER_ROW + 1
    return int(np.ceil(n_obstacles / cols)), cols


def _trajectory_cell(
    fig: Figure,
    spec: SubplotSpec,
    positions: np.ndarray,
    scenario: Scenario,
    title: str,
    legend: bool,
    zoom: bool,
    main_height: float,
    zoom_height: float,
) -> Axes:
    """A main top-view panel and, with ``zoom``, one zoom panel per obstacle under it.

    The zoom panels fill rows of :func:`_zoom_grid` slots; a row with fewer panels is centred.
    """
    n_obs = len(scenario.avoidance.obstacles) if zoom else 0
    zoom_rows, slots = _zoom_grid(n_obs)
    cell = spec.subgridspec(
        1 + zoom_rows, 1, height_ratios=[main_height] + [zoom_height] * zoom_rows
    )
    ax = fig.add_subplot(cell[0, 0])
    _draw_paths(ax, positions, scenario, legend=legend)
    if n_obs:
        _mark_zoom_windows(ax, scenario)
    ax.set_title(title)
    for row in range(zoom_rows):
        first = row * slots
        count = min(slots, n_obs - first)
        pad = (slots - count) / 2.0  # empty slots, half each side
        ratios = ([pad] if pad else []) + [1.0] * count + ([pad] if pad else [])
        line = cell[1 + row, 0].subgridspec(1, len(ratios), width_ratios=ratios)
        for k in range(count):
            zoom_ax = fig.add_subplot(line[0, k + (1 if pad else 0)])
            draw_obstacle_zoom(zoom_ax, positions, scenario, first + k)
    return ax


def _main_height(
    positions: Sequence[np.ndarray], scenario: Scenario, width: float, zoom: bool
) -> float:
    """Height [in] of a main top-view panel ``width`` inches wide that fits the drawn extent
    (paths, obstacles, zoom windows) at equal aspect, with room for the title and labels."""
    xy = [p[..., :2].reshape(-1, 2) for p in positions]
    for o, obstacle in enumerate(scenario.avoidance.obstacles):
        reach = zoom_half_width(scenario, o) if zoom else scenario.avoidance.safety_radius(obstacle)
        xy.append(np.asarray(obstacle.center) + reach * np.array([[-1.0, -1.0], [1.0, 1.0]]))
    xy = np.concatenate(xy)
    xy = xy[np.isfinite(xy).all(axis=1)]
    if len(xy) == 0:
        return 5.0
    dx, dy = np.ptp(xy, axis=0)
    aspect = dy / dx if dx > 0 else 1.0
    return float(np.clip((width - 1.0) * aspect * 1.1 + 1.1, 2.5, 7.0))


def plot_trajectories(
    positions: np.ndarray,
    scenario: Scenario,
    path: str | Path | None = None,
    title: str = "",
    zoom: bool = False,
) -> Figure:
    """Top view of every UAV's path.

    Args:
        positions: (T, N, 3) positions over an episode [m].
        scenario: for the obstacles.
        path: write a PNG there if given.
        title: axis title.
        zoom: add one zoom panel per obstacle under the main panel (:func:`draw_obstacle_zoom`).
    """
    if not zoom:
        fig, axes = _figure()
        ax = axes[0, 0]
        _draw_paths(ax, positions, scenario)
        ax.set_title(title)
        return _save(fig, path)
    zoom_rows, slots = _zoom_grid(len(scenario.avoidance.obstacles))
    width = 7.0
    main_height = _main_height([positions], scenario, width, True)
    zoom_height = width / max(slots, 1)
    fig = Figure(figsize=(width, main_height + zoom_rows * zoom_height), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(1, 1)
    _trajectory_cell(
        fig, grid[0, 0], positions, scenario, title, True, True, main_height, zoom_height
    )
    return _save(fig, path)


def plot_variant_trajectories(
    positions: Mapping[str, np.ndarray],
    scenario: Scenario,
    path: str | Path | None = None,
    suptitle: str = "",
    zoom: bool = True,
) -> Figure:
    """Fig. 5: top view of the paths of each variant, one cell per variant (2 columns).

    With ``zoom`` each cell holds, under the variant's main panel, one zoom panel per obstacle
    (:func:`draw_obstacle_zoom`: ±:data:`ZOOM_REACH` detection radii around the centre, with the
    obstacle and its safety circle), :data:`ZOOMS_PER_ROW` per row (one more from 4 obstacles
    on); each zoom window is outlined on the main panel. No zoom panel without obstacles.
    :func:`zoom_axes` finds them.

    Args:
        positions: label -> (T, N, 3) positions [m].
        scenario: for the obstacles.
        path: PNG path.
        suptitle: figure title.
        zoom: draw the zoom panels.
    """
    labels = list(positions)
    cols = 2 if len(labels) > 1 else 1
    rows = int(np.ceil(len(labels) / cols))
    zoom_rows, slots = _zoom_grid(len(scenario.avoidance.obstacles) if zoom else 0)
    width = 6.5
    main_height = _main_height(list(positions.values()), scenario, width, zoom)
    zoom_height = width / slots if slots else 0.0
    height = rows * (main_height + zoom_rows * zoom_height) + (0.4 if suptitle else 0.0)
    fig = Figure(figsize=(width * cols, height), layout="constrained")
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(rows, cols)
    for k, label in enumerate(labels):
        _trajectory_cell(
            fig,
            grid[k // cols, k % cols],
            positions[label],
            scenario,
            f"({chr(ord('a') + k)}) {label}",
            k == 0,
            zoom,
            main_height,
            zoom_height,
        )
    if suptitle:
        fig.suptitle(suptitle)
    return _save(fig, path)


def plot_observer(
    t: np.ndarray,
    estimate: np.ndarray,
    disturbance: np.ndarray,
    path: str | Path | None = None,
    title: str = "",
) -> Figure:
    """Fig. 6: the observer's estimate against the true disturbance, one panel per axis, and a
    fourth panel with the estimation error of every axis.

    Args:
        t: (T,) time [s].
        estimate: (T, 3) estimate [m/s^2].
        disturbance: (T, 3) true disturbance [m/s^2].
        path: PNG path.
        title: figure title.
    """
    fig, axes = _figure(4, 1, size=(8, 9), sharex=True)
    for axis in range(3):
        ax = axes[axis, 0]
        name = "xyz"[axis]
        ax.plot(t, disturbance[:, axis], color="0.2", lw=1.0, label=f"d_{name} (true)")
        ax.plot(t, estimate[:, axis], color="tab:red", lw=1.0, ls="--", label=f"estimate_{name}")
        ax.set_ylabel(f"{name} [m/s²]")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    ax = axes[3, 0]
    for axis in range(3):
        error = estimate[:, axis] - disturbance[:, axis]
        ax.plot(t, error, lw=0.7, color=VARIANT_COLORS[axis], label=f"{'xyz'[axis]}")
    ax.set_ylabel("estimate − d [m/s²]")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=3)
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        axes[0, 0].set_title(title)
    return _save(fig, path)


def plot_velocity_components(
    t: np.ndarray,
    velocities: Mapping[str, np.ndarray],
    reference: np.ndarray,
    path: str | Path | None = None,
    title: str = "",
    components: Sequence[int] = (0, 1),
) -> Figure:
    """Fig. 7: one UAV's velocity components per variant against the reference.

    Args:
        t: (T,) time [s].
        velocities: label -> (T, 3) velocity [m/s].
        reference: (T, 3) reference velocity [m/s].
        path: PNG path.
        title: figure title.
        components: axes to draw, one panel each.
    """
    fig, axes = _figure(len(components), 1, size=(9, 3.3 * len(components)), sharex=True)
    for row, axis in enumerate(components):
        ax = axes[row, 0]
        name = "xyz"[axis]
        ax.plot(t, reference[:, axis], color="k", ls="--", lw=1.2, label="reference")
        for k, (label, v) in enumerate(velocities.items()):
            ax.plot(t, v[:, axis], color=VARIANT_COLORS[k % 6], lw=0.9, label=label)
        ax.set_ylabel(f"v_{name} [m/s]")
        ax.set_title(f"({chr(ord('a') + row)}) velocity along {name.upper()}", fontsize=10)
        ax.grid(alpha=0.3)
        ax.legend(loc="best", fontsize=8, ncol=3)
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_log_cost(
    t: np.ndarray,
    log_cost: Mapping[str, np.ndarray],
    band: Mapping[str, tuple[np.ndarray, np.ndarray]] | None = None,
    markers: Mapping[str, float] | None = None,
    path: str | Path | None = None,
    title: str = "",
    ylabel: str = "log10 of the cost averaged over UAVs [-]",
) -> Figure:
    """Fig. 8: log10 of the mean cost over UAVs against time, per variant.

    Args:
        t: (T,) time [s].
        log_cost: label -> (T,) curve.
        band: label -> (low, high) (T,) arrays shaded around the curve (e.g. min/max over seeds).
        markers: label -> time [s] of a vertical dotted line (events).
        path: PNG path.
        title: axis title; name the quantity of ``ylabel`` in it (Fig. 8 repeats it verbatim).
        ylabel: y label: the plotted quantity and its unit.
    """
    fig, axes = _figure(size=(10, 5))
    ax = axes[0, 0]
    for k, (label, curve) in enumerate(log_cost.items()):
        color = VARIANT_COLORS[k % 6]
        if band is not None and label in band:
            low, high = band[label]
            ax.fill_between(t, low, high, color=color, alpha=0.12, lw=0)
        ax.plot(t, curve, color=color, lw=0.9, label=label)
    for name, when in (markers or {}).items():
        if when is None or not np.isfinite(when):
            continue
        ax.axvline(when, color="0.4", ls=":", lw=1.0)
        ax.annotate(  # above the axes, clear of the curves
            name,
            (when, 1.0),
            xytext=(0, 3),
            textcoords="offset points",
            xycoords=("data", "axes fraction"),
            rotation=90,
            va="bottom",
            ha="center",
            fontsize=7,
            color="0.3",
            annotation_clip=False,
        )
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    # outside the axes, right of them: clear of the curves and of the event labels at the top
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)
    if title:
        ax.set_title(title, pad=70 if markers else 6)  # above the event labels
    return _save(fig, path)


LINE_STYLES = ("-", "--", "-.", ":")


def overlap_style(k: int, n: int) -> dict[str, object]:
    """Line style and width of curve k of n that may lie exactly on one another (e.g. two
    variants triggering at every step): earlier curves wider, each with its own dash, so a
    curve drawn over another leaves it visible at both sides."""
    return {"ls": LINE_STYLES[k % len(LINE_STYLES)], "lw": 1.2 + 1.6 * (n - 1 - k) / max(n - 1, 1)}


def plot_trigger_timeline(
    t: np.ndarray,
    triggered: Mapping[str, np.ndarray],
    cumulative: Mapping[str, np.ndarray] | None = None,
    path: str | Path | None = None,
    title: str = "",
    uav_label: str = "UAV5",
) -> Figure:
    """Fig. 9: when one UAV was triggered, per variant (raster), and its cumulative count.

    Args:
        t: (T,) time of each decision [s].
        triggered: label -> (T,) bool.
        cumulative: label -> (T,) cumulative trigger count (e.g. mean over seeds); a second panel.
        path: PNG path.
        title: figure title.
        uav_label: name of the UAV for the labels.
    """
    rows = 2 if cumulative else 1
    fig, axes = _figure(rows, 1, size=(10, 3.2 * rows + 0.6), sharex=True)
    ax = axes[0, 0]
    labels = list(triggered)
    for k, label in enumerate(labels):
        times = t[np.asarray(triggered[label], dtype=bool)]
        ax.vlines(times, k + 0.6, k + 1.4, color=VARIANT_COLORS[k % 6], lw=0.6)
    ax.set_yticks(np.arange(1, len(labels) + 1), labels, fontsize=8)
    ax.set_ylim(0.4, len(labels) + 0.6)
    ax.invert_yaxis()
    ax.set_title(f"(a) triggered steps of {uav_label}", fontsize=10)
    ax.grid(alpha=0.3, axis="x")
    if cumulative:
        ax2 = axes[1, 0]
        for k, (label, curve) in enumerate(cumulative.items()):
            ax2.plot(
                t,
                curve,
                color=VARIANT_COLORS[k % 6],
                label=f"{label} ({curve[-1]:.0f})",  # equal totals stay told apart
                **overlap_style(k, len(cumulative)),
            )
        ax2.set_ylabel("triggered steps")
        ax2.set_title(f"(b) cumulative triggers of {uav_label}", fontsize=10)
        ax2.grid(alpha=0.3)
        ax2.legend(loc="upper left", fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    return _save(fig, path)


def plot_trigger_raster(
    t: np.ndarray,
    triggered: Mapping[str, np.ndarray],
    path: str | Path | None = None,
    title: str = "",
) -> Figure:
    """Triggered steps of every UAV, one panel per variant.

    Args:
        t: (T,) time of each decision [s].
        triggered: label -> (T, N) bool.
        path: PNG path.
        title: figure title.
    """
    labels = list(triggered)
    fig, axes = _figure(len(labels), 1, size=(10, 1.9 * len(labels) + 0.6), sharex=True)
    for k, label in enumerate(labels):
        ax = axes[k, 0]
        grid = np.asarray(triggered[label], dtype=bool)
        n = grid.shape[1]
        for i in range(n):
            ax.vlines(t[grid[:, i]], i + 0.6, i + 1.4, color=VARIANT_COLORS[k % 6], lw=0.5)
        counts = grid.sum(axis=0)
        ax.set_yticks(
            np.arange(1, n + 1), [f"UAV{i + 1} ({c})" for i, c in enumerate(counts)], fontsize=7
        )
        ax.set_ylim(0.4, n + 0.6)
        ax.invert_yaxis()
        ax.set_title(label, fontsize=9, loc="left")
        ax.grid(alpha=0.3, axis="x")
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    return _save(fig, path)
