"""Train BenchMARL's MAPPO, IPPO or MASAC on a formation scenario and export the shared actor.

    python -m uav_formation_baselines.benchmarl_train --algo mappo --scenario paper \
        --out runs/mappo_paper [--seed 0] [--set frames=600000 lr=3e-4 ...]

The task is :class:`~uav_formation_baselines.benchmarl_task.UavFormationTaskClass` with the
episode layer's training options (``task`` in the YAML: reward transform, divergence truncation,
mission corridor), on the batched torch env by default (no PettingZoo, the same numbers as
numpy). Settings live in ``baselines/hyperparams/benchmarl.yml``: a ``default`` section, one
per algorithm over it, ``--set`` last; unknown keys are errors naming the key. Every UAV shares
one actor (BenchMARL's ``share_policy_params``), so the trained actor flies any copy.

The output directory holds the actor as a policy file (``policy.json`` + ``policy.npz``: the
mean action ``tanh(loc)`` of BenchMARL's TanhNormal, which is its deterministic action; load with
``uav-formation evaluate --policy DIR``), ``config.yaml`` (settings, seed,
frames, wall time), ``scenario.yaml``, ``progress.csv`` (per iteration: frames, mean episode
reward, seconds) and BenchMARL's own experiment folder ``benchmarl/``.
"""

from __future__ import annotations

import copy
import csv
import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml
from torch import nn

from uav_formation_baselines import HYPERPARAMS_DIR
from uav_formation_baselines.config import parse_set
from uav_formation_baselines.torch_policy import ACTIVATIONS, save_policy
from uav_formation_env.cli import OneLineParser
from uav_formation_env.config_io import save_scenario
from uav_formation_env.evaluation.heldout import report_run

__all__ = [
    "ALGORITHMS",
    "BenchmarlRunConfig",
    "export_actor",
    "formation_task",
    "load_config",
    "make_experiment",
    "train_benchmarl",
]

ALGORITHMS = ("mappo", "ippo", "masac")
ON_POLICY = ("mappo", "ippo")


@dataclass(frozen=True)
class BenchmarlRunConfig:
    """One BenchMARL run (``baselines/hyperparams/benchmarl.yml``).

    Attributes:
        frames: env steps to collect in all (one step of one copy moves its N UAVs) [-].
        frames_per_batch: env steps per collection (per iteration) [-].
        envs: copies of the batched env [-].
        lr: Adam's step size [-].
        hidden: actor and critic hidden widths.
        activation: a key of ``torch_policy.ACTIVATIONS``.
        minibatch, minibatch_iters: on-policy minibatch size (env steps) and passes [-].
        train_batch, optimizer_steps, memory: off-policy batch size, gradient steps per
            iteration and replay capacity (env steps) [-].
        gamma: discount [-].
        eval_episodes: episodes of BenchMARL's evaluation (deterministic actions) at the first
            and last iteration, written as marl-eval JSON (``create_json``) into BenchMARL's
            experiment folder; 0 = no evaluation [-].
        task: options of the task (``UavFormationTaskConfig``: scenario overrides, reward,
            divergence and corridor, backend).
    """

    frames: int = 600_000
    frames_per_batch: int = 6_000
    envs: int = 10
    lr: float = 3e-4
    hidden: tuple[int, ...] = (256, 256)
    activation: str = "tanh"
    minibatch: int = 400
    minibatch_iters: int = 10
    train_batch: int = 512
    optimizer_steps: int = 200
    memory: int = 300_000
    gamma: float = 0.99
    eval_episodes: int = 0
    task: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = (
            "frames",
            "frames_per_batch",
            "envs",
            "minibatch",
            "minibatch_iters",
            "train_batch",
            "optimizer_steps",
            "memory",
        )
        for name in names:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if isinstance(self.eval_episodes, bool) or not isinstance(self.eval_episodes, int):
            raise ValueError(f"eval_episodes must be an integer >= 0, got {self.eval_episodes!r}")
        if self.eval_episodes < 0:
            raise ValueError(f"eval_episodes must be an integer >= 0, got {self.eval_episodes!r}")
        if self.frames_per_batch % self.envs:
            raise ValueError(
                f"frames_per_batch ({self.frames_per_batch}) must be a multiple of envs "
                f"({self.envs})"
            )
        if not self.lr > 0:
            raise ValueError(f"lr must be > 0, got {self.lr!r}")
        if not 0 < self.gamma <= 1:
            raise ValueError(f"gamma must lie in (0, 1], got {self.gamma!r}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}")
        object.__setattr__(self, "hidden", tuple(int(h) for h in self.hidden))


def load_config(algo: str, path: str | Path | None = None, **patch: Any) -> BenchmarlRunConfig:
    """``default``, then the algorithm's section, then ``patch`` (``task`` merged key by key)."""
    if algo not in ALGORITHMS:
        raise ValueError(f"algo must be one of {list(ALGORITHMS)}, got {algo!r}")
    path = Path(path) if path is not None else HYPERPARAMS_DIR / "benchmarl.yml"
    with open(path, encoding="utf-8") as stream:
        table = yaml.safe_load(stream) or {}
    values: dict[str, Any] = {}
    for part in (table.get("default") or {}, table.get(algo) or {}, patch):
        task = {**values.get("task", {}), **(part.get("task") or {})}
        values.update(part)
        values["task"] = task
    known = {f.name for f in fields(BenchmarlRunConfig)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown key {unknown[0]!r} in {path}; known keys: {sorted(known)}")
    return BenchmarlRunConfig(**values)


def formation_task(scenario: str, config: BenchmarlRunConfig) -> Any:
    """The BenchMARL task of a scenario with ``config.task``'s options (batched torch env unless
    ``task.backend`` says otherwise)."""
    from uav_formation_baselines.benchmarl_task import uav_formation_task

    return uav_formation_task(scenario, **{"backend": "torch", **config.task})


def make_experiment(
    algo: str, task: Any, config: BenchmarlRunConfig, seed: int, folder: str | Path
) -> Any:
    """A BenchMARL ``Experiment`` of ``algo`` on any BenchMARL ``task`` (ours or a peer's, for the
    same-run benchmark) with the settings of ``config``, on CPU, CSV logging into ``folder``."""
    from benchmarl.algorithms import IppoConfig, MappoConfig, MasacConfig
    from benchmarl.experiment import Experiment, ExperimentConfig
    from benchmarl.models.mlp import MlpConfig

    experiment_config = ExperimentConfig.get_from_yaml()
    experiment_config.sampling_device = experiment_config.train_device = "cpu"
    experiment_config.buffer_device = "cpu"
    experiment_config.max_n_frames, experiment_config.max_n_iters = config.frames, None
    experiment_config.lr, experiment_config.gamma = config.lr, config.gamma
    experiment_config.on_policy_collected_frames_per_batch = config.frames_per_batch
    experiment_config.on_policy_n_envs_per_worker = config.envs
    experiment_config.on_policy_minibatch_size = config.minibatch
    experiment_config.on_policy_n_minibatch_iters = config.minibatch_iters
    experiment_config.off_policy_collected_frames_per_batch = config.frames_per_batch
    experiment_config.off_policy_n_envs_per_worker = config.envs
    experiment_config.off_policy_train_batch_size = config.train_batch
    experiment_config.off_policy_n_optimizer_steps = config.optimizer_steps
    experiment_config.off_policy_memory_size = config.memory
    experiment_config.render = False
    # marl-eval's JSON (BenchMARL's create_json) holds the evaluations: first and last iteration
    evaluate = config.eval_episodes > 0
    experiment_config.evaluation = experiment_config.create_json = evaluate
    experiment_config.evaluation_episodes = max(config.eval_episodes, 1)
    batches = -(-config.frames // config.frames_per_batch)  # iterations, rounded up
    experiment_config.evaluation_interval = batches * config.frames_per_batch
    experiment_config.evaluation_deterministic_actions = True
    experiment_config.loggers = ["csv"]
    experiment_config.checkpoint_interval = 0
    experiment_config.checkpoint_at_end = False
    experiment_config.save_folder = str(folder)
    algorithms = {"mappo": MappoConfig, "ippo": IppoConfig, "masac": MasacConfig}
    model = MlpConfig(
        num_cells=list(config.hidden),
        activation_class=ACTIVATIONS[config.activation],
        layer_class=nn.Linear,
    )
    return Experiment(
        task=task,
        algorithm_config=algorithms[algo].get_from_yaml(),
        model_config=model,
        critic_model_config=model,
        seed=seed,
        config=experiment_config,
    )


class TanhNormalActor(nn.Module):
    """BenchMARL's shared actor as a plain module: MLP -> (loc, scale) -> ``[tanh(loc),
    log(scale)]`` (M, 6), the deterministic action of its TanhNormal on [-1, 1]."""

    def __init__(self, net: nn.Sequential, scale_mapping: nn.Module) -> None:
        super().__init__()
        self.net = net
        self.scale_mapping = scale_mapping

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        logits = self.net(obs)
        loc, raw_scale = logits[..., :3], logits[..., 3:]
        scale = self.scale_mapping(raw_scale).clamp_min(1e-4)
        return torch.cat([torch.tanh(loc), torch.log(scale)], dim=-1)


def actor_module(experiment: Any) -> TanhNormalActor:
    """The shared actor of a BenchMARL experiment (``share_policy_params``) as a
    :class:`TanhNormalActor` on CPU (weights copied)."""
    from benchmarl.models.mlp import Mlp
    from tensordict.nn.distributions import NormalParamExtractor

    mlps = [m for m in experiment.policy.modules() if isinstance(m, Mlp)]
    extractors = [m for m in experiment.policy.modules() if isinstance(m, NormalParamExtractor)]
    if len(mlps) != 1 or len(extractors) != 1:
        raise ValueError("expected one Mlp actor and one NormalParamExtractor in the policy")
    agents_mlp = mlps[0].mlp
    if not getattr(agents_mlp, "share_params", False):
        raise ValueError("the actor does not share its parameters across agents")
    state = {k: v.detach().cpu().clone() for k, v in agents_mlp.params.flatten_keys(".").items()}
    layers: list[nn.Module] = []
    for index, child in enumerate(agents_mlp._empty_net.children()):
        if isinstance(child, nn.Linear):  # its parameters live in ``params`` (meta here)
            weight = state[f"{index}.weight"]
            layers.append(nn.Linear(weight.shape[1], weight.shape[0]))
        else:
            layers.append(copy.deepcopy(child).cpu())
    net = nn.Sequential(*layers)
    net.load_state_dict(state)
    return TanhNormalActor(net, copy.deepcopy(extractors[0].scale_mapping).cpu()).eval()


def export_actor(
    experiment: Any, path: str | Path, sample: np.ndarray, observation: str = "full"
) -> Path:
    """Save the experiment's shared actor as a policy file in directory ``path`` (checked on
    ``sample`` (M, dim) observations): its MLP's ``loc`` outputs, squashed by tanh."""
    return save_policy(
        actor_module(experiment).net, path, sample, observation=observation, action="tanh"
    )


def train_benchmarl(
    algo: str,
    scenario: str,
    out: str | Path,
    config: BenchmarlRunConfig,
    seed: int = 0,
    threads: int = 1,
) -> dict[str, Any]:
    """One run (see the module docstring); returns its record (also ``config.yaml``)."""
    from uav_formation_env.envs import resolve_with_overrides

    torch.set_num_threads(int(threads))
    out = Path(out)
    folder = out / "benchmarl"
    folder.mkdir(parents=True, exist_ok=True)
    experiment = make_experiment(algo, formation_task(scenario, config), config, seed, folder)
    progress: list[dict[str, Any]] = []
    started = time.perf_counter()

    def on_batch(batch: Any) -> None:  # BenchMARL's per-iteration callback hook
        reward = batch.get(("next", "uav", "reward"))
        progress.append(
            {
                "iteration": len(progress),
                "frames": (len(progress) + 1) * config.frames_per_batch,
                "mean_reward_per_uav_step": float(reward.mean()),
                "seconds": time.perf_counter() - started,
            }
        )

    from benchmarl.experiment.callback import Callback

    class Progress(Callback):
        def on_batch_collected(self, batch: Any) -> None:
            on_batch(batch)

    experiment.callbacks.append(Progress())
    experiment.callbacks[-1].experiment = experiment
    experiment.run()
    seconds = time.perf_counter() - started
    task = experiment.task
    scen = resolve_with_overrides(task.settings.scenario, task.settings.scenario_overrides())
    save_scenario(scen, out / "scenario.yaml")
    from uav_formation_env.episode import FormationEpisodes

    sample = FormationEpisodes(scen, 2).reset(seed=[0, 1]).observation
    sample = sample.reshape(-1, sample.shape[-1])
    export_actor(experiment, out, sample, scen.observation.kind)
    with open(out / "progress.csv", "w", newline="", encoding="utf-8") as stream:
        writer = csv.DictWriter(
            stream, fieldnames=["iteration", "frames", "mean_reward_per_uav_step", "seconds"]
        )
        writer.writeheader()
        writer.writerows(progress)
    record = {
        "algorithm": algo,
        "scenario": scenario,
        "seed": seed,
        "config": {**asdict(config), "hidden": list(config.hidden)},
        "frames": int(experiment.total_frames),
        "agent_steps": int(experiment.total_frames) * scen.n_uav,
        "wall_time_s": seconds,
        "torch_threads": int(threads),
        # the transformed reward per UAV-step of the last batch (None: no batch)
        "final_reward_per_uav_step": progress[-1]["mean_reward_per_uav_step"] if progress else None,
    }
    with open(out / "config.yaml", "w", encoding="utf-8") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)
    return record


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n")[0])
    parser.add_argument("--algo", required=True, choices=ALGORITHMS)
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--config", default=None, help="YAML (default: benchmarl.yml)")
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="overrides, values parsed as YAML (task.reward=raw, frames=...)",
    )
    parser.add_argument(
        "--heldout-seeds",
        type=int,
        default=3,
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    args = parser.parse_args(argv)
    try:
        config = load_config(args.algo, args.config, **parse_set(args.set))
        record = train_benchmarl(
            args.algo, args.scenario, args.out, config, args.seed, args.threads
        )
    except (ValueError, FileNotFoundError, KeyError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(
        f"wrote the policy {args.out}: {record['frames']} frames in {record['wall_time_s']:.0f} s"
    )
    report_run(args.out, args.heldout_seeds, training_reward=record["final_reward_per_uav_step"])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
