"""Table 2 (trigger counts per UAV and variant) and ``summary.json``."""

from __future__ import annotations

from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config_io import to_dict
from uav_formation_env.evaluation import (
    EpisodeBatch,
    summarise,
)
from uav_formation_env.reproduce.variants import (
    LABELS,
    PAPER_EVENTS_S,
    PAPER_TRIGGER_MEAN,
    PAPER_TRIGGERS,
)


def trigger_counts(batch: EpisodeBatch) -> np.ndarray:
    """(B, N) triggered steps per seed and UAV."""
    if batch.triggered is None:
        raise ValueError(f"variant {batch.policy_name} has no trigger records")
    return batch.triggered.sum(axis=0)


def _std(x: np.ndarray) -> np.ndarray:
    return x.std(axis=0, ddof=1) if x.shape[0] > 1 else np.zeros(x.shape[1:])


def table2_rows(batches: dict[str, EpisodeBatch]) -> list[dict[str, Any]]:
    """Table 2 as rows: variant, UAV1..UAVN and mean (means over seeds), then their std."""
    rows = []
    for variant, batch in batches.items():
        counts = trigger_counts(batch).astype(float)  # (B, N)
        per_seed = np.concatenate((counts, counts.mean(axis=1, keepdims=True)), axis=1)
        names = [f"UAV{i + 1}" for i in range(counts.shape[1])] + ["mean"]
        row: dict[str, Any] = {"variant": variant}
        row.update({n: float(v) for n, v in zip(names, per_seed.mean(axis=0))})
        row.update({f"{n}_std": float(v) for n, v in zip(names, _std(per_seed))})
        rows.append(row)
    return rows


def write_table2(batches: dict[str, EpisodeBatch], path: str | Path) -> None:
    """``table2.csv``: columns variant, UAV1..UAVN, mean, UAV1_std..UAVN_std, mean_std."""
    rows = table2_rows(batches)
    header = list(rows[0])
    lines = [",".join(header)]
    for row in rows:
        lines.append(
            ",".join(
                row[h] if isinstance(row[h], str) else f"{row[h]:.2f}".rstrip("0").rstrip(".")
                for h in header
            )
        )
    Path(path).write_text("\n".join(lines) + "\n")


def build_summary(
    batches: dict[str, EpisodeBatch], seeds: list[int], wall: float, jobs: int
) -> dict[str, Any]:
    """The content of ``summary.json``."""
    first = next(iter(batches.values()))
    variants = {}
    for variant, batch in batches.items():
        s = summarise(batch)
        s["label"] = LABELS[variant]
        per_seed_mean = trigger_counts(batch).mean(axis=1)  # (B,)
        s["triggers_std_over_seeds"] = float(_std(per_seed_mean[:, None])[0])
        s["paper_triggers_per_uav"] = list(PAPER_TRIGGERS[variant])
        s["paper_triggers_mean"] = PAPER_TRIGGER_MEAN[variant]
        variants[variant] = s
    return {
        "variants": variants,
        "seeds": seeds,
        "duration_s": float(first.scenario.duration),
        "n_steps": first.n_steps,
        "wall_time_s": wall,
        "jobs": jobs,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "cost": to_dict(first.scenario.cost),
        "paper": {
            "triggers_per_uav": {k: list(v) for k, v in PAPER_TRIGGERS.items()},
            "triggers_mean": PAPER_TRIGGER_MEAN,
            "events_s": PAPER_EVENTS_S,
        },
    }


# ---------------------------------------------------------------------------------------- figures
