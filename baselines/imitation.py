"""Behaviour cloning with DAgger from the reference policy: a shared MLP that flies the mission.

    python -m uav_formation_baselines.imitation --scenario paper --out runs/bc_paper \
        [--seed 0] [--workers 4] [--device auto] [--set rounds=6 episodes=16 ...]
    python -m uav_formation_baselines.imitation --out runs/bc_paper --select 40

The teacher is a reference DMPC of the registry (``exact`` best response by default: the cheapest
per step, and no cheaper-looking than LFPIO on the mission). Round 0 flies the teacher's own
episodes and records (observation, teacher action) for every UAV and step; round r >= 1 flies the
learner of round r - 1, each copy and step executing the teacher's action with probability
``beta ** r`` and the learner's otherwise, and the teacher labels every visited observation
(DAgger, Ross et al. 2011): the learner is taught what to do where its own mistakes lead. After
each round the MLP (:class:`~uav_formation_baselines.torch_policy.NormalisedMLP`) is refitted on
everything gathered so far (mean squared error on the normalised action) and exported as the
policy directory ``rounds/<r>/`` (:mod:`uav_formation_env.policies.policy_file`); its validation
episodes are flown by the project's runner and scored with the mission metrics. The run's policy
(``policy.json`` + ``policy.npz``) is the round with the most completed validation missions (then
the lowest realised cost).

Training seeds start at ``seed_start`` (10,000), validation seeds at ``validation_seed_start``
(5,000), both apart from the held-out evaluation seeds (0-99) and the SB3 evaluation seeds (1000+).
A scene distribution with several N (``random_swarm``) is flown one group of equal N at a time,
and the learner must then use the N-independent observation (``observation.kind: local``).

The output directory holds the policy (load with ``uav-formation evaluate --policy DIR``),
``config.yaml`` (the resolved configuration, scenario name, seed, wall time), ``scenario.yaml``,
``rounds.csv`` (per round, written as each ends: samples, loss, validation completion and cost)
and ``rounds/``. ``--workers`` processes fly each round's episodes (the same data whatever their
number); ``--select SEEDS`` chooses a finished run's round again (:func:`select_round`).
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from uav_formation_baselines import HYPERPARAMS_DIR
from uav_formation_baselines.config import parse_set, scenario_sections
from uav_formation_baselines.imitation_data import collect, collect_in_workers, worker_pool
from uav_formation_baselines.imitation_select import (
    best_round,
    keep_round,
    select_round,
    validation_scores,
    write_rows,
)
from uav_formation_baselines.torch_policy import (
    ACTIVATIONS,
    NormalisedMLP,
    save_policy,
)
from uav_formation_env.cli import OneLineParser
from uav_formation_env.config import CostConfig, Scenario
from uav_formation_env.config_io import (
    resolve_scenario,
    save_scenario,
    with_overrides,
)
from uav_formation_env.evaluation.heldout import report_run
from uav_formation_env.policies import DMPC_OPTIMIZERS

__all__ = [
    "ImitationConfig",
    "best_round",
    "collect",
    "config_section",
    "load_config",
    "resolve_device",
    "sample_weights",
    "select_round",
    "teacher_scenario",
    "train_imitation",
]


@dataclass(frozen=True)
class ImitationConfig:
    """DAgger's settings (``baselines/hyperparams/bc.yml``, one section per scenario).

    Attributes:
        teacher: a reference DMPC solver name (``exact``, ``lfpio``, ...).
        teacher_threshold: the teacher's event-trigger threshold on J_i(W) [-]. 0 re-optimises
            every step, so each label is the best response to the state seen (the paper's 10
            executes the shifted old plan on ~63 % of steps, a function of the past); on 4 paper
            seeds the exact teacher's realised J was 7.270e5 at 0 and 7.278e5 at 10.
        rounds: data-gathering rounds (round 0 the teacher's own episodes) [-].
        episodes: episodes flown per round [-].
        start_episodes: extra episodes per round flown only for their first
            ``start_duration``: more start geometries (UAVs converging from the start box into
            formation, where a clone's errors become collisions) for the price of a few full
            episodes [-].
        start_duration: how long those episodes are flown [s].
        beta: the teacher executes with probability ``beta ** r`` in round r [-].
        duration: episode length [s] (None: the scenario's).
        hidden: hidden layer widths of the MLP.
        activation: its activation (a key of ``torch_policy.ACTIVATIONS``).
        epochs: passes over the aggregated data per round [-].
        batch_size: samples per gradient step [-].
        learning_rate: Adam's step size [-].
        masked_slots: observation slots the network never sees (e.g. 12, the time t / duration:
            with it, the MLP can learn the teacher's actions as a schedule in time rather than
            a feedback law).
        proximity_weight: loss weight of the UAV-steps where another UAV is nearer than the
            separation distance d_s (``cost.separation_distance``, where the teacher's
            separation term acts) [-]; 1 weighs every step alike. Those steps are rare (the
            start transient) and are where a clone's small errors become collisions.
        obstacle_margin: the steps of a UAV nearer than this to an obstacle's surface are
            weighted ``proximity_weight`` too (0: only the UAV-UAV rule) [m]. Clones that
            failed a mission by a step inside an obstacle grazed it while avoiding.
        validation_seeds: validation episodes per round [-].
        seed_start, validation_seed_start: first training / validation episode seed.
        overrides: scenario field overrides (e.g. ``{observation: {kind: local}}``).
        teacher_cost: overrides of the teacher's own J_i (``cost`` fields, e.g. J_i's obstacle
            clearance term ``{obstacle: 100, obstacle_lookahead: 10}``); the environment, its
            reward and the evaluation keep the scenario's. A clone's small action errors turn a
            teacher's grazing pass into a collision: on the 20 paper seeds the exact teacher
            passes O1 (radius 30 m) 31.5 m from its centre at the closest, and 39.2 m with the
            clearance term, at a lower paper J (6.55e5 against 7.35e5).
        shield: the learner flies its DAgger episodes and its validation behind the safety
            shield (:class:`~uav_formation_env.policies.shield.SafetyShield`, local layout
            only): it learns the teacher's answer in the states the shield leads to, and is
            meant to be flown with ``--shield``.
    """

    teacher: str = "exact"
    teacher_threshold: float = 0.0
    rounds: int = 6
    episodes: int = 16
    start_episodes: int = 0
    start_duration: float = 20.0
    beta: float = 0.5
    duration: float | None = None
    hidden: tuple[int, ...] = (256, 256)
    activation: str = "tanh"
    epochs: int = 15
    batch_size: int = 2048
    learning_rate: float = 1e-3
    masked_slots: tuple[int, ...] = ()
    proximity_weight: float = 1.0
    obstacle_margin: float = 0.0
    validation_seeds: int = 4
    seed_start: int = 10_000
    validation_seed_start: int = 5_000
    overrides: dict[str, Any] = field(default_factory=dict)
    teacher_cost: dict[str, Any] = field(default_factory=dict)
    shield: bool = False

    def __post_init__(self) -> None:
        if self.teacher not in DMPC_OPTIMIZERS:
            raise ValueError(
                f"teacher must be one of {list(DMPC_OPTIMIZERS)}, got {self.teacher!r}"
            )
        if (
            isinstance(self.start_episodes, bool)
            or not isinstance(self.start_episodes, int)
            or (self.start_episodes < 0)
        ):
            raise ValueError(f"start_episodes must be an integer >= 0, got {self.start_episodes!r}")
        if not self.start_duration > 0:
            raise ValueError(f"start_duration must be > 0 [s], got {self.start_duration!r}")
        for name in ("rounds", "episodes", "epochs", "batch_size", "validation_seeds"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        for name in ("seed_start", "validation_seed_start"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise ValueError(f"{name} must be an integer >= 0, got {value!r}")
        if not np.isfinite(self.teacher_threshold) or self.teacher_threshold < 0:
            raise ValueError(f"teacher_threshold must be >= 0, got {self.teacher_threshold!r}")
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta must lie in [0, 1], got {self.beta!r}")
        if not self.proximity_weight >= 1.0:
            raise ValueError(f"proximity_weight must be >= 1, got {self.proximity_weight!r}")
        if not self.obstacle_margin >= 0:
            raise ValueError(f"obstacle_margin must be >= 0 [m], got {self.obstacle_margin!r}")
        if not isinstance(self.shield, bool):
            raise ValueError(f"shield must be true or false, got {self.shield!r}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be > 0, got {self.learning_rate!r}")
        if self.duration is not None and not self.duration > 0:
            raise ValueError(f"duration must be > 0 [s] or None, got {self.duration!r}")
        if self.activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}")
        hidden = tuple(self.hidden)
        if not hidden or any(
            isinstance(h, bool) or not isinstance(h, int) or h < 1 for h in hidden
        ):
            raise ValueError(f"hidden must be a list of integers >= 1, got {self.hidden!r}")
        object.__setattr__(self, "hidden", hidden)
        object.__setattr__(self, "masked_slots", tuple(int(s) for s in self.masked_slots))
        cost_fields = {f.name for f in fields(CostConfig)}
        if not isinstance(self.teacher_cost, dict) or not set(self.teacher_cost) <= cost_fields:
            raise ValueError(
                f"teacher_cost must map cost fields ({sorted(cost_fields)}) to values, "
                f"got {self.teacher_cost!r}"
            )

    @classmethod
    def from_mapping(
        cls, values: dict[str, Any], where: str = "the configuration"
    ) -> ImitationConfig:
        """A config from a mapping; an unknown key is a ``ValueError`` naming it."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown key {unknown[0]!r} in {where}; known keys: {sorted(known)}")
        return cls(**values)


def config_section(scenario: str | Path) -> str:
    """The YAML section a scenario reads: its registered name, ``default`` for a YAML path."""
    return "default" if str(scenario).endswith((".yaml", ".yml")) else str(scenario)


def load_config(scenario_key: str, path: str | Path | None = None, **patch: Any) -> ImitationConfig:
    """The ``default`` section of the YAML (``baselines/hyperparams/bc.yml``), the scenario's
    section over it, then ``patch``."""
    path = Path(path) if path is not None else HYPERPARAMS_DIR / "bc.yml"
    table = scenario_sections(path)
    values = {**(table.get("default") or {}), **(table.get(scenario_key) or {}), **patch}
    return ImitationConfig.from_mapping(values, where=str(path))


def teacher_scenario(scenario: Scenario, config: ImitationConfig) -> Scenario:
    """The scenario the teacher plans with: ``scenario`` with ``config.teacher_cost`` over its
    cost (an unknown cost field is a ``ValueError`` naming it)."""
    if not config.teacher_cost:
        return scenario
    return with_overrides(scenario, {"cost": dict(config.teacher_cost)})


def sample_weights(
    nearest: np.ndarray,
    clearance: np.ndarray,
    scenario: Scenario,
    config: ImitationConfig,
) -> np.ndarray:
    """(M,) loss weights: ``config.proximity_weight`` where another UAV is nearer than the
    separation distance d_s or an obstacle's surface nearer than ``config.obstacle_margin`` [m],
    else 1."""
    close = (nearest < scenario.cost.separation_distance) | (clearance < config.obstacle_margin)
    return np.where(close, config.proximity_weight, 1.0)


def fit(
    model: NormalisedMLP,
    obs: np.ndarray,
    actions: np.ndarray,
    config: ImitationConfig,
    seed: int,
    weights: np.ndarray | None = None,
    device: str = "cpu",
) -> float:
    """``config.epochs`` passes of Adam on the (weighted) mean squared error of the mean action
    against the teacher's; ``weights`` (M,) per sample (None: 1); returns the last epoch's mean
    weighted loss. The model is fitted on ``device`` and left on the CPU (the batches' order
    comes from a CPU generator, so it is the same on every device)."""
    import torch

    generator = torch.Generator().manual_seed(seed)
    inputs = torch.as_tensor(obs, device=device)
    targets = torch.as_tensor(actions, device=device)
    sample_weight = (
        torch.ones(len(inputs), device=device)
        if weights is None
        else torch.as_tensor(np.asarray(weights, dtype=np.float32), device=device)
    )
    model.to(device)
    optimiser = torch.optim.Adam(model.net.parameters(), lr=config.learning_rate)
    # cosine decay to 0 over the round: the last weights are not a noisy SGD iterate, which
    # matters in closed loop (without it, validation completion jumped between rounds)
    batches = config.epochs * -(-len(inputs) // config.batch_size)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=batches)
    model.train()
    for _ in range(config.epochs):
        order = torch.randperm(len(inputs), generator=generator).to(device)
        # summed on the device: reading each batch's loss back would wait for the GPU every step
        loss_sum = torch.zeros((), dtype=torch.float64, device=device)
        for start in range(0, len(order), config.batch_size):
            index = order[start : start + config.batch_size]
            error = ((model.mean_action(inputs[index]) - targets[index]) ** 2).mean(dim=-1)
            weight = sample_weight[index]
            loss = (weight * error).sum() / weight.sum()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
            loss_sum += loss.detach().double() * len(index)
    model.to("cpu")
    model.eval()
    return float(loss_sum) / len(inputs)


def train_imitation(
    scenario: str | Path | Scenario,
    out: str | Path,
    config: ImitationConfig,
    seed: int = 0,
    threads: int = 1,
    progress: bool = True,
    workers: int = 1,
    device: str = "auto",
) -> dict[str, Any]:
    """DAgger (see the module docstring); writes ``out`` and returns the run's record.

    ``threads``: torch CPU threads of this process; ``workers``: processes that fly and label
    each round's episodes (:func:`~uav_formation_baselines.imitation_data.collect_in_workers`:
    the same data whatever the number); ``device``: where the MLP is fitted (``auto``: CUDA when
    present, else the CPU)."""
    fit_device = resolve_device(device)
    pool = worker_pool(workers)  # checks ``workers`` before anything is written
    try:
        return _train(scenario, out, config, seed, threads, progress, workers, pool, fit_device)
    finally:
        if pool is not None:
            pool.shutdown()


def resolve_device(device: str) -> str:
    """``auto`` -> ``cuda`` when torch sees a GPU, else ``cpu``; ``cpu`` and ``cuda[:k]`` as given
    (``cuda`` without a GPU is a ``ValueError``)."""
    import torch

    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cpu" or str(device).startswith("cuda"):
        if str(device).startswith("cuda") and not torch.cuda.is_available():
            raise ValueError(f"device {device!r} asked for, but torch sees no CUDA device")
        return str(device)
    raise ValueError(f"device must be 'auto', 'cpu' or 'cuda[:k]', got {device!r}")


def _train(
    scenario: str | Path | Scenario,
    out: str | Path,
    config: ImitationConfig,
    seed: int,
    threads: int,
    progress: bool,
    workers: int,
    pool: Any,
    fit_device: str,
) -> dict[str, Any]:
    import torch

    torch.set_num_threads(int(threads))
    torch.manual_seed(seed)
    scen = resolve_scenario(scenario)
    patch = dict(config.overrides)
    if config.duration is not None:
        patch["duration"] = float(config.duration)
    scen = with_overrides(scen, patch) if patch else scen
    out = Path(out)
    (out / "rounds").mkdir(parents=True, exist_ok=True)
    save_scenario(scen, out / "scenario.yaml")
    teacher_scen = teacher_scenario(scen, config)
    started = time.perf_counter()
    validation = list(
        range(config.validation_seed_start, config.validation_seed_start + config.validation_seeds)
    )
    all_obs: list[np.ndarray] = []
    all_actions: list[np.ndarray] = []
    all_weights: list[np.ndarray] = []
    model: NormalisedMLP | None = None
    learner_path: str | None = None  # the last round's export: workers load it by path
    rows: list[dict[str, Any]] = []
    start_steps = max(1, round(config.start_duration / scen.dynamics.dt))
    for r in range(config.rounds):
        base = config.seed_start + seed * 100_000
        parts = [(None, base + r * config.episodes, config.episodes)]
        if config.start_episodes:  # seeds of their own, apart from the full episodes'
            parts.append(
                (start_steps, base + 50_000 + r * config.start_episodes, config.start_episodes)
            )
        for part, (steps, first, count) in enumerate(parts):
            obs, actions, nearest, clearance = collect_in_workers(
                pool,
                workers,
                list(range(first, first + count)),
                scenario=scen,
                teacher_name=config.teacher,
                teacher_threshold=config.teacher_threshold,
                learner=learner_path,
                teacher_probability=config.beta**r if r else 1.0,
                mix_seed=seed * 1000 + 10 * r + part,
                n_steps=steps,
                teacher_scenario=teacher_scen,
                shield=config.shield,
            )
            all_obs.append(obs)
            all_actions.append(actions)
            all_weights.append(sample_weights(nearest, clearance, scen, config))
        data_obs, data_actions = np.concatenate(all_obs), np.concatenate(all_actions)
        if model is None:  # normalise by the teacher's own state distribution, fixed afterwards
            model = NormalisedMLP(
                data_obs.mean(axis=0),
                data_obs.std(axis=0),
                config.hidden,
                config.activation,
                masked_slots=config.masked_slots,
            )
        loss = fit(
            model,
            data_obs,
            data_actions,
            config,
            seed * 1000 + r,
            np.concatenate(all_weights),
            device=fit_device,
        )
        path = save_policy(
            model,
            out / "rounds" / str(r),
            data_obs[:64],
            observation=scen.observation.kind,
            metadata={"scenario": scen.name, "algorithm": "dagger", "round": r, "seed": seed},
        )
        learner_path = str(path)
        row = {
            "round": r,
            "samples": len(data_obs),
            "close_fraction": float(np.mean(np.concatenate(all_weights) > 1.0)),
            "loss": loss,
            "teacher_probability": config.beta**r if r else 1.0,
            **validation_scores(scen, learner_path, validation, pool, workers, config.shield),
            "seconds": time.perf_counter() - started,
        }
        rows.append(row)
        write_rows(out / "rounds.csv", rows)  # each round: a stopped run keeps its table
        if progress:
            print(
                f"round {r}: {row['samples']} samples, loss {loss:.4g}, validation "
                f"{row['validation_completed']}/{row['validation_episodes']} completed, "
                f"J {row['validation_cost']:.4g}, route error max "
                f"{row['validation_route_error_max_m']:.1f} m, {row['seconds']:.0f} s",
                flush=True,
            )
    best = best_round(rows)
    keep_round(out, best["round"])
    record = {
        "algorithm": "dagger",
        "scenario": scen.name,
        "seed": seed,
        "config": {
            **asdict(config),
            "hidden": list(config.hidden),
            "masked_slots": list(config.masked_slots),
        },
        "best_round": best["round"],
        "agent_steps": int(sum(len(o) for o in all_obs)),
        "wall_time_s": time.perf_counter() - started,
        "torch_threads": int(threads),
        "workers": int(workers),
        "fit_device": fit_device,
    }
    with open(out / "config.yaml", "w", encoding="utf-8") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)
    return record


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--seed", type=int, default=0, help="run seed (network, seeds, coins)")
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument(
        "--workers", type=int, default=1, help="processes flying each round's episodes"
    )
    parser.add_argument(
        "--device",
        default="auto",
        help="where the MLP is fitted: auto (CUDA if present), cpu, cuda",
    )
    parser.add_argument("--config", default=None, help="YAML (default: hyperparams/bc.yml)")
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="configuration overrides, values parsed as YAML",
    )
    parser.add_argument("--quiet", action="store_true", help="no per-round lines")
    parser.add_argument(
        "--select",
        type=int,
        default=None,
        metavar="SEEDS",
        help="do not train: choose the finished run's round again on this many validation "
        "seeds (select_round)",
    )
    parser.add_argument(
        "--heldout-seeds",
        type=int,
        default=3,
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    args = parser.parse_args(argv)
    try:
        if args.select is not None:
            best = select_round(args.out, args.select, workers=args.workers)
            done = (
                f"(round {best['round']}: {best['validation_completed']}/"
                f"{best['validation_episodes']} validation missions, "
                f"J {best['validation_cost']:.4g})"
            )
        else:
            config = load_config(config_section(args.scenario), args.config, **parse_set(args.set))
            record = train_imitation(
                args.scenario,
                args.out,
                config,
                args.seed,
                args.threads,
                progress=not args.quiet,
                workers=args.workers,
                device=args.device,
            )
            done = (
                f"(round {record['best_round']}), {record['agent_steps']} agent-steps in "
                f"{record['wall_time_s']:.0f} s"
            )
    except (ValueError, FileNotFoundError, KeyError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    print(f"wrote the policy of {args.out} {done}")
    if args.select is None:  # a new policy: its mission on held-out seeds
        report_run(args.out, args.heldout_seeds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
