"""Figures of an episode (matplotlib, Agg-safe): top-view trajectories with obstacles."""

from __future__ import annotations

from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from uav_formation_env.config import Scenario


def draw_obstacles(ax: plt.Axes, scenario: Scenario) -> None:
    """Obstacles (filled) and their safety circles (dashed) on a top-view axis."""
    avoidance = scenario.avoidance
    for obstacle in avoidance.obstacles:
        ax.add_patch(plt.Circle(obstacle.center, obstacle.radius, color="0.35", alpha=0.8))
        ax.add_patch(
            plt.Circle(
                obstacle.center,
                avoidance.safety_radius(obstacle),
                fill=False,
                linestyle="--",
                color="0.35",
            )
        )


def plot_trajectories(
    positions: np.ndarray, scenario: Scenario, path: str | Path | None = None, title: str = ""
) -> plt.Figure:
    """Top view of every UAV's path.

    Args:
        positions: (T, N, 3) positions over an episode [m].
        scenario: for the obstacles.
        path: write a PNG there if given.
        title: axis title.
    """
    fig, ax = plt.subplots(figsize=(7, 6))
    draw_obstacles(ax, scenario)
    for i in range(positions.shape[1]):
        ax.plot(positions[:, i, 0], positions[:, i, 1], lw=1.2, label=f"UAV{i + 1}")
        ax.plot(positions[0, i, 0], positions[0, i, 1], "o", ms=3, color="k")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title)
    ax.legend(loc="best", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=120)
    return fig
