"""The one list of policy names, and :func:`make_policy`: a policy from a name or a model path.

Names (every other list in the package, the CLI help and the reproduction's variants, is built
from these):

- :data:`DMPC_OPTIMIZERS`: the reference DMPC (:class:`~uav_formation_env.policies.dmpc.
  NashDMPCPolicy`) with that solver: ``pio``, ``lfpio``, ``pso`` (the metaheuristics of
  :mod:`~uav_formation_env.policies.optimizers`), ``exact`` (the best response solved exactly)
  and ``nash`` (best responses iterated to a Nash equilibrium every step);
- :data:`SIMPLE_POLICIES`: ``heuristic`` (consensus PD) and ``random``;
- :data:`SHIPPED_MODELS`: the learned policies installed with the package (one per task, in the
  format of :mod:`~uav_formation_env.policies.policy_file`, under :data:`MODELS_DIR`);
- anything else is the path of a policy directory (``policy.json`` + ``policy.npz``) or of a
  stable-baselines3 model (:class:`~uav_formation_env.policies.learned.SB3Policy`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from uav_formation_env.config import Scenario
from uav_formation_env.policies.learned import SB3Policy
from uav_formation_env.policies.policy_file import FilePolicy, is_policy_dir
from uav_formation_env.policies.protocol import BatchPolicy
from uav_formation_env.policies.simple import HeuristicPolicy, RandomPolicy
from uav_formation_env.policies.solvers import (
    DMPC_OPTIMIZERS,
    DMPC_SOLVERS,
    SolverConfig,
    solver_config,
)

__all__ = [
    "DMPC_OPTIMIZERS",
    "DMPC_SOLVERS",
    "MODELS_DIR",
    "PAPER_OPTIMIZERS",
    "POLICY_HELP",
    "POLICY_LABELS",
    "POLICY_NAMES",
    "SHIPPED_MODELS",
    "SIMPLE_POLICIES",
    "BatchPolicy",
    "SolverConfig",
    "make_policy",
    "run_model_file",
    "model_scenario",
    "solver_config",
]

# name -> the policy built from (scenario, seed)
_SIMPLE: dict[str, Callable[[Scenario, int | None], BatchPolicy]] = {
    "heuristic": lambda scenario, seed: HeuristicPolicy(scenario),
    "random": lambda scenario, seed: RandomPolicy(seed),
}
SIMPLE_POLICIES = tuple(_SIMPLE)  # ("heuristic", "random")
POLICY_NAMES = (*DMPC_OPTIMIZERS, *SIMPLE_POLICIES)
MODELS_DIR = Path(__file__).resolve().parents[1] / "models"  # installed as package data
# name -> what the model is; each directory holds policy.json, policy.npz, scenario.yaml
SHIPPED_MODELS = {
    "random_fields_dagger": "DAgger students on random obstacle fields (random_fields)",
    "random_swarm_dagger": "DAgger students on random swarms of 3-10 UAVs (random_swarm)",
    "paper_ppo": "PPO from the training reward alone (curriculum hold, track, paper) on the paper",
}
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
    f"{', '.join(SIMPLE_POLICIES)}, a shipped learned policy ({', '.join(SHIPPED_MODELS)}: "
    "it flies its own scenario), a policy directory or run directory (policy.json + "
    "policy.npz, what every trainer of the project exports), or a stable-baselines3 model or "
    "run directory (model.zip; obs_stats.npz beside it is applied)"
)


def model_scenario(name: str) -> Path | None:
    """The ``scenario.yaml`` a saved model was trained for: a shipped model's, or that of the
    model's run directory (the directory itself, or the model file's); None if it has none."""
    if name.lower() in SHIPPED_MODELS:
        return MODELS_DIR / name.lower() / "scenario.yaml"
    path = Path(name)
    for directory in (path, path.parent):
        if directory.is_dir() and (directory / "scenario.yaml").is_file() and path.exists():
            return directory / "scenario.yaml"
    return None


RUN_MODEL_FILES = ("policy.json", "model.zip")  # what a run directory holds


def run_model_file(path: Path) -> Path:
    """The SB3 model of a run directory (``model.zip`` beside ``obs_stats.npz`` of
    ``uav-formation train``), else ``path`` itself."""
    if path.is_dir() and (path / "model.zip").is_file():
        return path / "model.zip"
    return path


def _in_its_action_mode(
    policy: BatchPolicy, scenario: Scenario, directory: Path, header: dict | None = None
) -> BatchPolicy:
    """A saved policy as an acceleration policy: one trained in the velocity action mode flies
    through :class:`~uav_formation_env.policies.action_modes.VelocitySetpointPolicy` with the
    set-point range and gain it was trained with. The mode is the policy file's
    ``action_mode`` (``header``), else that of the ``scenario.yaml`` in ``directory`` (every
    trainer writes one), else acceleration."""
    from uav_formation_env.config import EpisodeConfig

    header, beside = header or {}, directory / "scenario.yaml"
    if "action_mode" in header:
        episode = EpisodeConfig(
            action=header["action_mode"],
            velocity_range=float(header.get("velocity_range", EpisodeConfig.velocity_range)),
            velocity_gain=float(header.get("velocity_gain", EpisodeConfig.velocity_gain)),
        )
    elif beside.is_file():
        from uav_formation_env.config_io import load_scenario

        episode = load_scenario(beside).episode
    else:
        return policy
    from uav_formation_env.policies.action_modes import in_acceleration_mode

    return in_acceleration_mode(policy, episode, scenario.dynamics.u_max)


def make_policy(
    name: str,
    scenario: Scenario,
    seed: int | None = None,
    algo: str | None = None,
    random: str = "generator",
    trust_pickle: bool = False,
) -> BatchPolicy:
    """A policy from a name of :data:`POLICY_NAMES` or :data:`SHIPPED_MODELS`, or the path of a
    policy directory or a stable-baselines3 model (see the module docstring).

    Args:
        name: policy name (case-insensitive) or model path.
        scenario: the scenario the policy flies (mission data of DMPC / heuristic).
        seed: the policy's own seed, mixed into the per-episode random streams of the DMPC
            optimisers and the random policy (None: the episode seeds alone decide).
        algo: stable-baselines3 algorithm of a model path (None: try each).
        random: the DMPC optimisers' random numbers, ``"generator"`` (each copy's numpy
            generator) or ``"counter"`` (counter-based, drawn on the observations' device); see
            :class:`~uav_formation_env.policies.dmpc.NashDMPCPolicy`. Other policies ignore it.
        trust_pickle: let a stable-baselines3 model read a ``vecnormalize.pkl`` (unpickling runs
            code from the file: only for files you made yourself).
    """
    key = name.lower()
    if key in DMPC_SOLVERS:
        from uav_formation_env.policies.dmpc import NashDMPCPolicy  # loads the optimisers

        return NashDMPCPolicy(scenario, key, seed=seed, random=random)
    if key in _SIMPLE:
        return _SIMPLE[key](scenario, seed)
    path = MODELS_DIR / key if key in SHIPPED_MODELS else Path(name)
    if is_policy_dir(path):
        exported = _loaded(path, lambda: FilePolicy(path))
        exported.check_scenario(scenario)
        return _in_its_action_mode(exported, scenario, exported.path, exported.header)
    if path.suffix == ".pt" or (path.is_dir() and (path / "policy.pt").is_file()):
        raise ValueError(
            f"policy {name!r}: TorchScript files (.pt) are not read (loading them runs code); "
            "export the policy as a policy directory (policy.json + policy.npz)"
        )
    path = run_model_file(path)
    if path.is_file() or path.with_suffix(".zip").is_file():
        policy = _loaded(path, lambda: SB3Policy(path, algo, trust_pickle=trust_pickle))
        policy.check_scenario(scenario)
        return _in_its_action_mode(policy, scenario, path.parent)
    if path.is_dir():
        raise FileNotFoundError(
            f"policy directory {name!r} holds no model: expected one of {list(RUN_MODEL_FILES)}"
        )
    if path.suffix == ".zip" or len(path.parts) > 1:
        raise FileNotFoundError(f"policy model file not found: {name!r}")
    raise ValueError(
        f"unknown policy {name!r}: expected one of {[*POLICY_NAMES, *SHIPPED_MODELS]}, a policy "
        "directory (policy.json + policy.npz) or a stable-baselines3 model (.zip)"
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
