"""Training callbacks: periodic evaluation with the package's runner, and checkpoints.

Every saved model goes into a directory of its own together with the observation statistics of
the same moment, because :class:`uav_formation_env.evaluation.SB3Policy` normalises a model's
observations with the statistics beside it: ``best/model.zip``, ``checkpoints/<steps>/``. They
are written twice: ``obs_stats.npz`` (plain arrays, what the evaluation reads) and SB3's
``vecnormalize.pkl`` (a pickle, to resume training with ``VecNormalize.load``).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback

from uav_formation_env.config import Scenario
from uav_formation_env.evaluation import SB3Policy, run_episodes, summarise
from uav_formation_env.policies.action_modes import in_acceleration_mode
from uav_formation_env.policies.learned import OBS_STATS_FILE, ObsStats
from uav_formation_env.tasks import evaluation_scenario

EVAL_KEYS = (
    "realised_cost_mean",
    "formation_rmse_m",
    "collisions",
    "min_separation_m",
    "min_obstacle_surface_distance_m",
)
NORMALIZER_FILE = "vecnormalize.pkl"


def live_policy(model: BaseAlgorithm) -> SB3Policy:
    """The model being trained as a batch policy for :func:`run_episodes`: the same computation
    as :class:`~uav_formation_env.evaluation.SB3Policy` on a saved model, without a round trip
    through files (the training VecNormalize's statistics are read, never updated)."""
    return SB3Policy.from_model(model, model.get_vec_normalize_env())


def save_run(model: BaseAlgorithm, directory: Path, name: str = "model") -> Path:
    """Save ``model`` as ``directory/name.zip`` and its VecNormalize beside it (as
    ``obs_stats.npz`` and ``vecnormalize.pkl``)."""
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / f"{name}.zip"
    model.save(path)
    normalizer = model.get_vec_normalize_env()
    if normalizer is not None:
        normalizer.save(str(directory / NORMALIZER_FILE))
        stats = ObsStats.of(normalizer)
        if stats is not None:
            stats.save(directory / OBS_STATS_FILE)
    return path


class FormationEvalCallback(BaseCallback):
    """Every ``eval_freq`` agent-steps, fly the deterministic policy on fixed seeds.

    Logs ``eval/<metric>`` for :data:`EVAL_KEYS` (SB3 logger: CSV, TensorBoard), appends a row
    to ``out/evaluations.csv`` and keeps the model of the lowest mean realised cost in
    ``out/best/``. (Ranking by collisions first picked poor early models that happened to fly
    the few evaluation seeds without a collision.)

    Args:
        scenario: the scenario trained on; evaluation flies it under the evaluation's rules
            (:func:`uav_formation_env.tasks.evaluation_scenario`), a velocity-mode policy
            through its set-point loop.
        seeds: one episode per seed, flown as one batch.
        eval_freq: agent-steps between evaluations (> 0).
        out: run directory.
        duration: episode length [s] (None: the scenario's).
    """

    def __init__(
        self,
        scenario: Scenario,
        seeds: list[int],
        eval_freq: int,
        out: Path,
        duration: float | None = None,
    ) -> None:
        super().__init__(verbose=0)
        self.trained = scenario
        self.scenario = evaluation_scenario(scenario)
        self.seeds = [int(s) for s in seeds]
        self.eval_freq = int(eval_freq)
        self.out = Path(out)
        self.duration = duration
        self.best = math.inf
        self.history: list[dict[str, Any]] = []
        self._last = 0

    def _on_training_start(self) -> None:
        # a fresh run in a reused directory must not inherit the old run's rows
        (self.out / "evaluations.csv").unlink(missing_ok=True)

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.eval_freq:
            self._last = self.num_timesteps
            self.evaluate()
        return True

    def _on_training_end(self) -> None:
        if self.num_timesteps != self._last:
            self._last = self.num_timesteps
            self.evaluate()

    def evaluate(self) -> dict[str, Any]:
        """One evaluation now; returns the summary row."""
        policy = in_acceleration_mode(
            live_policy(self.model), self.trained.episode, self.scenario.dynamics.u_max
        )
        summary = summarise(run_episodes(self.scenario, policy, self.seeds, duration=self.duration))
        row: dict[str, Any] = {"timesteps": self.num_timesteps}
        row.update({key: summary[key] for key in EVAL_KEYS})
        for key in EVAL_KEYS:
            if row[key] is not None:
                self.logger.record(f"eval/{key}", float(row[key]))
        self.logger.dump(self.num_timesteps)
        self.history.append(row)
        self._append_csv(row)
        score = float(row["realised_cost_mean"])
        if score < self.best:
            self.best = score
            save_run(self.model, self.out / "best")
        return row

    def _append_csv(self, row: dict[str, Any]) -> None:
        path = self.out / "evaluations.csv"
        new = not path.exists()
        with open(path, "a", newline="") as stream:
            writer = csv.DictWriter(stream, fieldnames=["timesteps", *EVAL_KEYS])
            if new:
                writer.writeheader()
            writer.writerow(row)


class CheckpointCallback(BaseCallback):
    """Every ``save_freq`` agent-steps, save ``out/checkpoints/<steps>/model.zip`` and its
    ``vecnormalize.pkl`` (SB3's own callback names the statistics file differently).

    Args:
        save_freq: agent-steps between checkpoints (> 0).
        out: run directory.
    """

    def __init__(self, save_freq: int, out: Path) -> None:
        super().__init__(verbose=0)
        self.save_freq = int(save_freq)
        self.out = Path(out)
        self._last = 0

    def _on_step(self) -> bool:
        if self.num_timesteps - self._last >= self.save_freq:
            self._last = self.num_timesteps
            save_run(self.model, self.out / "checkpoints" / f"{self.num_timesteps:09d}")
        return True
