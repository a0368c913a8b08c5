"""Hyper-parameters of the on-policy trainer (:mod:`uav_formation_baselines.onpolicy`).

One YAML (``baselines/hyperparams/onpolicy.yml``) holds a ``default`` section and one optional
section per algorithm (``ppo``, ``mappo``, ``ippo``) merged over it; ``--set key=value`` overrides
are merged last (dotted keys reach into mappings, values parsed as YAML, as in
:func:`uav_formation_baselines.config.parse_set`). The result is an :class:`OnPolicyConfig`:
frozen, validated, and any key it does not know is a ``ValueError`` naming the key.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from uav_formation_baselines import HYPERPARAMS_DIR
from uav_formation_baselines.config import apply_overrides

ONPOLICY_ALGOS = ("ppo", "mappo", "ippo")
ONPOLICY_ACTIVATIONS = ("tanh", "relu", "elu", "gelu", "silu")  # the policy file's activations


@dataclass(frozen=True)
class OnPolicyConfig:
    """Every hyper-parameter of one on-policy run (units: agent-steps, where counts).

    A rollout is ``rollout_steps`` control steps of ``copies`` scenario copies of N UAVs, so
    ``rollout_steps * copies * N`` agent-steps (frames); each update runs ``epochs`` passes of
    ``minibatches`` minibatches over its (step, copy, agent) rows ((step, copy) rows for
    ``ippo``, whose per-agent networks see all N agents of a row).
    """

    copies: int = 256  # scenario copies B
    rollout_steps: int = 32  # control steps per rollout
    epochs: int = 4
    minibatches: int = 4
    learning_rate: float = 3.0e-4
    anneal_lr: bool = True  # linear decay to 0 over the run
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_coef: float = 0.2
    clip_vloss: bool = False
    value_norm: bool = True  # critic targets normalised by running return statistics
    # bootstrap a copy truncated by the divergence bounds like one at the time limit (false: its
    # return ends there, as if terminated: a diverged state the critic never trained on gives
    # no extrapolated value)
    bootstrap_diverged: bool = True
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    norm_adv: bool = True
    target_kl: float | None = None  # stop an update's epochs beyond this approximate KL
    hidden: tuple[int, ...] = (64, 64)
    activation: str = "tanh"
    log_std_init: float = -1.0  # initial log std of the normalised action
    obs_clip: float = 10.0  # clip of the normalised observation (and state)
    reward_scaling: bool = False  # divide rewards by the running std of the discounted return
    init_reg: float = 0.0  # L2 pull of the actor towards its --init weights (0: none)
    threads: int = 1  # torch CPU threads
    eval_every: int = 10  # updates between evaluations (0: only at the end)
    eval_seeds: int = 8  # held-out evaluation episodes
    eval_seed_start: int = 1000  # first evaluation seed (training copies draw from 10^6 on)
    reward: str = "train"  # "train": the task under tasks.TRAINING_PRESET; "paper": -J_i
    promote_at: float = 0.75  # curriculum: completed fraction of an evaluation that moves up
    # curriculum: and the evaluation's mean route error max below this [m] (0: no such bound)
    promote_route_error: float = 80.0
    env: Mapping[str, Any] = field(default_factory=dict)  # scenario overrides (with_overrides)

    def __post_init__(self) -> None:
        positive_ints = ("copies", "rollout_steps", "epochs", "minibatches", "threads")
        for name in positive_ints:
            _check_int(name, getattr(self, name), 1)
        for name in ("eval_every", "eval_seeds", "eval_seed_start"):
            _check_int(name, getattr(self, name), 0)
        for name in ("learning_rate", "obs_clip", "max_grad_norm"):
            if not _real(getattr(self, name)) or getattr(self, name) <= 0:
                raise ValueError(f"{name} must be a positive number, got {getattr(self, name)!r}")
        for name in ("gamma", "gae_lambda"):
            value = getattr(self, name)
            if not _real(value) or not 0 <= value <= 1:
                raise ValueError(f"{name} must be in [0, 1], got {value!r}")
        for name in ("clip_coef", "ent_coef", "vf_coef", "init_reg"):
            value = getattr(self, name)
            if not _real(value) or value < 0:
                raise ValueError(f"{name} must be a number >= 0, got {value!r}")
        if not _real(self.log_std_init):
            raise ValueError(f"log_std_init must be a number, got {self.log_std_init!r}")
        if self.target_kl is not None and (not _real(self.target_kl) or self.target_kl <= 0):
            raise ValueError(f"target_kl must be a positive number or null, got {self.target_kl!r}")
        flags = ("anneal_lr", "clip_vloss", "value_norm", "bootstrap_diverged", "norm_adv")
        if not _real(self.promote_at) or not 0.0 <= self.promote_at <= 1.0:
            raise ValueError(f"promote_at must be a number in [0, 1], got {self.promote_at!r}")
        if not _real(self.promote_route_error) or self.promote_route_error < 0:
            raise ValueError(
                f"promote_route_error must be a number >= 0 [m], got {self.promote_route_error!r}"
            )
        if self.reward not in ("train", "paper"):
            raise ValueError(f"reward must be 'train' or 'paper', got {self.reward!r}")
        for name in (*flags, "reward_scaling"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        hidden = self.hidden
        if (
            isinstance(hidden, str | bytes)
            or not hasattr(hidden, "__iter__")
            or not hidden
            or not all(isinstance(h, int) and not isinstance(h, bool) and h > 0 for h in hidden)
        ):
            raise ValueError(f"hidden must be a non-empty list of positive ints, got {hidden!r}")
        object.__setattr__(self, "hidden", tuple(hidden))
        if self.activation not in ONPOLICY_ACTIVATIONS:
            raise ValueError(
                f"activation must be one of {ONPOLICY_ACTIVATIONS}, got {self.activation!r}"
            )
        if not isinstance(self.env, Mapping):
            raise ValueError(f"env must be a mapping of scenario overrides, got {self.env!r}")
        for name in ("learning_rate", "gamma", "gae_lambda", "clip_coef", "ent_coef", "vf_coef"):
            object.__setattr__(self, name, float(getattr(self, name)))

    def as_dict(self) -> dict[str, Any]:
        """Plain YAML-ready values (lists for tuples, dicts for mappings)."""
        data = dataclasses.asdict(self)
        data["hidden"] = list(self.hidden)
        data["env"] = _plain(self.env)
        return data


def _check_int(name: str, value: Any, minimum: int) -> None:
    if not isinstance(value, int) or isinstance(value, bool) or value < minimum:
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")


def _real(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and value == value


def _plain(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, tuple | list):
        return [_plain(v) for v in value]
    return value


CONFIG_KEYS = tuple(f.name for f in dataclasses.fields(OnPolicyConfig))


def config_from_mapping(data: Mapping[str, Any]) -> OnPolicyConfig:
    """An :class:`OnPolicyConfig` of a mapping; an unknown key is a ``ValueError`` naming it."""
    unknown = sorted(set(data) - set(CONFIG_KEYS))
    if unknown:
        raise ValueError(
            f"unknown on-policy hyper-parameter(s) {unknown}; allowed: {sorted(CONFIG_KEYS)}"
        )
    return OnPolicyConfig(**dict(data))


def hyperparams_file() -> Path:
    """The shipped ``baselines/hyperparams/onpolicy.yml``."""
    return HYPERPARAMS_DIR / "onpolicy.yml"


def load_config(
    algo: str, overrides: Mapping[str, Any] | None = None, path: str | Path | None = None
) -> OnPolicyConfig:
    """The merged hyper-parameters of ``algo``: ``default``, then its section, then overrides.

    Args:
        algo: one of :data:`ONPOLICY_ALGOS`.
        overrides: nested mapping (as from ``parse_set``).
        path: YAML file (None: :func:`hyperparams_file`).
    """
    if algo not in ONPOLICY_ALGOS:
        raise ValueError(f"algo must be one of {ONPOLICY_ALGOS}, got {algo!r}")
    path = Path(path) if path is not None else hyperparams_file()
    with open(path, encoding="utf-8") as stream:
        table = yaml.safe_load(stream) or {}
    if not isinstance(table, Mapping):
        raise ValueError(f"{path}: expected a mapping of sections, got {type(table).__name__}")
    unknown = sorted(set(table) - {"default", *ONPOLICY_ALGOS})
    if unknown:
        raise ValueError(
            f"{path}: unknown section(s) {unknown}; expected 'default' or one of {ONPOLICY_ALGOS}"
        )
    merged = apply_overrides(table.get("default") or {}, table.get(algo) or {})
    return config_from_mapping(apply_overrides(merged, overrides or {}))
