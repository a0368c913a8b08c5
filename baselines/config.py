"""Hyper-parameters: one YAML per algorithm, keyed by scenario name, with a ``default`` section.

As in rl-baselines3-zoo, one flat mapping per scenario mixes the algorithm's constructor arguments
(``learning_rate``, ``n_steps``, ``policy_kwargs``, ...) with the training set-up keys of
:data:`TRAINING_DEFAULTS` (copies, normalisation, evaluation, ...). A scenario's section is merged
over ``default`` (nested mappings key by key), and ``--set key=value`` overrides are merged last;
dotted keys reach into mappings (``policy_kwargs.net_arch=[256,256]``), values are parsed as YAML.
"""

from __future__ import annotations

import copy
import inspect
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import yaml

from uav_formation_baselines import HYPERPARAMS_DIR
from uav_formation_env.config_io import SCENARIOS

# Training set-up keys (not constructor arguments of the algorithm) and their defaults.
TRAINING_DEFAULTS: dict[str, Any] = {
    "policy": "MlpPolicy",
    "copies": 8,  # scenario copies B; the VecEnv has B * N entries
    "normalize": {"norm_obs": True, "norm_reward": True, "clip_obs": 10.0, "clip_reward": 10.0},
    # the episode layer's training options (scenario.episode, see uav_formation_env.episode):
    # reward transform, divergence truncation, start along the mission, mission corridor
    "episode": {
        "reward": "raw",
        "reward_scale": 100.0,
        "max_formation_error": 100.0,
        "max_velocity_error": 40.0,
        "start": "staggered",
    },
    "env_overrides": {},  # scenario field overrides for training only (e.g. collision.mode)
    "eval_freq": 50_000,  # agent-steps between evaluations (0: none)
    "eval_seeds": [1000, 1001, 1002, 1003],  # seeds of the periodic evaluation episodes
    "eval_duration": None,  # evaluation episode length [s] (None: the scenario's)
    "checkpoint_freq": 0,  # agent-steps between checkpoints (0: none)
}
ACTIVATIONS = ("tanh", "relu", "elu", "leaky_relu", "gelu", "silu")


def _deep_merge(base: Mapping[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    merged = copy.deepcopy(dict(base))
    for key, value in patch.items():
        if isinstance(value, Mapping) and isinstance(merged.get(key), Mapping):
            merged[key] = _deep_merge(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged


def hyperparams_path(algo: str) -> Path:
    """The shipped YAML of an algorithm (``baselines/hyperparams/<algo>.yml``)."""
    return HYPERPARAMS_DIR / f"{algo.lower()}.yml"


def scenario_sections(path: str | Path) -> dict[str, Any]:
    """The sections of a YAML keyed by scenario name: ``default`` and registered scenario names.

    A misspelt section would otherwise be skipped without a word (its scenario would train with
    ``default`` alone), so any other top-level key is a ``ValueError`` naming it.
    """
    with open(path, encoding="utf-8") as stream:
        table = yaml.safe_load(stream) or {}
    if not isinstance(table, Mapping):
        raise ValueError(f"{path}: expected a mapping of sections, got {type(table).__name__}")
    for key in table:
        if key != "default" and key not in SCENARIOS:
            raise ValueError(
                f"{path}: unknown section {key!r}; expected 'default' or a registered scenario "
                f"name ({', '.join(sorted(SCENARIOS))})"
            )
    return dict(table)


def load_hyperparams(algo: str, scenario_key: str, path: str | Path | None = None) -> dict:
    """The merged hyper-parameters of ``algo`` on a scenario.

    Args:
        algo: ``"ppo"`` or ``"sac"``.
        scenario_key: section name (a registered scenario name); missing sections use
            ``default`` alone.
        path: YAML file (None: the shipped one).
    """
    path = Path(path) if path is not None else hyperparams_path(algo)
    table = scenario_sections(path)
    if "default" not in table:
        raise ValueError(f"{path} has no 'default' section")
    params = _deep_merge(TRAINING_DEFAULTS, table["default"])
    return _deep_merge(params, table.get(scenario_key) or {})


def parse_set(items: Sequence[str]) -> dict[str, Any]:
    """``["a.b=1", "c=[64, 64]"]`` as a nested mapping with YAML-parsed values."""
    patch: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key.strip():
            raise ValueError(f"--set expects key=value, got {item!r}")
        parts = key.strip().split(".")
        node = patch
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = _number_or_value(yaml.safe_load(raw))
    return patch


def _number_or_value(value: Any) -> Any:
    # YAML 1.1 reads "1e-3" (no dot) as a string; a learning rate must be a number
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


def apply_overrides(params: Mapping[str, Any], patch: Mapping[str, Any]) -> dict[str, Any]:
    """``params`` with ``patch`` merged in (see :func:`parse_set`)."""
    return _deep_merge(params, patch)


def split_params(params: Mapping[str, Any], algo_cls: type) -> tuple[dict, dict]:
    """Split merged hyper-parameters into (training set-up, algorithm keyword arguments).

    Keys that are neither training keys nor arguments of ``algo_cls`` raise ``ValueError``
    (so a typo in the YAML or in ``--set`` fails loudly). ``policy_kwargs.activation_fn`` is
    given by name (``"tanh"``, ``"relu"``, ...) and converted to the torch module here.
    """
    allowed = set(inspect.signature(algo_cls.__init__).parameters) - {"self", "env", "policy"}
    unknown = sorted(set(params) - set(TRAINING_DEFAULTS) - allowed)
    if unknown:
        raise ValueError(
            f"unknown hyper-parameter(s) {unknown} for {algo_cls.__name__}; training keys: "
            f"{sorted(TRAINING_DEFAULTS)}; algorithm keys: {sorted(allowed)}"
        )
    training = {k: copy.deepcopy(params[k]) for k in TRAINING_DEFAULTS if k in params}
    algo_kwargs = {k: copy.deepcopy(v) for k, v in params.items() if k not in TRAINING_DEFAULTS}
    policy_kwargs = algo_kwargs.get("policy_kwargs")
    if policy_kwargs and isinstance(policy_kwargs.get("activation_fn"), str):
        policy_kwargs["activation_fn"] = activation(policy_kwargs["activation_fn"])
    return training, algo_kwargs


def activation(name: str) -> type:
    """The torch activation module of a name in :data:`ACTIVATIONS`."""
    from torch import nn

    modules = {
        "tanh": nn.Tanh,
        "relu": nn.ReLU,
        "elu": nn.ELU,
        "leaky_relu": nn.LeakyReLU,
        "gelu": nn.GELU,
        "silu": nn.SiLU,
    }
    if name not in modules:
        raise ValueError(f"unknown activation_fn {name!r}; expected one of {ACTIVATIONS}")
    return modules[name]
