"""Learning curves of training runs (matplotlib, Agg backend).

Two panels over agent-timesteps, one line per run: the training episodes' mean stage cost per
UAV-step (``-rollout/ep_rew_mean / rollout/ep_len_mean`` of ``progress.csv``, stochastic policy,
untransformed reward; per step because divergence resets cut early episodes short) and the
periodic evaluation's mean realised cost per UAV and episode (``evaluations.csv``, deterministic
policy, full episodes, collisions marked). Both on a log axis: costs span decades in training.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path

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
    fig.tight_layout()
    png = Path(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png
