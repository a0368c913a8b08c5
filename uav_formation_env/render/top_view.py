"""The top-view frame renderer (see the package docstring for what a frame shows)."""

from __future__ import annotations

from collections import deque
from typing import TYPE_CHECKING, Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection, PatchCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle

from uav_formation_env.config import Scenario
from uav_formation_env.render.style import (
    BACKGROUND_COLOR,
    COLLISION_COLOR,
    DPI,
    GROUP_COLORS,
    MARGIN_BOTTOM,
    MARGIN_LEFT,
    MARGIN_RIGHT,
    MARGIN_TOP,
    MARKER_DIAMETER,
    MIN_SIZE_FOR_TICKS,
    OBSTACLE_COLOR,
    UAV_COLORS,
    checked_array,
    group_edges,
    nice_grid_step,
)

if TYPE_CHECKING:
    from uav_formation_env.sim import StepResult


class TopViewRenderer:
    """Fast, headless top-view frames of one scenario copy.

    Args:
        scenario: the scenario (obstacles, safety margin, number of UAVs N).
        width: frame width [px].
        height: frame height [px].
        trail_length: positions kept per UAV for its trail (0 draws no trail).
        view_span: extent of the view along the shorter image side [m].
        fit_swarm: widen the view when the swarm (plus a 10 % margin) does not fit in ``view_span``.
        arrow_seconds: a reference-velocity arrow is ``arrow_seconds * |v^d|`` long [s].
        show_ticks: draw matplotlib axes with tick labels (about 1.6x the time per frame;
            ignored below 200 px). Off, the view has a world-fixed grid whose spacing, and the
            view centre, are printed in the corner text.
    """

    def __init__(
        self,
        scenario: Scenario,
        width: int = 640,
        height: int = 640,
        trail_length: int = 100,
        view_span: float = 300.0,
        fit_swarm: bool = True,
        arrow_seconds: float = 2.0,
        show_ticks: bool = False,
    ) -> None:
        if int(width) < 16 or int(height) < 16:
            raise ValueError(f"width and height must be >= 16 px, got {width}x{height}")
        if int(trail_length) < 0:
            raise ValueError(f"trail_length must be >= 0, got {trail_length}")
        if not view_span > 0:
            raise ValueError(f"view_span must be > 0 m, got {view_span}")
        if not arrow_seconds >= 0:
            raise ValueError(f"arrow_seconds must be >= 0 s, got {arrow_seconds}")
        self.scenario = scenario
        self.n_uav = scenario.n_uav
        self.width = int(width)
        self.height = int(height)
        self.trail_length = int(trail_length)
        self.view_span = float(view_span)
        self.fit_swarm = bool(fit_swarm)
        self.arrow_seconds = float(arrow_seconds)
        self.show_ticks = bool(show_ticks) and min(width, height) >= MIN_SIZE_FOR_TICKS
        self._trail: deque[np.ndarray] = deque(maxlen=self.trail_length)
        self._window: Any = None  # (pyplot figure, AxesImage) of show(), created lazily
        self._build_figure()

    # ---------------------------------------------------------------- construction
    def _build_figure(self) -> None:
        n = self.n_uav
        self.figure = Figure(
            figsize=(self.width / DPI, self.height / DPI), dpi=DPI, facecolor=BACKGROUND_COLOR
        )
        self.canvas = FigureCanvasAgg(self.figure)
        if self.show_ticks:
            rect = (
                MARGIN_LEFT / self.width,
                MARGIN_BOTTOM / self.height,
                1.0 - (MARGIN_LEFT + MARGIN_RIGHT) / self.width,
                1.0 - (MARGIN_BOTTOM + MARGIN_TOP) / self.height,
            )
        else:
            rect = (0.0, 0.0, 1.0, 1.0)
        ax = self.figure.add_axes(rect)
        self.axes = ax
        ax.set_facecolor(BACKGROUND_COLOR)
        ax.set_axisbelow(True)  # grid under the obstacles
        if self.show_ticks:
            ax.tick_params(labelsize=7, length=3, pad=2)
            ax.grid(True, color="0.85", linewidth=0.6)
            self._grid = None
        else:
            ax.set_axis_off()  # no ticks, spines or axis background: the figure is the background
            self._grid = LineCollection([], colors="0.88", linewidths=0.6, zorder=0.5)
            ax.add_collection(self._grid)
        self._grid_step = 0.0  # spacing of the own grid [m]
        # Plot-area size [px], for equal data units per pixel on both axes.
        self._axes_px = (rect[2] * self.width, rect[3] * self.height)

        avoidance = self.scenario.avoidance
        obstacles = avoidance.obstacles
        ax.add_collection(
            PatchCollection(
                [Circle(o.center, o.radius) for o in obstacles],
                facecolors=OBSTACLE_COLOR,
                edgecolors="none",
                zorder=1.0,
            )
        )
        ax.add_collection(
            PatchCollection(
                [Circle(o.center, avoidance.safety_radius(o)) for o in obstacles],
                facecolors="none",
                edgecolors=OBSTACLE_COLOR,
                linestyles="--",
                linewidths=1.0,
                zorder=1.1,
            )
        )

        uav_colors = [UAV_COLORS[i % len(UAV_COLORS)] for i in range(n)]
        self._trails = LineCollection([], colors=uav_colors, linewidths=1.0, alpha=0.7, zorder=2)
        ax.add_collection(self._trails)
        self._edges = LineCollection([], linewidths=1.2, alpha=0.8, zorder=3)
        ax.add_collection(self._edges)
        zeros = np.zeros(n)
        self._arrows = ax.quiver(
            zeros,
            zeros,
            zeros,
            zeros,
            angles="xy",
            scale_units="xy",
            scale=1.0,
            units="dots",
            width=1.5,
            headwidth=4,
            headlength=5,
            headaxislength=4.5,
            color="0.15",
            zorder=4,
        )
        marker_area = (MARKER_DIAMETER * 72.0 / DPI) ** 2  # [pt^2]
        self._markers = ax.scatter(
            zeros,
            zeros,
            s=marker_area,
            c=uav_colors,
            edgecolors="black",
            linewidths=0.6,
            zorder=5,
        )
        self._collided = ax.scatter(
            np.zeros(0),
            np.zeros(0),
            s=marker_area * 2.6,
            facecolors="none",
            edgecolors=COLLISION_COLOR,
            linewidths=2.0,
            zorder=6,
        )
        self._labels = [
            ax.text(
                0.0,
                0.0,
                str(i + 1),  # UAV1..UAVN, as every figure and report names them
                ha="center",
                va="center",
                fontsize=6 if i + 1 >= 10 else 7,
                fontweight="bold",
                color="white",
                zorder=7,
                clip_on=True,
            )
            for i in range(n)
        ]
        self._time_text = ax.text(
            0.02,
            0.98,
            "",
            transform=ax.transAxes,
            ha="left",
            va="top",
            fontsize=9,
            zorder=8,
            bbox={"boxstyle": "round,pad=0.25", "facecolor": "white", "alpha": 0.8, "lw": 0},
        )

    # ---------------------------------------------------------------- public API
    def reset(self) -> None:
        """Forget the trails (call at the start of an episode)."""
        self._trail.clear()

    @property
    def trail(self) -> np.ndarray:
        """Positions kept for the trails, oldest first: (L, N, 3) with L <= ``trail_length`` [m]."""
        if not self._trail:
            return np.zeros((0, self.n_uav, 3))
        return np.stack(self._trail)

    def frame(
        self,
        positions: np.ndarray,
        reference_velocity: np.ndarray,
        adjacency: np.ndarray,
        groups: np.ndarray,
        t: float,
        collisions: np.ndarray | None = None,
    ) -> np.ndarray:
        """Draw one frame and append ``positions`` to the trails.

        Args:
            positions: (N, 3) UAV positions [m].
            reference_velocity: (N, 3) reference velocities v^d [m/s].
            adjacency: (N, N) communication graph, ``adjacency[i, j] != 0``: i receives from j.
            groups: (N,) integer sub-formation ids; edges are drawn inside a group only.
            t: time [s].
            collisions: optional (N,) bool, UAVs to highlight as collided.

        Returns:
            (height, width, 3) uint8 RGB image.
        """
        n = self.n_uav
        positions = checked_array(positions, (n, 3), "positions")
        velocity = checked_array(reference_velocity, (n, 3), "reference_velocity")
        adjacency = checked_array(adjacency, (n, n), "adjacency")
        groups = checked_array(groups, (n,), "groups", dtype=np.int64)
        collided = (
            np.zeros(n, dtype=bool)
            if collisions is None
            else checked_array(collisions, (n,), "collisions", dtype=bool)
        )
        if self.trail_length > 0:
            self._trail.append(positions.copy())
        xy = positions[:, :2]

        self._set_view(xy)
        trail = self.trail
        self._trails.set_segments([trail[:, i, :2] for i in range(n)] if len(trail) > 1 else [])

        edges = group_edges(adjacency, groups)
        if len(edges):
            receivers, senders = edges[:, 0], edges[:, 1]
            self._edges.set_segments(np.stack([xy[senders], xy[receivers]], axis=1))
            self._edges.set_colors(
                [GROUP_COLORS[int(g) % len(GROUP_COLORS)] for g in groups[receivers]]
            )
        else:
            self._edges.set_segments([])

        self._arrows.set_offsets(xy)
        arrow = np.nan_to_num(velocity[:, :2] * self.arrow_seconds, posinf=0.0, neginf=0.0)
        self._arrows.set_UVC(arrow[:, 0], arrow[:, 1])
        self._markers.set_offsets(xy)
        self._collided.set_offsets(xy[collided] if collided.any() else np.zeros((0, 2)))
        for label, (x, y) in zip(self._labels, xy):
            label.set_position((float(x), float(y)))
        text = f"t = {float(t):6.1f} s"
        if collided.any():
            text += f"   collided: {int(collided.sum())}"
        if self._grid is not None:
            x0, x1 = self.axes.get_xlim()
            y0, y1 = self.axes.get_ylim()
            text += (
                f"\ncentre ({np.round(0.5 * (x0 + x1)) + 0.0:.0f},"
                f" {np.round(0.5 * (y0 + y1)) + 0.0:.0f}) m,"
                f" grid {self._grid_step:g} m"
            )
        self._time_text.set_text(text)

        self.canvas.draw()
        image = np.asarray(self.canvas.buffer_rgba())[..., :3]
        return self._fit_size(image)

    def frame_from_step(self, result: StepResult, index: int = 0) -> np.ndarray:
        """:meth:`frame` of copy ``index`` of a :class:`~uav_formation_env.sim.StepResult`.

        Args:
            result: a step (or reset) result of :class:`~uav_formation_env.sim.FormationSim`.
            index: batch copy to draw.

        Returns:
            (height, width, 3) uint8 RGB image.
        """
        return self.frame(
            result.z[index, :, :3],
            result.reference_velocity[index],
            result.adjacency[index],
            result.groups[index],
            float(result.t[index]),
            collisions=result.collision[index],
        )

    def data_to_pixel(self, points: np.ndarray) -> np.ndarray:
        """Pixel (row, column) of world points in the last frame drawn.

        Args:
            points: (K, 2) horizontal positions [m].

        Returns:
            (K, 2) float array of (row, column), row 0 at the top; may lie outside the image.
        """
        display = self.axes.transData.transform(np.asarray(points, dtype=float).reshape(-1, 2))
        return np.stack([self.height - display[:, 1], display[:, 0]], axis=1)

    def show(self, frame: np.ndarray) -> None:
        """Display ``frame`` in an interactive window (``render_mode="human"``).

        The window (a pyplot figure) is created on the first call and again if it was closed.
        With a non-interactive matplotlib backend (e.g. Agg) nothing is displayed.

        Args:
            frame: (height, width, 3) uint8 RGB image, as returned by :meth:`frame`.
        """
        import matplotlib.pyplot as plt

        if self._window is None or not plt.fignum_exists(self._window[0].number):
            fig = plt.figure(figsize=(frame.shape[1] / DPI, frame.shape[0] / DPI), dpi=DPI)
            fig.canvas.manager.set_window_title(f"uav_formation: {self.scenario.name}")
            ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
            ax.set_axis_off()
            image = ax.imshow(frame, interpolation="nearest")
            self._window = (fig, image)
            plt.show(block=False)
        else:
            self._window[1].set_data(frame)
        fig = self._window[0]
        fig.canvas.draw_idle()
        fig.canvas.flush_events()
        fig.canvas.start_event_loop(0.001)

    def close(self) -> None:
        """Close the window of :meth:`show`, if any, and forget the trails.

        The renderer can still produce frames afterwards.
        """
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
        self._trail.clear()

    # ---------------------------------------------------------------- internals
    def _set_view(self, xy: np.ndarray) -> None:
        finite = np.isfinite(xy).all(axis=1)
        xy = xy[finite] if finite.any() else np.zeros((1, 2))  # NaN positions are not drawn
        center = xy.mean(axis=0)
        span = self.view_span
        axes_w, axes_h = self._axes_px
        # Half extents along x and y with equal metres per pixel: view_span on the shorter side.
        scale_x, scale_y = max(1.0, axes_w / axes_h), max(1.0, axes_h / axes_w)
        if self.fit_swarm:
            reach = np.abs(xy - center).max(axis=0) * 1.1  # [m], half extent with a 10 % margin
            needed = max(reach[0] / scale_x, reach[1] / scale_y) * 2.0
            span = max(span, float(needed))
        half_x, half_y = 0.5 * span * scale_x, 0.5 * span * scale_y
        x0, x1 = center[0] - half_x, center[0] + half_x
        y0, y1 = center[1] - half_y, center[1] + half_y
        self.axes.set_xlim(x0, x1)
        self.axes.set_ylim(y0, y1)
        if self._grid is not None:
            step = nice_grid_step(span / 6.0)
            self._grid_step = step
            xs = np.arange(np.ceil(x0 / step), np.floor(x1 / step) + 1) * step
            ys = np.arange(np.ceil(y0 / step), np.floor(y1 / step) + 1) * step
            segments = [((x, y0), (x, y1)) for x in xs] + [((x0, y), (x1, y)) for y in ys]
            self._grid.set_segments(segments)

    def _fit_size(self, image: np.ndarray) -> np.ndarray:
        """Copy of ``image`` cropped or edge-padded to exactly (height, width, 3)."""
        out = image[: self.height, : self.width]
        if out.shape[:2] != (self.height, self.width):
            pad = ((0, self.height - out.shape[0]), (0, self.width - out.shape[1]), (0, 0))
            out = np.pad(out, pad, mode="edge")
        return np.array(out, dtype=np.uint8, order="C")
