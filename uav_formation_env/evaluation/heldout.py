"""The end of every training run: how the trained policy flies the mission on a few held-out seeds.

Every trainer of the project (``uav-formation train``, the examples, the DAgger / BenchMARL
recipes) ends with :func:`heldout_report`: the policy and the reference (LFPIO by default) fly the
same held-out seeds (0, 1, 2 by default: the evaluation seeds, never a training or validation
seed), and the report puts missions completed, the worst route error, the collisions after t = 0
and the realised cost J against the reference's beside the training reward. It is written as
``heldout.json`` into the run directory when one is given, and printed by :meth:`HeldoutReport.
text`. ``uav-formation evaluate --policy DIR --seeds 3`` gives the same figures.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import load_scenario, with_overrides
from uav_formation_env.evaluation.digest import fly_in_chunks, summarise_digests
from uav_formation_env.policies.registry import BatchPolicy, make_policy
from uav_formation_env.tasks import evaluation_scenario

__all__ = [
    "HELDOUT_FILE",
    "HELDOUT_SEEDS",
    "HeldoutReport",
    "heldout_report",
    "report_run",
    "versus_reference",
]

HELDOUT_SEEDS = (0, 1, 2)  # the first evaluation seeds (training uses 1000+ and 5000+)
HELDOUT_FILE = "heldout.json"
HELDOUT_BATCH_SIZE = 100  # seeds flown at once (the memory of one batch)


@dataclass(frozen=True)
class HeldoutReport:
    """The mission of a trained policy on held-out seeds, beside a reference's on the same seeds.

    Attributes:
        policy: the policy's label.
        scenario: the scenario's name.
        seeds: the held-out seeds flown.
        duration_s: episode length [s].
        completed: missions completed (of ``len(seeds)``).
        route_error_max_m: worst route error of the formation centroid over seeds and steps [m].
        collisions_after_start: UAV-steps in collision after t = 0, summed over seeds.
        cost: realised J per UAV, mean over seeds (lower is better).
        reference: the reference's name (None: no reference flown).
        reference_completed: the reference's missions completed.
        reference_cost: the reference's realised J per UAV on the same seeds.
        training_reward: the trainer's last mean episode reward (its own transform), or None.
    """

    policy: str
    scenario: str
    seeds: tuple[int, ...]
    duration_s: float
    completed: int
    route_error_max_m: float
    collisions_after_start: int
    cost: float
    reference: str | None = None
    reference_completed: int | None = None
    reference_cost: float | None = None
    training_reward: float | None = None

    @property
    def cost_ratio(self) -> float | None:
        """``cost / reference_cost`` (1: as cheap as the reference; lower is better)."""
        if self.reference_cost is None or not self.reference_cost > 0:
            return None
        return self.cost / self.reference_cost

    def text(self) -> str:
        """A few lines for the end of a training run."""
        k = len(self.seeds)
        seeds = f"{self.seeds[0]}..{self.seeds[-1]}" if k > 1 else str(self.seeds[0])
        lines = [
            f"held-out mission of {self.policy} on {self.scenario!r}, seeds {seeds} "
            f"({self.duration_s:g} s episodes):",
            f"  completed {self.completed} of {k}; route error max {self.route_error_max_m:.1f} m; "
            f"collisions after t = 0: {self.collisions_after_start} UAV-steps",
        ]
        cost = f"  realised J per UAV {self.cost:.4g}"
        if self.cost_ratio is not None:
            assert self.reference is not None and self.reference_completed is not None
            cost += " = " + versus_reference(
                self.cost, self.reference, self.reference_cost, self.reference_completed, k
            )
        lines.append(cost)
        if self.training_reward is not None:
            lines.append(f"  training reward (the trainer's own scale): {self.training_reward:.4g}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready, with ``cost_ratio``."""
        data = asdict(self)
        data["seeds"] = list(self.seeds)
        data["cost_ratio"] = self.cost_ratio
        return data


def versus_reference(
    cost: float, reference: str, reference_cost: float, reference_completed: int, episodes: int
) -> str:
    """``"R x LFPIO's J_ref (which completed k of n; lower J is better)"``: a realised J per UAV
    against a reference's on the same seeds."""
    return (
        f"{cost / reference_cost:.3g} x {reference.upper()}'s {reference_cost:.4g} "
        f"(which completed {reference_completed} of {episodes}; lower J is better)"
    )


def _fly(scenario: Scenario, policy: BatchPolicy, seeds: Sequence[int], name: str, progress: bool):
    digests = fly_in_chunks(
        scenario,
        policy,
        list(seeds),
        HELDOUT_BATCH_SIZE,
        policy_name=name,
        progress=progress,
        desc=f"held out: {name}",
    )
    return summarise_digests(digests)


def heldout_report(
    scenario: Scenario,
    policy: BatchPolicy,
    seeds: Sequence[int] = HELDOUT_SEEDS,
    *,
    policy_name: str = "the trained policy",
    reference: str | None = "lfpio",
    duration: float | None = None,
    training_reward: float | None = None,
    out: str | Path | None = None,
    progress: bool = False,
) -> HeldoutReport:
    """Fly ``policy`` and ``reference`` on ``seeds`` of ``scenario`` and report the mission.

    Args:
        scenario: the scenario the policy was trained for (its observation layout).
        policy: a batch policy (``act_batch(obs (B, N, dim)) -> (B, N, 3)``).
        seeds: held-out seeds (>= 1 of them).
        policy_name: the policy's label.
        reference: a policy name of the registry flown on the same seeds (None: none).
        duration: episode length [s] (None: the scenario's).
        training_reward: the trainer's last mean episode reward, shown beside the mission.
        out: a run directory to write ``heldout.json`` into (None: nothing written).
        progress: progress bars over the steps.
    """
    seeds = tuple(int(s) for s in seeds)
    if not seeds:
        raise ValueError("seeds: give at least one held-out seed")
    if duration is not None:
        scenario = with_overrides(scenario, {"duration": float(duration)})
    summary = _fly(scenario, policy, seeds, policy_name, progress)
    mission = summary["mission"]
    worst = [e for e in mission["route_error_max_m_per_seed"] if e is not None]
    ref_completed = ref_cost = None
    if reference is not None:
        ref = _fly(scenario, make_policy(reference, scenario), seeds, reference, progress)
        ref_completed = int(ref["mission"]["completed"])
        ref_cost = float(ref["realised_cost_mean"])
    reward = None if training_reward is None else float(training_reward)
    report = HeldoutReport(
        policy=policy_name,
        scenario=scenario.name,
        seeds=seeds,
        duration_s=float(scenario.duration),
        completed=int(mission["completed"]),
        route_error_max_m=max(worst) if worst else math.nan,
        collisions_after_start=int(mission["collisions_after_start"]),
        cost=float(summary["realised_cost_mean"]),
        reference=reference,
        reference_completed=ref_completed,
        reference_cost=ref_cost,
        training_reward=reward if reward is None or math.isfinite(reward) else None,
    )
    if out is not None:
        path = Path(out) / HELDOUT_FILE
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(report.to_dict(), indent=2) + "\n", encoding="utf-8")
    return report


def report_run(
    out: str | Path,
    seeds: int = len(HELDOUT_SEEDS),
    *,
    training_reward: float | None = None,
    reference: str | None = "lfpio",
    progress: bool = False,
) -> HeldoutReport | None:
    """The end of a training run: fly the run directory ``out`` as ``uav-formation evaluate
    --policy out`` does (its model on its ``scenario.yaml``) and ``reference`` on held-out seeds
    0..seeds-1; write ``heldout.json``, print the report and return it (None when ``seeds`` is 0).
    """
    if seeds == 0:
        return None
    out = Path(out)
    # the run's own scenario under the evaluation's rules (acceleration actions, no corridor)
    scenario = evaluation_scenario(load_scenario(out / "scenario.yaml"))
    report = heldout_report(
        scenario,
        make_policy(str(out), scenario),
        range(int(seeds)),
        policy_name=str(out),
        reference=reference,
        training_reward=training_reward,
        out=out,
        progress=progress,
    )
    print(report.text())
    print(f"fly it again: uav-formation evaluate --policy {out} --seeds 10")
    return report
