"""Choosing a DAgger run's round: each round's policy flown on validation seeds and scored.

Training scores every round on its ``validation_seeds`` (:func:`validation_scores`) and keeps the
best (:func:`best_round`); ``--select`` scores a finished run's rounds again on more seeds
(:func:`select_round`). Validation seeds (5,000 on) are apart from the evaluation seeds (0-99).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import yaml

from uav_formation_baselines.imitation_data import fly_in_workers, worker_pool
from uav_formation_env.config import Scenario
from uav_formation_env.config_io import load_scenario
from uav_formation_env.evaluation import summarise_groups

__all__ = ["best_round", "keep_round", "select_round", "validation_scores", "write_rows"]


def validation_scores(
    scenario: Scenario,
    learner: str | Path,
    seeds: list[int],
    pool: Any = None,
    workers: int = 1,
    shield: bool = False,
) -> dict[str, Any]:
    """A round's validation: the saved policy ``learner`` (behind the safety shield if
    ``shield``) flies ``seeds`` (grouped by N, split over the ``workers`` of ``pool`` if given)
    through the project's runner; missions completed,
    episodes, realised J per UAV, route error max [m] and colliding UAV-steps, as
    ``validation_*`` columns."""
    summary = summarise_groups(fly_in_workers(pool, workers, scenario, learner, seeds, shield))
    mission = summary["mission"]
    return {
        "validation_completed": mission["completed"],
        "validation_episodes": mission["episodes"],
        "validation_cost": summary["realised_cost_mean"],
        "validation_route_error_max_m": mission["route_error_max_m"],
        "validation_collisions": mission["collisions_after_start"],
    }


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` (dicts with the same keys) as a CSV table at ``path``."""
    with open(path, "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(stream, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def keep_round(out: Path, round_index: int) -> None:
    """Make the policy of ``rounds/<round_index>/`` the run's (``policy.json``, ``policy.npz``)."""
    for name in ("policy.json", "policy.npz"):
        (out / name).write_bytes((out / "rounds" / str(round_index) / name).read_bytes())


def best_round(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """The row of the round with the most completed validation missions, then the lowest
    realised cost (rows with ``validation_completed`` and ``validation_cost``)."""
    return max(rows, key=lambda row: (row["validation_completed"], -row["validation_cost"]))


def select_round(
    out: str | Path,
    validation_seeds: int,
    validation_seed_start: int | None = None,
    workers: int = 1,
) -> dict[str, Any]:
    """Choose a finished run's round again, on more validation seeds.

    Eight validation episodes tell rounds apart by one mission at most (the paper students
    complete 90-95 % of their missions), so the round that training kept is partly chance.
    Every round's policy ``rounds/<r>/`` of the run in ``out`` is flown on the seeds
    ``validation_seed_start`` .. + ``validation_seeds`` - 1 (default start: the run's own,
    5,000, apart from the evaluation seeds 0-99) and scored like training's validation
    (:func:`best_round`); the rows go to ``selection.csv``, the chosen round is copied to the
    run's policy and recorded under ``selection`` in ``config.yaml``.

    Returns:
        the chosen round's row (round, validation_completed, validation_cost, ...).
    """
    if (
        isinstance(validation_seeds, bool)
        or not isinstance(validation_seeds, int)
        or validation_seeds < 1
    ):
        raise ValueError(f"validation_seeds must be an integer >= 1, got {validation_seeds!r}")
    out = Path(out)
    record_path = out / "config.yaml"
    if not record_path.is_file() or not (out / "rounds").is_dir():
        raise FileNotFoundError(f"{out} is not a finished imitation run (config.yaml, rounds/)")
    with open(record_path, encoding="utf-8") as stream:
        record = yaml.safe_load(stream)
    start = record["config"]["validation_seed_start"]
    start = start if validation_seed_start is None else int(validation_seed_start)
    scen = load_scenario(out / "scenario.yaml")
    seeds = list(range(start, start + validation_seeds))
    shield = bool(record["config"].get("shield", False))  # as the run's rounds were scored
    rows = []
    pool = worker_pool(workers)
    try:
        for r in sorted(int(p.name) for p in (out / "rounds").iterdir() if p.name.isdigit()):
            learner = out / "rounds" / str(r)
            scores = validation_scores(scen, learner, seeds, pool, workers, shield)
            rows.append({"round": r, **scores})
    finally:
        if pool is not None:
            pool.shutdown()
    best = best_round(rows)
    write_rows(out / "selection.csv", rows)
    keep_round(out, best["round"])
    record["best_round"] = best["round"]
    record["selection"] = {
        "validation_seed_start": start,
        "validation_seeds": validation_seeds,
        "round": best["round"],
    }
    with open(record_path, "w", encoding="utf-8") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)
    return best
