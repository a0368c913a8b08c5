"""Colours, sizes and small drawing helpers of the top-view renderer."""

from __future__ import annotations

from typing import Any

import numpy as np

DPI = 100  # figure resolution: one inch is DPI pixels [px/in]
OBSTACLE_COLOR = "#5f7386"  # obstacle fill and safety-circle colour (opaque, not a pure grey)
BACKGROUND_COLOR = "#ffffff"
COLLISION_COLOR = "#ff0000"
UAV_COLORS = (  # tab10, cycled over UAV indices
    "#1f77b4",
    "#ff7f0e",
    "#2ca02c",
    "#d62728",
    "#9467bd",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#17becf",
)
GROUP_COLORS = ("#1b9e77", "#d95f02", "#7570b3", "#e7298a", "#66a61e", "#e6ab02")  # Dark2

# Axes margins around the plot area [px]: room for the tick labels.
MARGIN_LEFT, MARGIN_BOTTOM, MARGIN_RIGHT, MARGIN_TOP = 44, 24, 8, 8
MIN_SIZE_FOR_TICKS = 200  # below this width or height [px] the axes fill the image, no ticks
MARKER_DIAMETER = 15.0  # UAV marker diameter [px]


def group_edges(adjacency: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """Communication edges drawn by the renderer: inside a group, off the diagonal.

    Args:
        adjacency: (N, N) with ``adjacency[i, j] != 0`` when UAV ``i`` receives from ``j``.
        groups: (N,) integer sub-formation ids.

    Returns:
        (E, 2) int64 array of ``(receiver i, sender j)`` pairs, in row-major order.
    """
    adjacency = np.asarray(adjacency)
    groups = np.asarray(groups)
    same_group = groups[:, None] == groups[None, :]
    mask = (adjacency != 0) & same_group
    np.fill_diagonal(mask, False)
    return np.argwhere(mask).astype(np.int64)


def nice_grid_step(target: float) -> float:
    """Smallest of 1, 2, 5 times a power of ten that is >= ``target`` (> 0)."""
    power = 10.0 ** np.floor(np.log10(target))
    for factor in (1.0, 2.0, 5.0, 10.0):
        if factor * power >= target * (1 - 1e-9):
            return float(factor * power)
    return float(10.0 * power)  # pragma: no cover


def checked_array(value: Any, shape: tuple[int, ...], name: str, dtype: type = float) -> np.ndarray:
    array = np.asarray(value, dtype=dtype)
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {array.shape}")
    return array
