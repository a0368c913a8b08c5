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
from matplotlib.patches import Circle

from uav_formation_env.config import Scenario

DPI = 120
VARIANT_COLORS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown")


def _figure(rows: int = 1, cols: int = 1, size: tuple[float, float] = (7, 6), **kwargs):
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, cols, squeeze=False, **kwargs)
    return fig, axes


def _save(fig: Figure, path: str | Path | None) -> Figure:
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


def _draw_paths(ax: Axes, positions: np.ndarray, scenario: Scenario, legend: bool = True) -> None:
    draw_obstacles(ax, scenario)
    for i in range(positions.shape[1]):
        ax.plot(positions[:, i, 0], positions[:, i, 1], lw=1.0, label=f"UAV{i + 1}")
        ax.plot(positions[0, i, 0], positions[0, i, 1], "o", ms=3, color="k")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    if legend:
        ax.legend(loc="best", fontsize=7)


def plot_trajectories(
    positions: np.ndarray, scenario: Scenario, path: str | Path | None = None, title: str = ""
) -> Figure:
    """Top view of every UAV's path.

    Args:
        positions: (T, N, 3) positions over an episode [m].
        scenario: for the obstacles.
        path: write a PNG there if given.
        title: axis title.
    """
    fig, axes = _figure()
    ax = axes[0, 0]
    _draw_paths(ax, positions, scenario)
    ax.set_title(title)
    return _save(fig, path)


def plot_variant_trajectories(
    positions: Mapping[str, np.ndarray],
    scenario: Scenario,
    path: str | Path | None = None,
    suptitle: str = "",
) -> Figure:
    """Fig. 5: top view of the paths of each variant, one panel per variant (2 columns).

    Args:
        positions: label -> (T, N, 3) positions [m].
        scenario: for the obstacles.
        path: PNG path.
        suptitle: figure title.
    """
    labels = list(positions)
    cols = 2 if len(labels) > 1 else 1
    rows = int(np.ceil(len(labels) / cols))
    fig, axes = _figure(rows, cols, size=(6.5 * cols, 5.0 * rows))
    for k, ax in enumerate(axes.ravel()):
        if k >= len(labels):
            ax.set_visible(False)
            continue
        _draw_paths(ax, positions[labels[k]], scenario, legend=k == 0)
        ax.set_title(f"({chr(ord('a') + k)}) {labels[k]}")
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
    ylabel: str = "log10 J_mean",
) -> Figure:
    """Fig. 8: log10 of the mean cost over UAVs against time, per variant.

    Args:
        t: (T,) time [s].
        log_cost: label -> (T,) curve.
        band: label -> (low, high) (T,) arrays shaded around the curve (e.g. min/max over seeds).
        markers: label -> time [s] of a vertical dotted line (events).
        path: PNG path.
        title: axis title.
        ylabel: y label.
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
        ax.annotate(
            name,
            (when, 1.0),
            xycoords=("data", "axes fraction"),
            rotation=90,
            va="top",
            ha="right",
            fontsize=7,
            color="0.3",
        )
    ax.set_xlabel("t [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    if title:
        ax.set_title(title)
    return _save(fig, path)


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
            ax2.plot(t, curve, color=VARIANT_COLORS[k % 6], lw=1.2, label=label)
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
