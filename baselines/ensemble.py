"""An ensemble of learned policies: one policy file whose action is its members' mean.

    python -m uav_formation_baselines.ensemble --out runs/dagger_paper_ensemble \
        runs/dagger_paperG_s3 runs/dagger_paperG_s4 ... [--top 4]

Each member is a finished run of the same scenario and observation layout (its policy,
``scenario.yaml`` and ``config.yaml``): a DAgger run, or an on-policy run (PPO, ``RUN`` or its
``RUN/best``). ``--top K`` keeps the K members that scored best on their validation seeds
(:func:`validation_score`; ranked like :func:`~uav_formation_baselines.imitation.best_round`),
never on evaluation seeds. The mean of several policies' actions averages out the errors they do
not share (baselines/RESULTS.md). Members trained in the velocity action mode average their
set-points, and the ensemble flies through the same inner loop (its ``scenario.yaml``).

The output directory holds the policy (``policy.json``, ``policy.npz``; load with ``uav-formation
evaluate --policy DIR``), ``scenario.yaml`` (the members') and ``config.yaml`` (``algorithm:
<members' algorithm>_ensemble``, the members with their scores, their summed agent-steps and wall
times).
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from uav_formation_env.cli import OneLineParser
from uav_formation_env.config_io import load_scenario, save_scenario
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.evaluation.heldout import report_run
from uav_formation_env.policies.policy_file import (
    JSON_NAME,
    load_policy_file,
    merge_members,
    save_policy_file,
)
from uav_formation_env.scenes import seeds_by_n_uav

__all__ = ["build_ensemble", "rank_runs", "validation_score"]


def validation_score(run: str | Path) -> dict[str, Any]:
    """The validation row of a run; keys ``round``, ``validation_completed``,
    ``validation_episodes``, ``validation_cost``, ``source``. A DAgger run: its chosen round's,
    from ``selection.csv`` (``--select``) if it has one, else ``rounds.csv``. An on-policy run:
    the evaluation its policy was saved at (``selected_by`` of a ``RUN/best``, else the last
    evaluation in ``progress.csv``; ``round`` is the update)."""
    run = Path(run)
    with open(run / "config.yaml", encoding="utf-8") as stream:
        record = yaml.safe_load(stream)
    if "best_round" not in record:
        return _onpolicy_score(run, record)
    chosen = int(record["best_round"])
    for name in ("selection.csv", "rounds.csv"):
        if (run / name).is_file():
            with open(run / name, encoding="utf-8") as stream:
                row = next((r for r in csv.DictReader(stream) if int(r["round"]) == chosen), None)
            if row is None:
                raise ValueError(f"{run}/{name} has no row for the chosen round {chosen}")
            return {
                "round": chosen,
                "validation_completed": int(row["validation_completed"]),
                "validation_episodes": int(row["validation_episodes"]),
                "validation_cost": float(row["validation_cost"]),
                "source": name,
            }
    raise FileNotFoundError(f"{run} has neither selection.csv nor rounds.csv")


def _onpolicy_score(run: Path, record: dict[str, Any]) -> dict[str, Any]:
    """:func:`validation_score` of an on-policy run (uav_formation_baselines.onpolicy)."""
    source, row = "selected_by", record.get("selected_by")
    if not row:
        source, progress = "progress.csv", run / "progress.csv"
        if not progress.is_file():
            raise FileNotFoundError(f"{run} has no best_round, selected_by or progress.csv")
        with open(progress, encoding="utf-8") as stream:
            rows = [r for r in csv.DictReader(stream) if r.get("eval_completed")]
        if not rows:
            raise ValueError(f"{progress} has no evaluation")
        row = rows[-1]
    return {
        "round": int(row.get("update", -1)),
        "validation_completed": int(row["eval_completed"]),
        "validation_episodes": int(row["eval_episodes"]),
        "validation_cost": float(row["eval_J"]),
        "source": source,
    }


def rank_runs(runs: list[str | Path]) -> list[tuple[Path, dict[str, Any]]]:
    """``runs`` with their :func:`validation_score`, best first: the most completed validation
    missions, then the lowest realised cost (runs scored on different seed counts are not
    comparable: a ``ValueError``)."""
    scored = [(Path(run), validation_score(run)) for run in runs]
    counts = {score["validation_episodes"] for _, score in scored}
    if len(counts) > 1:
        raise ValueError(f"runs were validated on different numbers of seeds: {sorted(counts)}")
    return sorted(
        scored, key=lambda item: (-item[1]["validation_completed"], item[1]["validation_cost"])
    )


def _combined(policies: list[Any]) -> tuple[list[Any], np.ndarray, np.ndarray, Any, Any]:
    """The networks of ``policies`` as one file's (members, obs_mean, obs_std, observation_clip,
    member_statistics): without a clip, one set of statistics with the others absorbed into the
    first layers (:func:`merge_members`); with one (not linear), each member keeps its own."""
    clips = {policy.header["observation_clip"] for policy in policies}
    if len(clips) != 1:
        raise ValueError(f"the members clip their observations differently: {sorted(clips)}")
    clip, parts = clips.pop(), [part for policy in policies for part in policy.parts()]
    if clip is None:
        members, mean, std = merge_members(parts)
        return members, mean, std, None, None
    statistics = [(member_mean, member_std) for _, member_mean, member_std in parts]
    return [layers for layers, _, _ in parts], *statistics[0], clip, statistics


def build_ensemble(
    runs: list[str | Path], out: str | Path, top: int | None = None
) -> dict[str, Any]:
    """Write the ensemble of ``runs`` (the ``top`` best by :func:`rank_runs`, all if None) to
    ``out``; returns its ``config.yaml`` record. The members must share one scenario (their
    ``scenario.yaml`` files load equal), else a ``ValueError`` naming the first that differs."""
    if len(runs) < 1:
        raise ValueError("runs: give at least one run directory")
    if top is not None and (isinstance(top, bool) or not isinstance(top, int) or top < 1):
        raise ValueError(f"top must be an integer >= 1, got {top!r}")
    for run in runs:
        for name in (JSON_NAME, "scenario.yaml", "config.yaml"):
            if not (Path(run) / name).is_file():
                raise FileNotFoundError(f"{run} is not a finished run: no {name}")
    ranked = rank_runs(runs)[:top]
    scenario = load_scenario(ranked[0][0] / "scenario.yaml")
    for run, _ in ranked[1:]:
        if load_scenario(run / "scenario.yaml") != scenario:
            raise ValueError(f"{run}/scenario.yaml differs from {ranked[0][0]}/scenario.yaml")
    policies = [load_policy_file(run) for run, _ in ranked]
    activations = {policy.header["activation"] for policy in policies}
    if len(activations) != 1:
        raise ValueError(f"the members use different activations: {sorted(activations)}")
    if any(policy.header["action"] != "clip" for policy in policies):
        raise ValueError("an ensemble averages unsquashed actions: members need action 'clip'")
    members, mean, std, clip, statistics = _combined(policies)
    records = []
    for run, _ in ranked:
        with open(run / "config.yaml", encoding="utf-8") as stream:
            records.append(yaml.safe_load(stream))
    algorithm = f"{records[0].get('algorithm', 'policy')}_ensemble"
    out = Path(out)
    save_policy_file(
        out,
        members,
        mean,
        std,
        observation=scenario.observation.kind,
        activation=activations.pop(),
        observation_clip=clip,
        metadata={"scenario": scenario.name, "algorithm": algorithm},
        member_statistics=statistics,
    )
    # the file must give the members' mean action on the first observations of episodes 0, 1
    # (of one N: a scene distribution over N, random_swarm, may draw two)
    n_uav, seeds = next(iter(seeds_by_n_uav(scenario, [0, 1]).items()))
    sample = FormationEpisodes(scenario, len(seeds), n_uav=n_uav).reset(seed=seeds).observation
    sample = sample.reshape(-1, sample.shape[-1])
    want = np.clip(sum(policy.outputs(sample) for policy in policies) / len(policies), -1, 1)
    difference = float(abs(load_policy_file(out).act_flat(sample) - want).max())
    if difference > 1e-5:
        raise RuntimeError(f"the ensemble differs from its members' mean by {difference:.3g}")
    save_scenario(scenario, out / "scenario.yaml")
    record = {
        "algorithm": algorithm,
        "scenario": scenario.name,
        "top": top,
        "candidates": [str(run) for run in runs],
        "members": [
            {"run": str(run), "seed": rec.get("seed"), **score}
            for (run, score), rec in zip(ranked, records)
        ],
        # the members' training, summed: what the ensemble cost to train on one machine
        "agent_steps": int(sum(rec.get("agent_steps", rec.get("frames", 0)) for rec in records)),
        "wall_time_s": float(sum(rec.get("wall_time_s", 0.0) for rec in records)),
    }
    with open(out / "config.yaml", "w", encoding="utf-8") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)
    return record


def _run_name(run: Path) -> str:
    """A member's name in messages: the run's folder (``RUN/best`` for a run's best policy)."""
    return f"{run.parent.name}/{run.name}" if run.name == "best" else run.name


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="finished run directories (same scenario)")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--top", type=int, default=None, help="keep the K best-validated runs")
    parser.add_argument(
        "--heldout-seeds",
        type=int,
        default=3,
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    args = parser.parse_args(argv)
    try:
        record = build_ensemble(args.runs, args.out, args.top)
    except (ValueError, FileNotFoundError, KeyError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    names = ", ".join(_run_name(Path(m["run"])) for m in record["members"])
    print(f"wrote the policy {args.out}: the mean of {len(record['members'])} members ({names})")
    report_run(args.out, args.heldout_seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
