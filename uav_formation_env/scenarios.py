"""Scenario builders: the paper's, other formation sizes, obstacle fields, wind.

Formation shapes and obstacle fields are data: every builder returns a validated
:class:`~uav_formation_env.config.Scenario`. Random obstacle fields draw from a passed
``np.random.Generator``.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from uav_formation_env.config import (
    DisturbanceConfig,
    FormationConfig,
    ObstacleConfig,
    Scenario,
)
from uav_formation_env.formations import formation_offsets


def v_offsets(n_uav: int, spacing: float = 10.0) -> tuple[tuple[float, ...], ...]:
    """V formation pointing +x (:func:`~uav_formation_env.formations.formation_offsets`):
    apex at 0, then pairs k = 1, 2, … at (-spacing k, ±2 spacing k); for N = 5 and the default
    spacing this is the paper's z^d (eq. 22)."""
    return tuple(tuple(row) for row in formation_offsets("v", n_uav, spacing).tolist())


def leader_chain_adjacency(n_uav: int) -> tuple[tuple[int, ...], ...]:
    """Every UAV receives from UAV 1 (the apex) and from its neighbours in index order."""
    h = np.zeros((n_uav, n_uav), dtype=int)
    h[1:, 0] = 1
    idx = np.arange(n_uav - 1)
    h[idx, idx + 1] = 1
    h[idx + 1, idx] = 1
    np.fill_diagonal(h, 0)
    return tuple(tuple(int(x) for x in row) for row in h)


def random_obstacles(
    rng: np.random.Generator,
    count: int = 3,
    x_range: tuple[float, float] = (250.0, 950.0),
    y_range: tuple[float, float] = (-60.0, 60.0),
    radius_range: tuple[float, float] = (15.0, 35.0),
    detection_margin: float = 40.0,
    max_tries: int = 1000,
) -> tuple[ObstacleConfig, ...]:
    """Obstacles uniform in a box (by default across the first leg of the paper's route).

    Rejection-samples until no two detection circles overlap (the validity rule of
    :class:`~uav_formation_env.config.AvoidanceConfig`).
    """
    placed: list[ObstacleConfig] = []
    for _ in range(max_tries):
        if len(placed) == count:
            break
        candidate = ObstacleConfig(
            (float(rng.uniform(*x_range)), float(rng.uniform(*y_range))),
            float(rng.uniform(*radius_range)),
        )
        if all(
            np.hypot(candidate.center[0] - o.center[0], candidate.center[1] - o.center[1])
            >= candidate.radius + o.radius + 2 * detection_margin
            for o in placed
        ):
            placed.append(candidate)
    if len(placed) < count:
        raise ValueError(f"could not place {count} non-overlapping obstacles in the box")
    return tuple(sorted(placed, key=lambda o: o.center[0]))


def make_scenario(
    n_uav: int = 5,
    obstacles: str = "paper",
    observer: bool = True,
    collision_mode: str = "none",
    seed: int = 0,
    wind: tuple[float, float, float] = (0.0, 0.0, 0.0),
    gust_std: float = 0.0,
    duration: float | None = None,
) -> Scenario:
    """A variant of the paper's scenario.

    Args:
        n_uav: formation size; N = 5 gives the paper's V and graph, others a V with a
            leader-chain graph.
        obstacles: "paper", "none" or "random" (3 obstacles drawn with ``seed``).
        observer: NFTSMO compensation on or off.
        collision_mode: "none", "penalty" or "terminate".
        seed: seed of the random obstacle field.
        wind: constant wind [m/s^2].
        gust_std: Gauss-Markov gust std [m/s^2] (0 = off).
        duration: episode length [s] (None: the paper's 200 s).
    """
    base = Scenario()
    if n_uav == 5:
        formation = base.formation
    else:
        formation = FormationConfig(v_offsets(n_uav), leader_chain_adjacency(n_uav))
    if obstacles == "paper":
        field = base.avoidance.obstacles
    elif obstacles == "none":
        field = ()
    elif obstacles == "random":
        field = random_obstacles(np.random.default_rng(seed))
    else:
        raise ValueError(f"obstacles must be 'paper', 'none' or 'random', got {obstacles!r}")
    return replace(
        base,
        name=f"n{n_uav}_{obstacles}",
        duration=base.duration if duration is None else duration,
        formation=formation,
        avoidance=replace(base.avoidance, obstacles=field),
        observer=replace(base.observer, enabled=observer),
        disturbance=DisturbanceConfig(wind=wind, gust_std=gust_std),
        collision=replace(base.collision, mode=collision_mode),
    )


def windy_scenario() -> Scenario:
    """The paper's scenario with a constant 0.3 m/s² crosswind and 0.1 m/s² gusts."""
    return replace(make_scenario(wind=(0.0, 0.3, 0.0), gust_std=0.1), name="windy")


__all__ = [
    "leader_chain_adjacency",
    "make_scenario",
    "random_obstacles",
    "v_offsets",
    "windy_scenario",
]
