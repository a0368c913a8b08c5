"""The paper's four variants, its published numbers, and one variant's batched run."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.evaluation import (
    EpisodeBatch,
    make_policy,
    run_episodes,
)

# name -> (optimiser, observer on)
VARIANTS: dict[str, tuple[str, bool]] = {
    "pio": ("pio", False),
    "lfpio": ("lfpio", False),
    "pio_nftsmo": ("pio", True),
    "lfpio_nftsmo": ("lfpio", True),
}
LABELS = {
    "pio": "PIO",
    "lfpio": "LFPIO",
    "pio_nftsmo": "PIO + NFTSMO",
    "lfpio_nftsmo": "LFPIO + NFTSMO",
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


def variant_scenario(base: Scenario, variant: str, duration: float | None = None) -> Scenario:
    """The scenario of a variant: ``base`` with the observer on or off (and the duration)."""
    overrides: dict[str, Any] = {"observer.enabled": VARIANTS[variant][1]}
    if duration is not None:
        overrides["duration"] = float(duration)
    return with_overrides(base, overrides)


def run_variant(
    variant: str,
    base: Scenario,
    seeds: Sequence[int],
    duration: float | None = None,
    policy_seed: int = 0,
    progress: Any = False,
) -> EpisodeBatch:
    """All seeds of one variant as one batch (see the module docstring)."""
    scenario = variant_scenario(base, variant, duration)
    policy = make_policy(VARIANTS[variant][0], scenario, seed=policy_seed)
    return run_episodes(
        scenario, policy, seeds, policy_name=variant, progress=progress, desc=LABELS[variant]
    )
