"""The paper's four variants, its published numbers, and one variant's batched run."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.evaluation import EpisodeBatch, run_episodes
from uav_formation_env.policies.registry import (
    DMPC_OPTIMIZERS,
    PAPER_OPTIMIZERS,
    POLICY_LABELS,
    make_policy,
)
from uav_formation_env.sim_options import SimOptions

OBSERVER_SUFFIX = "_nftsmo"  # a variant flown with the NFTSMO observer on
# name -> (optimiser, observer on): the paper's optimisers without and with the observer
VARIANTS: dict[str, tuple[str, bool]] = {
    f"{name}{OBSERVER_SUFFIX if observer else ''}": (name, observer)
    for observer in (False, True)
    for name in PAPER_OPTIMIZERS
}
# The other solvers of the same game for the Nash-gap comparison (observer on). Besides these names
# a game variant can be the path of a stable-baselines3 model (its action held over the horizon).
GAME_VARIANTS: dict[str, tuple[str, bool]] = {
    f"{name}{OBSERVER_SUFFIX}": (name, True)
    for name in DMPC_OPTIMIZERS
    if name not in PAPER_OPTIMIZERS
}
LABELS = {
    variant: POLICY_LABELS[name] + (" + NFTSMO" if observer else "")
    for variant, (name, observer) in {**VARIANTS, **GAME_VARIANTS}.items()
}
# Table 2 of the paper (one run, 1000 steps)
PAPER_TRIGGERS: dict[str, tuple[float, ...]] = {
    "pio": (1000, 1000, 1000, 1000, 1000),
    "lfpio": (1000, 1000, 1000, 1000, 1000),
    "pio_nftsmo": (513, 632, 578, 598, 539),
    "lfpio_nftsmo": (455, 560, 501, 518, 459),
}
PAPER_TRIGGER_MEAN = {"pio": 1000.0, "lfpio": 1000.0, "pio_nftsmo": 572.0, "lfpio_nftsmo": 498.6}
PAPER_LFPIO_REDUCTION = 0.128  # LFPIO + NFTSMO vs PIO + NFTSMO, paper's text
PAPER_EVENTS_S = {"O1 split": 10.0, "O1 restore": 13.6, "O2 encounter": 66.2}
PAPER_STEPS = 1000
QUICK_DURATION_S = 20.0
FIGURES = (
    "fig5_trajectories.png",
    "fig6_observer.png",
    "fig7_velocity_uav1.png",
    "fig8_log_cost.png",
    "fig9_triggers_uav5.png",
    "fig9_triggers_all_uavs.png",
)


def variant_spec(variant: str) -> tuple[str, bool]:
    """``(policy name or model path, observer on)`` of a paper or game variant."""
    if variant in VARIANTS:
        return VARIANTS[variant]
    if variant in GAME_VARIANTS:
        return GAME_VARIANTS[variant]
    path = Path(variant)
    if path.is_file() or path.with_suffix(".zip").is_file():
        return variant, True
    raise ValueError(
        f"unknown variant {variant!r}: expected one of {list(VARIANTS) + list(GAME_VARIANTS)} "
        "or the path of a stable-baselines3 model"
    )


def variant_label(variant: str) -> str:
    """Display name of a variant (a model's directory name, upper case, + NFTSMO)."""
    if variant in LABELS:
        return LABELS[variant]
    return f"{Path(variant).parent.name.upper() or Path(variant).stem} + NFTSMO"


def variant_scenario(base: Scenario, variant: str, duration: float | None = None) -> Scenario:
    """The scenario of a variant: ``base`` with the observer on or off (and the duration)."""
    overrides: dict[str, Any] = {"observer.enabled": variant_spec(variant)[1]}
    if duration is not None:
        overrides["duration"] = float(duration)
    return with_overrides(base, overrides)


def run_variant(
    variant: str,
    base: Scenario,
    seeds: Sequence[int],
    duration: float | None = None,
    policy_seed: int | None = None,
    progress: Any = False,
    array_backend: str = "numpy",
    device: Any = None,
    random: str = "generator",
) -> EpisodeBatch:
    """All seeds of one variant as one batch, with the Nash gap of its plans at every step
    (``array_backend`` and ``device``: the :class:`~uav_formation_env.sim_options.SimOptions` of
    :func:`~uav_formation_env.evaluation.run_episodes`;
    ``random``: that of :func:`~uav_formation_env.evaluation.make_policy`).
    """
    scenario = variant_scenario(base, variant, duration)
    policy = make_policy(variant_spec(variant)[0], scenario, seed=policy_seed, random=random)
    return run_episodes(
        scenario,
        policy,
        seeds,
        policy_name=variant,
        progress=progress,
        desc=variant_label(variant),
        nash_gap=True,
        options=SimOptions(backend=array_backend, device=device),
    )
