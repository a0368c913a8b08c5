"""The reproduction's figures from a short real run: Fig. 8's labels, Fig. 5's obstacle zooms,
every curve of Figs. 8-10 visible."""

from __future__ import annotations

import dataclasses
import re
import warnings
from types import SimpleNamespace

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle
from PIL import Image

from uav_formation_env.config import AvoidanceConfig, ObstacleConfig
from uav_formation_env.config_io import paper_scenario
from uav_formation_env.plotting import (
    ZOOM_REACH,
    detection_radius,
    plot_trigger_timeline,
    plot_variant_trajectories,
    zoom_axes,
)
from uav_formation_env.reproduce import FIGURES, run_variant
from uav_formation_env.reproduce.figures import FIG8_QUANTITY, draw_figures, write_figures
from uav_formation_env.reproduce.nash_analysis import NASH_FIGURE, nash_gap_figure, plot_nash_gap
from uav_formation_env.reproduce.variants import LABELS

PAPER = paper_scenario()
VARIANTS = ("pio_nftsmo", "lfpio_nftsmo")


@pytest.fixture(scope="module")
def batches():
    """80 s of two variants on one seed: the swarm splits at O1 (9.8 s) and meets O2 (~67 s)."""
    return {v: run_variant(v, PAPER, [0], duration=80.0) for v in VARIANTS}


@pytest.fixture(scope="module")
def figures(batches):
    return draw_figures(batches)


# ------------------------------------------------------------------ Fig. 8
def test_fig8_axis_label_and_title_name_the_same_quantity_and_unit(figures, batches):
    [ax] = figures["fig8_log_cost.png"].axes
    ylabel, title = ax.get_ylabel(), ax.get_title()
    assert ylabel == FIG8_QUANTITY
    assert re.fullmatch(r".+ \[[^\]]*\]", ylabel), ylabel  # the quantity, then its unit
    assert ylabel in title
    # and it is what the curves show: log10 of J_pre averaged over the UAVs
    curve = ax.get_lines()[0]
    j_pre = batches[VARIANTS[0]].j_pre[:, 0]
    np.testing.assert_allclose(curve.get_ydata(), np.log10(j_pre.mean(axis=1)))
    assert ax.get_xlabel() == "t [s]"
    assert not legend_covers_data(figures["fig8_log_cost.png"])


# ------------------------------------------------------------------ Fig. 5
def _check_zoom(ax: Axes, scenario, index: int, n_uav: int) -> None:
    obstacle = scenario.avoidance.obstacles[index]
    half = ZOOM_REACH * detection_radius(scenario, index)
    cx, cy = obstacle.center
    np.testing.assert_allclose(ax.get_xlim(), (cx - half, cx + half))
    np.testing.assert_allclose(ax.get_ylim(), (cy - half, cy + half))
    radii = {
        round(p.get_radius(), 6)
        for p in ax.patches
        if isinstance(p, Circle) and np.allclose(p.center, obstacle.center)
    }
    # the disc, the safety circle R_s and the detection circle
    assert radii == {
        obstacle.radius,
        scenario.avoidance.safety_radius(obstacle),
        detection_radius(scenario, index),
    }
    assert len(ax.get_lines()) == n_uav  # one path per UAV


def test_fig5_has_one_zoom_per_obstacle_under_each_variant(figures, batches):
    fig = figures["fig5_trajectories.png"]
    zooms = zoom_axes(fig)
    n_obstacles = len(PAPER.avoidance.obstacles)
    assert n_obstacles == 2
    assert len(zooms) == len(VARIANTS) * n_obstacles
    assert [ax.get_label() for ax in zooms] == ["zoom O1", "zoom O2"] * len(VARIANTS)
    assert len(fig.axes) == len(VARIANTS) * (1 + n_obstacles)
    for k, ax in enumerate(zooms):
        _check_zoom(ax, PAPER, k % n_obstacles, PAPER.n_uav)
    # the paths inside the zoom on O1 are the variant's own: it passes within 2 d^o of O1
    positions = batches[VARIANTS[0]].z[:, 0, :, :2]
    line = zooms[0].get_lines()[0]
    np.testing.assert_array_equal(line.get_xydata(), positions[:, 0])
    distance = np.linalg.norm(positions - np.array(PAPER.avoidance.obstacles[0].center), axis=-1)
    assert distance.min() < ZOOM_REACH * detection_radius(PAPER, 0)


@pytest.mark.parametrize(
    ("n_obstacles", "n_variants"), [(0, 1), (0, 3), (1, 3), (2, 1), (3, 2), (4, 1), (7, 3)]
)
def test_fig5_zoom_count_for_any_number_of_obstacles(n_obstacles, n_variants):
    obstacles = tuple(ObstacleConfig((300.0 * (k + 1), 0.0), 20.0) for k in range(n_obstacles))
    scenario = dataclasses.replace(PAPER, avoidance=AvoidanceConfig(obstacles=obstacles))
    x = np.linspace(0.0, 300.0 * (n_obstacles + 1), 60)
    path = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=-1)  # (T, 3)
    positions = path[:, None, :] + np.array([[0.0, 10.0 * i, 0.0] for i in range(5)])
    fig = plot_variant_trajectories(
        {f"variant {k}": positions for k in range(n_variants)}, scenario, suptitle="test"
    )
    zooms = zoom_axes(fig)
    assert len(zooms) == n_variants * n_obstacles
    assert len(fig.axes) == n_variants * (1 + n_obstacles)
    for k, ax in enumerate(zooms):
        _check_zoom(ax, scenario, k % n_obstacles, 5)
    # no two panels overlap
    fig.canvas.draw()
    boxes = [ax.get_position() for ax in fig.axes]
    for a in range(len(boxes)):
        for b in range(a + 1, len(boxes)):
            assert not boxes[a].overlaps(boxes[b]), (a, b)


# ------------------------------------------------------------------ Fig. 10
def _segments_points(ax: Axes, per_segment: int = 8) -> np.ndarray:
    """Display coordinates of every plotted line, sampled along its segments, in the axes."""
    points = []
    for line in ax.get_lines():
        xy = np.asarray(line.get_xydata(), dtype=float)
        xy = xy[np.isfinite(xy).all(axis=1)]
        if len(xy) == 0:
            continue
        display = ax.transData.transform(xy)
        if len(display) > 1:
            f = np.linspace(0.0, 1.0, per_segment, endpoint=False)[None, :, None]
            display = (display[:-1, None] + f * (display[1:, None] - display[:-1, None])).reshape(
                -1, 2
            )
        points.append(display)
    points = np.concatenate(points) if points else np.zeros((0, 2))
    box = ax.get_window_extent()
    inside = (
        (points[:, 0] >= box.x0)
        & (points[:, 0] <= box.x1)
        & (points[:, 1] >= box.y0)
        & (points[:, 1] <= box.y1)
    )
    return points[inside]


def legend_covers_data(fig: Figure) -> bool:
    """Whether an axes' legend lies over any point of its plotted lines inside the axes."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:
        legend = ax.get_legend()
        if legend is None:
            continue
        box = legend.get_window_extent(renderer)
        if not box.overlaps(ax.get_window_extent(renderer)):
            continue  # outside the axes
        points = _segments_points(ax)
        over = (
            (points[:, 0] >= box.x0)
            & (points[:, 0] <= box.x1)
            & (points[:, 1] >= box.y0)
            & (points[:, 1] <= box.y1)
        )
        if over.any():
            return True
    return False


def fake_gaps(variants, rng, steps=400):
    t = np.arange(steps + 1) * 0.2
    return {
        v: SimpleNamespace(
            t=t,
            nash_gap=10.0 ** rng.uniform(-12, 3, size=(steps, 1, 5)),
            nash_in_box=np.ones((steps, 1, 5), dtype=bool),
        )
        for v in variants
    }


def test_fig10_one_panel_per_solver_so_every_curve_shows(batches):
    fig = nash_gap_figure(batches)
    assert len(fig.axes) == len(VARIANTS)
    for ax, variant in zip(fig.axes, VARIANTS):
        assert ax.get_title(loc="left") == LABELS[variant]
        *others, own = ax.get_lines()
        assert len(others) == len(VARIANTS) - 1  # the others, grey, for comparison
        assert all(line.get_color() == "0.8" for line in others)
        assert own.get_color() != "0.8"
        assert ax.get_legend() is None


def test_fig10_seven_identical_levels_stay_visible():
    """Seven solvers with the same gaps: each still has a panel of its own."""
    fake = fake_gaps(["pio", "lfpio", "pio_nftsmo", "lfpio_nftsmo", "pso", "exact", "nash"],
                     np.random.default_rng(0))  # fmt: skip
    same = next(iter(fake.values())).nash_gap
    for batch in fake.values():
        batch.nash_gap = same
    fig = nash_gap_figure(fake)
    assert len(fig.axes) == 7 and all(len(ax.get_lines()) == 7 for ax in fig.axes)


def test_fig10_a_step_without_an_in_box_plan_is_a_gap_not_a_warning():
    fake = fake_gaps(["pio"], np.random.default_rng(1), steps=4)
    fake["pio"].nash_in_box[2] = False  # no UAV of any seed in the box at step 2
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's "All-NaN slice encountered"
        fig = nash_gap_figure(fake)
    curve = fig.axes[0].get_lines()[-1].get_ydata()
    assert np.isnan(curve[2]) and np.isfinite(curve[[0, 1, 3]]).all()


# ------------------------------------------------------------------ Fig. 8 and Fig. 9 legibility
def test_fig8_event_labels_sit_above_the_axes(figures):
    fig = figures["fig8_log_cost.png"]
    [ax] = fig.axes
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    top = ax.get_window_extent(renderer).y1
    labels = [child for child in ax.texts if child.get_rotation() == 90]
    assert len(labels) >= 3  # O1 split, O1 restore, O2, the turns
    assert all(label.get_window_extent(renderer).y0 >= top for label in labels)
    title = ax.title.get_window_extent(renderer)
    assert all(label.get_window_extent(renderer).y1 <= title.y0 for label in labels)


def test_fig9_equal_cumulative_counts_stay_visible():
    t = np.arange(100) * 0.2
    every = np.ones(100, dtype=bool)
    fig = plot_trigger_timeline(
        t, {"PIO": every, "LFPIO": every}, {"PIO": np.cumsum(every), "LFPIO": np.cumsum(every)}
    )
    lines = fig.axes[1].get_lines()
    assert lines[0].get_linewidth() > lines[1].get_linewidth()  # the first shows around the second
    assert lines[0].get_linestyle() != lines[1].get_linestyle()
    assert [text.get_text() for text in fig.axes[1].get_legend().get_texts()] == [
        "PIO (100)",
        "LFPIO (100)",
    ]


def test_legend_check_sees_a_legend_over_the_data():
    """The check itself: a legend inside the axes over a curve is caught."""
    fig = Figure()
    ax = fig.subplots()
    x = np.linspace(0.0, 1.0, 50)
    ax.plot(x, np.ones_like(x), label="flat at the top")
    ax.plot(x, x, label="diagonal")
    ax.set_ylim(0.0, 1.05)
    ax.legend(loc="upper right")
    FigureCanvasAgg(fig)
    assert legend_covers_data(fig)


# ------------------------------------------------------------------ files
def test_figures_are_written(figures, batches, tmp_path):
    written = write_figures(batches, tmp_path)
    assert [p.name for p in written] == list(FIGURES) == list(figures)
    plot_nash_gap(batches, tmp_path / NASH_FIGURE)
    for name in [*FIGURES, NASH_FIGURE]:
        with Image.open(tmp_path / name) as image:
            assert image.format == "PNG"
            assert min(image.size) > 300, name
