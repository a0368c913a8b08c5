"""The one list of policy names, and :func:`make_policy`: a policy from a name or a model path.

Names (every other list in the package, the CLI help and the reproduction's variants, is built
from these):

- :data:`DMPC_OPTIMIZERS`: the reference DMPC (:class:`~uav_formation_env.policies.dmpc.
  NashDMPCPolicy`) with that solver: ``pio``, ``lfpio``, ``pso`` (the metaheuristics of
  :mod:`~uav_formation_env.policies.optimizers`), ``exact`` (the best response solved exactly)
  and ``nash`` (best responses iterated to a Nash equilibrium every step);
- :data:`SIMPLE_POLICIES`: ``heuristic`` (consensus PD) and ``random``;
- anything else is the path of a stable-baselines3 model (:class:`~uav_formation_env.policies.
  learned.SB3Policy`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Protocol

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.policies.best_response import ExactConfig
from uav_formation_env.policies.learned import SB3Policy, TorchScriptPolicy
from uav_formation_env.policies.nash import NashConfig
from uav_formation_env.policies.optimizers.config import (
    OPTIMIZERS,
    LFPIOConfig,
    PIOConfig,
    PSOConfig,
)
from uav_formation_env.policies.simple import HeuristicPolicy, RandomPolicy

__all__ = [
    "DMPC_OPTIMIZERS",
    "DMPC_SOLVERS",
    "PAPER_OPTIMIZERS",
    "POLICY_HELP",
    "POLICY_LABELS",
    "POLICY_NAMES",
    "SIMPLE_POLICIES",
    "BatchPolicy",
    "SolverConfig",
    "make_policy",
    "solver_config",
]

SolverConfig = PIOConfig | LFPIOConfig | PSOConfig | ExactConfig | NashConfig
# name -> the config of NashDMPCPolicy's solver (its defaults)
DMPC_SOLVERS: dict[str, type[SolverConfig]] = {
    **OPTIMIZERS,
    "exact": ExactConfig,
    "nash": NashConfig,
}
DMPC_OPTIMIZERS = tuple(DMPC_SOLVERS)  # ("pio", "lfpio", "pso", "exact", "nash")
# name -> the policy built from (scenario, seed)
_SIMPLE: dict[str, Callable[[Scenario, int | None], BatchPolicy]] = {
    "heuristic": lambda scenario, seed: HeuristicPolicy(scenario),
    "random": lambda scenario, seed: RandomPolicy(seed),
}
SIMPLE_POLICIES = tuple(_SIMPLE)  # ("heuristic", "random")
POLICY_NAMES = (*DMPC_OPTIMIZERS, *SIMPLE_POLICIES)
PAPER_OPTIMIZERS = ("pio", "lfpio")  # the two the paper compares (its Table 2)
POLICY_LABELS = {
    "pio": "PIO",
    "lfpio": "LFPIO",
    "pso": "PSO",
    "exact": "exact best response",
    "nash": "iterated best response (Nash)",
    "heuristic": "consensus PD heuristic",
    "random": "random",
}
POLICY_HELP = (
    f"{', '.join(DMPC_OPTIMIZERS)} (the reference DMPC with that solver), "
    f"{', '.join(SIMPLE_POLICIES)}, a stable-baselines3 model path (.zip; a vecnormalize.pkl "
    "beside it is applied), or a TorchScript policy (.pt, or a run directory holding policy.pt: "
    "the RLlib recipe's export)"
)


class BatchPolicy(Protocol):
    """What :func:`~uav_formation_env.evaluation.run_episodes` needs of a policy
    (``reset(batch_size, seeds)`` optional; a policy with ``needs_neighbour_index = True`` is
    called as ``act_batch(obs, neighbour_index)`` with the local layout's slot index)."""

    def act_batch(self, obs: np.ndarray) -> np.ndarray: ...


def solver_config(optimizer: str | SolverConfig) -> SolverConfig:
    """The solver config of a DMPC solver name (case-insensitive; its defaults), or the config
    itself."""
    if isinstance(optimizer, SolverConfig):
        return optimizer
    if isinstance(optimizer, str) and optimizer.lower() in DMPC_SOLVERS:
        return DMPC_SOLVERS[optimizer.lower()]()
    raise ValueError(
        f"unknown optimizer {optimizer!r}: expected one of {sorted(DMPC_SOLVERS)} or a config "
        "object"
    )


def make_policy(
    name: str,
    scenario: Scenario,
    seed: int | None = None,
    algo: str | None = None,
    random: str = "generator",
) -> BatchPolicy:
    """A policy from a name of :data:`POLICY_NAMES` (see the module docstring) or the path of a
    stable-baselines3 model.

    Args:
        name: policy name (case-insensitive) or model path.
        scenario: the scenario the policy flies (mission data of DMPC / heuristic).
        seed: the policy's own seed, mixed into the per-episode random streams of the DMPC
            optimisers and the random policy (None: the episode seeds alone decide).
        algo: stable-baselines3 algorithm of a model path (None: try each).
        random: the DMPC optimisers' random numbers, ``"generator"`` (each copy's numpy
            generator) or ``"counter"`` (counter-based, drawn on the observations' device); see
            :class:`~uav_formation_env.policies.dmpc.NashDMPCPolicy`. Other policies ignore it.
    """
    key = name.lower()
    if key in DMPC_SOLVERS:
        from uav_formation_env.policies.dmpc import NashDMPCPolicy  # imports this module

        return NashDMPCPolicy(scenario, key, seed=seed, random=random)
    if key in _SIMPLE:
        return _SIMPLE[key](scenario, seed)
    path = Path(name)
    if path.is_dir() and (path / "policy.pt").is_file():
        path = path / "policy.pt"  # a run directory of the RLlib recipe
    if path.suffix == ".pt":
        exported = _loaded(path, lambda: TorchScriptPolicy(path))
        exported.check_scenario(scenario)
        return exported
    if path.is_file() or path.with_suffix(".zip").is_file():
        policy = _loaded(path, lambda: SB3Policy(path, algo))
        policy.check_scenario(scenario)
        return policy
    if path.suffix == ".zip" or len(path.parts) > 1:
        raise FileNotFoundError(f"policy model file not found: {name!r}")
    raise ValueError(
        f"unknown policy {name!r}: expected one of {list(POLICY_NAMES)}, the path of a "
        "stable-baselines3 model (.zip) or of a TorchScript policy (.pt)"
    )


def _loaded(path: Path, load: Callable[[], BatchPolicy]) -> BatchPolicy:
    """``load()``, with a corrupt or foreign file's error (torch's, pickle's, zipfile's) as one
    ``ValueError`` naming the file; the loaders' own errors (ValueError, a missing file or
    extra) pass unchanged."""
    try:
        return load()
    except (FileNotFoundError, ImportError, ValueError):
        raise
    except Exception as error:  # noqa: BLE001 - any failure of a third-party loader
        first = str(error).strip().splitlines()[0] if str(error).strip() else ""
        raise ValueError(
            f"cannot load the model {str(path)!r} (corrupt, truncated or not a model file?): "
            f"{type(error).__name__}: {first[:200]}"
        ) from error
