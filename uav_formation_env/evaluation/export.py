"""Evaluation results as score matrices for rliable (Agarwal et al., 2021).

rliable compares algorithms by interval estimates (IQM, optimality gap, probability of
improvement) of a dict ``{algorithm: scores}`` with ``scores`` of shape (runs, tasks). Here a
run is an episode seed and a task a scenario: each algorithm is given its ``evaluate``
outputs (``summary.json`` files or their folders, or summary dicts), one per task in the same
order, all over the same seeds::

    from uav_formation_env.evaluation.export import rliable_scores
    from rliable import library as rly, metrics

    scores = rliable_scores({"lfpio": ["results/lfpio_paper", "results/lfpio_fields"],
                             "dagger": ["results/dagger_paper", "results/dagger_fields"]})
    iqm, ci = rly.get_interval_estimates(scores, lambda s: np.array([metrics.aggregate_iqm(s)]))

Metrics (higher is better, as rliable assumes): ``"return"``, minus the realised J per UAV of
each seed (the paper's index, the sum of the rewards); ``"completed"``, 1 where the mission was
completed, else 0.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

METRICS = ("return", "completed")

SummaryLike = str | Path | Mapping[str, Any]


def _summary(source: SummaryLike) -> Mapping[str, Any]:
    if isinstance(source, Mapping):
        return source
    path = Path(source)
    if path.is_dir():
        path = path / "summary.json"
    if not path.is_file():
        raise FileNotFoundError(f"evaluation summary not found: {str(path)!r}")
    return json.loads(path.read_text(encoding="utf-8"))


def per_seed_scores(summary: SummaryLike, metric: str = "return") -> tuple[list[int], np.ndarray]:
    """The seeds of one evaluation and its (seeds,) scores of ``metric`` (:data:`METRICS`)."""
    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")
    data = _summary(summary)
    if metric == "return":
        scores = -np.asarray(data["realised_cost_per_seed"], dtype=float)
    else:
        scores = np.asarray(data["mission"]["completed_per_seed"], dtype=float)
    return [int(s) for s in data["seeds"]], scores


def rliable_scores(
    runs: Mapping[str, Sequence[SummaryLike]], metric: str = "return"
) -> dict[str, np.ndarray]:
    """``{algorithm: (seeds, tasks) scores}`` from each algorithm's evaluations, one per task.

    Raises:
        ValueError: an unknown metric, algorithms with different numbers of tasks, or
            evaluations over different seeds.
    """
    counts = {name: len(tasks) for name, tasks in runs.items()}
    if len(set(counts.values())) > 1:
        raise ValueError(f"every algorithm needs the same tasks, got task counts {counts}")
    reference: list[int] | None = None
    out = {}
    for name, tasks in runs.items():
        columns = []
        for task in tasks:
            seeds, scores = per_seed_scores(task, metric)
            if reference is None:
                reference = seeds
            elif seeds != reference:
                raise ValueError(
                    f"{name}: an evaluation over seeds {seeds[:3]}..., the first over "
                    f"{reference[:3]}...; rliable's runs must be the same seeds"
                )
            columns.append(scores)
        out[name] = np.stack(columns, axis=1)
    return out


def write_rliable(scores: Mapping[str, np.ndarray], path: str | Path) -> Path:
    """The score dict as an ``.npz`` (one array per algorithm), loadable without pickle:
    ``dict(np.load(path))``."""
    path = Path(path)
    np.savez(path, **{name: np.asarray(value, dtype=float) for name, value in scores.items()})
    return path
