"""Figures of the baselines (matplotlib, Agg backend): learning curves and the mission comparison.

:func:`mission_bars`: per policy, the realised cost, the mission completion rate and the route
error max, from the rows of :func:`uav_formation_baselines.evaluate.comparison_rows` (values read
from ``summarise``; nothing is computed here).

:func:`learning_curve`: two panels over agent-timesteps, one line per run: the training
episodes' mean stage cost per UAV-step (``-rollout/ep_rew_mean / rollout/ep_len_mean`` of
``progress.csv``, stochastic policy, untransformed reward; per step because divergence resets
cut early episodes short) and the periodic evaluation's mean realised cost per UAV and episode
(``evaluations.csv``, deterministic policy, full episodes, collisions marked). Both on a log axis:
costs span decades in training.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def _column(path: Path, x_key: str, y_key: str) -> tuple[list[float], list[float]]:
    """(x, y) of the rows of a CSV where both keys hold numbers."""
    xs, ys = [], []
    if not path.is_file():
        return xs, ys
    with open(path, newline="") as stream:
        for row in csv.DictReader(stream):
            try:
                x, y = float(row.get(x_key) or "nan"), float(row.get(y_key) or "nan")
            except ValueError:
                continue
            if math.isfinite(x) and math.isfinite(y):
                xs.append(x)
                ys.append(y)
    return xs, ys


def learning_curve(
    run_dirs: Sequence[str | Path],
    png: str | Path,
    labels: Sequence[str] | None = None,
    references: dict[str, float] | None = None,
) -> Path:
    """Plot the learning curves of runs into ``png``.

    Args:
        run_dirs: run directories of :mod:`uav_formation_baselines.train`.
        png: output image.
        labels: one label per run (None: the directory names).
        references: horizontal lines ``{label: realised cost per UAV}`` on the evaluation panel
            (e.g. the heuristic's and the DMPC's on the same seeds).
    """
    labels = list(labels) if labels is not None else [Path(d).name for d in run_dirs]
    fig, (train_ax, eval_ax) = plt.subplots(1, 2, figsize=(11, 4), sharex=True)
    for run, label in zip(run_dirs, labels):
        run = Path(run)
        x, y = _column(run / "progress.csv", "time/total_timesteps", "rollout/ep_rew_mean")
        _, length = _column(run / "progress.csv", "time/total_timesteps", "rollout/ep_len_mean")
        if x and len(length) == len(y):
            train_ax.plot(x, [-v / max(n, 1.0) for v, n in zip(y, length)], label=label)
        x, cost = _column(run / "evaluations.csv", "timesteps", "realised_cost_mean")
        if x:
            (line,) = eval_ax.plot(x, cost, marker="o", ms=3, label=label)
            _, hits = _column(run / "evaluations.csv", "timesteps", "collisions")
            crashed = [(xi, ci) for xi, ci, h in zip(x, cost, hits) if h > 0]
            if crashed:
                eval_ax.scatter(*zip(*crashed), marker="x", color=line.get_color(), zorder=3)
    for name, value in (references or {}).items():
        eval_ax.axhline(value, ls="--", lw=1, color="gray")
        eval_ax.annotate(name, (0.01, value), xycoords=("axes fraction", "data"), fontsize=8)
    train_ax.set_title("training episodes (stochastic policy)")
    train_ax.set_ylabel("mean stage cost per UAV-step")
    eval_ax.set_title("evaluation (deterministic; x = collisions)")
    eval_ax.set_ylabel("realised cost per UAV and episode")
    for ax in (train_ax, eval_ax):
        ax.set_xlabel("agent-timesteps")
        ax.set_yscale("log")
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    return _save(fig, png)


def _save(fig, png: str | Path) -> Path:
    """Write ``fig`` to ``png`` (its folder created) and close it."""
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def mission_bars(
    rows: Sequence[dict[str, Any]],
    png: str | Path,
    threshold: float | None = None,
    reference: str | None = None,
) -> Path:
    """Bar chart of the comparison: realised cost per UAV, missions completed (fraction of seeds)
    and route error max per policy, with their 95 % CI over seeds as error bars.

    Args:
        rows: :func:`~uav_formation_baselines.evaluate.comparison_rows`.
        png: output image.
        threshold: the completion threshold of the route error max [m] (dashed line), if known.
        reference: label of the reference policy (its bars are hatched).
    """
    labels = [str(r["policy"]) for r in rows]
    short = [Path(label).name if "/" in label else label for label in labels]
    x = list(range(len(rows)))
    fig, (cost_ax, done_ax, route_ax) = plt.subplots(1, 3, figsize=(13, 4))
    panels = (
        (cost_ax, "realised_cost", "realised cost per UAV (Σ J_i)", True),
        (done_ax, "completion_rate", "missions completed (fraction of seeds)", False),
        (route_ax, "route_error_max_m", "route error max [m] (centroid vs preset route)", True),
    )
    for ax, key, title, log in panels:
        values = [float(r[f"{key}_mean" if key == "realised_cost" else key]) for r in rows]
        errors = [float(r.get(f"{key}_ci95") or 0.0) for r in rows]
        bars = ax.bar(x, values, yerr=errors if any(errors) else None, capsize=3, color="C0")
        for bar, label in zip(bars, labels):
            if label == reference:
                bar.set_hatch("//")
                bar.set_facecolor("C2")
        if key == "completion_rate":
            for xi, r in zip(x, rows):
                ax.annotate(f"{r['completed']}/{r['episodes']}", (xi, r[key]), ha="center",
                            va="bottom", fontsize=8)  # fmt: skip
            ax.set_ylim(0, 1.12)
        if log and all(v > 0 for v in values):
            ax.set_yscale("log")
        if key == "route_error_max_m" and threshold is not None:
            ax.axhline(threshold, ls="--", lw=1, color="red", label=f"threshold {threshold:g} m")
            ax.legend(fontsize=8)
        ax.set_title(title, fontsize=10)
        ax.set_xticks(x)
        ax.set_xticklabels(short, rotation=30, ha="right", fontsize=8)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    return _save(fig, png)


# The learning-curve sources of each recipe's run directory: (file, x column, y column).
# Left panel, deterministic evaluation during training (realised J per UAV over agent-steps):
# DAgger's validation after each round and SB3's FormationEvalCallback. Right panel: BenchMARL's
# training reward per UAV-step over frames.
EVALUATION_CURVES = (
    ("rounds.csv", "samples", "validation_cost"),
    ("evaluations.csv", "timesteps", "realised_cost_mean"),
)
TRAINING_CURVES = (("progress.csv", "frames", "mean_reward_per_uav_step"),)


def run_curves(run: str | Path) -> dict[str, list[tuple[list[float], list[float]]]]:
    """The ``(x, y)`` curves a run directory holds: ``"evaluation"`` (:data:`EVALUATION_CURVES`)
    and ``"training"`` (:data:`TRAINING_CURVES`); files a recipe does not write are skipped."""
    run = Path(run)
    return {
        panel: [curve for curve in (_column(run / f, x, y) for f, x, y in sources) if curve[0]]
        for panel, sources in (("evaluation", EVALUATION_CURVES), ("training", TRAINING_CURVES))
    }


def training_curves(
    run_dirs: Sequence[str | Path],
    png: str | Path,
    reference_cost: float | None = None,
) -> Path:
    """Learning curves of the DAgger, SB3 and BenchMARL recipes (:func:`run_curves`), one line
    per run, coloured by the algorithm of its ``config.yaml``.

    Left: the deterministic evaluation during training, realised J per UAV over agent-steps
    (DAgger's validation after each round over the labelled agent-steps so far; SB3's periodic
    evaluation over its timesteps), with ``reference_cost`` (LFPIO's realised J on the
    evaluation seeds) as a dashed line. Right: BenchMARL's training reward per UAV-step
    (``progress.csv``: the transformed reward the algorithm optimises, stochastic policy) over
    frames.
    """
    import yaml

    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    colours: dict[str, Any] = {}
    for run in map(Path, run_dirs):
        config = yaml.safe_load((run / "config.yaml").read_text()) or {}
        algorithm = str(config.get("algorithm") or config.get("algo"))
        label = None if algorithm in colours else algorithm  # one legend entry per algorithm
        colour = colours.setdefault(algorithm, f"C{len(colours)}")
        curves = run_curves(run)
        for xs, ys in curves["evaluation"]:
            left.plot(xs, ys, "o-", color=colour, label=label)
        for xs, ys in curves["training"]:
            right.plot(xs, ys, "-", color=colour, label=label)
    if reference_cost is not None:
        left.axhline(reference_cost, color="k", ls="--", label="LFPIO (evaluation seeds)")
    left.set_yscale("log")
    left.set_xlabel("agent-steps (DAgger: labelled)")
    left.set_ylabel("evaluation realised J per UAV")
    left.set_title("Evaluation during training (DAgger, SB3)")
    right.set_xlabel("frames (env steps)")
    right.set_ylabel("training reward per UAV-step (transformed)")
    right.set_title("BenchMARL")
    for axis in (left, right):
        if axis.lines:
            axis.legend(fontsize=8)
        axis.grid(alpha=0.3)
    fig.tight_layout()
    png = Path(png)
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def ladder_curves(
    run_dirs: Sequence[str | Path],
    png: str | Path,
    references: dict[str, float] | None = None,
    label_of: Callable[[dict[str, Any]], str] | None = None,
) -> Path:
    """Learning curves of the in-process trainer's runs (``progress.csv`` of
    ``uav_formation_baselines.onpolicy``), one line per run, coloured by ``label_of`` of its
    ``config.yaml`` (the results table's row; None: the algorithm).

    Top: the deterministic evaluation's return per UAV under the training reward over
    agent-steps (left) and over training wall time (right), with ``references`` (name -> the
    same return of a reference policy on the same task, e.g. LFPIO, the heuristic, random
    actions) as dashed lines. Bottom: the evaluation's missions completed (fraction), likewise.
    """
    import csv

    import yaml

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharey="row")
    colours: dict[str, Any] = {}
    for run in map(Path, run_dirs):
        config = yaml.safe_load((run / "config.yaml").read_text()) or {}
        row = label_of(config) if label_of else str(config.get("algorithm"))
        label = None if row in colours else row
        colour = colours.setdefault(row, f"C{len(colours) % 10}")
        with open(run / "progress.csv", newline="", encoding="utf-8") as stream:
            rows = [r for r in csv.DictReader(stream) if r.get("eval_return")]
        for column, x_key in enumerate(("frames", "wall_s")):
            xs = [float(r[x_key]) for r in rows]
            done = [int(r["eval_completed"]) / max(1, int(r["eval_episodes"])) for r in rows]
            axes[0, column].plot(xs, [float(r["eval_return"]) for r in rows], "-", color=colour,
                                 label=label)  # fmt: skip
            axes[1, column].plot(xs, done, "-", color=colour, label=label)
    for name, value in (references or {}).items():
        for axis in axes[0]:
            axis.axhline(value, ls="--", lw=1, color="k" if name == "lfpio" else "0.5",
                         label=name)  # fmt: skip
    axes[0, 0].set_ylabel("evaluation return per UAV (reward train)")
    axes[1, 0].set_ylabel("missions completed (fraction)")
    for axis in axes[1]:
        axis.set_ylim(-0.05, 1.05)
    axes[1, 0].set_xlabel("agent-steps")
    axes[1, 1].set_xlabel("training wall time [s]")
    for axis in axes.ravel():
        axis.grid(alpha=0.3)
    axes[0, 1].legend(fontsize=8)
    fig.tight_layout()
    return _save(fig, png)
