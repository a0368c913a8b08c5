"""BenchMARL task for the formation env: run BenchMARL's algorithms on any named scenario.

One task per registered scenario of one N (:data:`uav_formation_env.config_io.SCENARIOS`):
``UavFormationTask.PAPER``, ``.OPEN_FIELD``, ``.WINDY``, ``.RANDOM_OBSTACLES``, ``.N3``, ``.N8``,
``.RANDOM_FIELDS``, ``.RANDOM_ROUTES``, ``.SWARM_20``, ``.SWARM_50``, ``.SWARM_100``; or
:func:`uav_formation_task` for a YAML path or any overrides. ``random_swarm`` draws N per
reset, and a TorchRL group has one shape, so it has no task here. The environment is TorchRL's
``PettingZooWrapper`` around :func:`uav_formation_env.parallel_env`, unpatched: one group
``"uav"`` of the N UAVs, observations (N, 47) for N = 5, continuous actions (N, 3) in [-1, 1],
the global state of ``state()`` for centralised critics (MAPPO, MADDPG, QMIX-like mixers), and the
numeric infos (cost terms, neighbours, ...) under ``("uav", "info")``.

The task's config (:class:`UavFormationTaskConfig`) puts the scenario under the training preset
by default (``reward="train"``: :data:`uav_formation_env.tasks.TRAINING_PRESET`, docs/training.md),
the same task the project's own trainer sees; ``reward="paper"`` keeps -J_i, whose per-episode
returns are -2e11..-4e12. Use BenchMARL's Python API with
``task=UavFormationTask.PAPER.get_task()`` (``examples/benchmarl_mappo.py`` is a runnable script;
its hydra command line only knows the tasks that ship inside benchmarl). Needs the
``[benchmarl]`` extra (benchmarl, torchrl, torch).

``backend="torch"`` (a task option) skips PettingZoo: the task's env is then the batched
:class:`~uav_formation_env.envs.torchrl_adapter.FormationTorchRLEnv` of ``num_envs`` copies on
BenchMARL's sampling device (the simulator, cost and observations as torch tensors, the same
numbers as numpy), which BenchMARL uses as a vectorised env (no SerialEnv of single copies).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from benchmarl.environments.common import Task, TaskClass
from benchmarl.utils import DEVICE_TYPING
from torchrl.data import Composite
from torchrl.envs import EnvBase
from torchrl.envs.libs.pettingzoo import PettingZooWrapper

from uav_formation_env import parallel_env
from uav_formation_env.envs import resolve_with_overrides, torchrl_env

__all__ = [
    "ENV_NAME",
    "UavFormationTask",
    "UavFormationTaskClass",
    "UavFormationTaskConfig",
    "uav_formation_task",
]

ENV_NAME = "uav_formation"
BACKENDS = ("pettingzoo", "torch")  # the task's env: one PettingZoo copy, or batched torch


@dataclass
class UavFormationTaskConfig:
    """The task's configuration (BenchMARL's ``TaskConfig``): the scenario and its overrides.

    Attributes:
        scenario: a registered scenario name (``"paper"``, ``"n3"``, ...) or a YAML path.
        reward: ``"train"`` (the training preset of :mod:`uav_formation_env.tasks`) or
            ``"paper"`` (the scenario's own reward, -J_i).
        duration: episode length [s]; None keeps the scenario's (200 s, 1000 steps, for the paper).
        overrides: any other scenario fields, as ``{"observer.enabled": False}``.
        return_state: expose the global state ``state()`` (for centralised critics).
        backend: ``"pettingzoo"`` (TorchRL's PettingZooWrapper of one copy, BenchMARL stacks
            copies) or ``"torch"`` (the batched torch-backend env, vectorised on the device).
    """

    scenario: str = "paper"
    reward: str = "train"
    duration: float | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    return_state: bool = True
    backend: str = "pettingzoo"

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")

    def scenario_overrides(self) -> dict[str, Any]:
        """The env overrides of this config (as for ``parallel_env(scenario, **overrides)``)."""
        overrides: dict[str, Any] = {"reward": self.reward}
        if self.duration is not None:
            overrides["duration"] = self.duration
        overrides.update(self.overrides)
        return overrides


def _task_config(config: dict[str, Any] | None) -> UavFormationTaskConfig:
    """``config`` (possibly partial) validated into a :class:`UavFormationTaskConfig`."""
    config = dict(config or {})
    known = {f.name for f in fields(UavFormationTaskConfig)}
    unknown = sorted(set(config) - known)
    if unknown:
        raise ValueError(f"unknown uav_formation task option(s) {unknown}; known: {sorted(known)}")
    return UavFormationTaskConfig(**config)


class UavFormationTaskClass(TaskClass):
    """BenchMARL ``TaskClass`` of a formation scenario (see the module docstring).

    Args:
        name: the task name (a registered scenario's name in upper case, or any label).
        config: a mapping of :class:`UavFormationTaskConfig` fields; missing ones take the
            defaults (the training devices on).
    """

    def __init__(self, name: str, config: dict[str, Any] | None) -> None:
        super().__init__(name=name, config=asdict(_task_config(config)))
        # the scenario, validated now: a bad name or override fails here, not in a worker
        self._scenario = resolve_with_overrides(
            self.settings.scenario, self.settings.scenario_overrides()
        )

    @property
    def settings(self) -> UavFormationTaskConfig:
        return _task_config(self.config)

    def get_env_fun(
        self,
        num_envs: int,
        continuous_actions: bool,
        seed: int | None,
        device: DEVICE_TYPING,
    ) -> Callable[[], EnvBase]:
        settings = copy.deepcopy(self.settings)
        scenario = self._scenario
        if settings.backend == "torch":  # vectorised: num_envs copies in one torch env

            def make_torch_env() -> EnvBase:
                return torchrl_env(
                    scenario, num_envs, device, seed, return_state=settings.return_state
                )

            return make_torch_env

        # Not vectorised: BenchMARL stacks num_envs copies in a SerialEnv / ParallelEnv.
        def make_env() -> EnvBase:
            return PettingZooWrapper(
                env=parallel_env(scenario),
                return_state=settings.return_state,
                seed=seed,
                device=device,
            )

        return make_env

    def supports_continuous_actions(self) -> bool:
        return True

    def supports_discrete_actions(self) -> bool:
        return False

    def has_render(self, env: EnvBase) -> bool:
        return False  # the top-view renderer is for figures, not evaluation videos

    def max_steps(self, env: EnvBase) -> int:
        return self._scenario.n_steps

    def group_map(self, env: EnvBase) -> dict[str, list[str]]:
        return env.group_map

    def _group_keys(self, env: EnvBase, keep: str) -> Composite | None:
        """The observation spec with only ``(group, keep)`` per group (no state), unbatched (as
        BenchMARL builds its models: a vectorised torch env's spec without the copy axis)."""
        spec = env.full_observation_spec_unbatched.clone()
        for group in self.group_map(env):
            group_spec = spec[group]
            for key in list(group_spec.keys()):
                if key != keep:
                    del group_spec[key]
            if group_spec.is_empty():
                del spec[group]
        if "state" in spec:
            del spec["state"]
        return None if spec.is_empty() else spec

    def observation_spec(self, env: EnvBase) -> Composite:
        return self._group_keys(env, "observation")

    def info_spec(self, env: EnvBase) -> Composite | None:
        return self._group_keys(env, "info")

    def state_spec(self, env: EnvBase) -> Composite | None:
        spec = env.full_observation_spec_unbatched
        if "state" in spec:
            return Composite({"state": spec["state"].clone()})
        return None

    def action_mask_spec(self, env: EnvBase) -> Composite | None:
        return None  # every UAV acts at every step

    def action_spec(self, env: EnvBase) -> Composite:
        return env.full_action_spec_unbatched

    @staticmethod
    def env_name() -> str:
        return ENV_NAME

    @staticmethod
    def log_info(batch) -> dict[str, float]:
        """The mean raw stage cost J per agent-step of the batch (whatever the reward)."""
        # .keys(): iterating a TensorDict itself runs over its batch dimension
        for group in batch.get("next").keys():  # noqa: SIM118
            key = ("next", group, "info", "J")
            if key in batch.keys(include_nested=True):
                return {f"collection/{group}/cost_J": batch.get(key).float().mean().item()}
        return {}


class UavFormationTask(Task):
    """The registered scenarios as BenchMARL tasks; ``get_task(config)`` takes
    :class:`UavFormationTaskConfig` fields (missing ones default; the scenario is the member's)."""

    PAPER = None
    HOLD = None
    TRACK = None
    OPEN_FIELD = None
    WINDY = None
    RANDOM_OBSTACLES = None
    N3 = None
    N8 = None
    RANDOM_FIELDS = None
    RANDOM_ROUTES = None
    SWARM_20 = None
    SWARM_50 = None
    SWARM_100 = None

    @staticmethod
    def associated_class():
        return UavFormationTaskClass

    def get_task(self, config: dict[str, Any] | None = None) -> UavFormationTaskClass:
        merged = {"scenario": self.name.lower(), **(config or {})}
        return UavFormationTaskClass(name=self.name, config=merged)

    def get_from_yaml(self, path: str | None = None) -> UavFormationTaskClass:
        """The task with the defaults, or with the config of the YAML file ``path``."""
        if path is None:
            return self.get_task()
        import yaml

        with open(path, encoding="utf-8") as handle:
            return self.get_task(yaml.safe_load(handle) or {})


def uav_formation_task(
    scenario: str = "paper", name: str | None = None, **config: Any
) -> UavFormationTaskClass:
    """A task for any scenario name or YAML path, with :class:`UavFormationTaskConfig` options,
    e.g. ``uav_formation_task("my_scenario.yaml", duration=60.0, reward="paper")``."""
    label = name or str(scenario).rsplit("/", 1)[-1].split(".")[0].upper()
    return UavFormationTaskClass(name=label, config={"scenario": str(scenario), **config})
