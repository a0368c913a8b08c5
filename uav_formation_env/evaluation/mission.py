"""Mission metrics: does a policy fly the mission, not only keep its cost low?

The paper's game cost J_i tracks the preset *velocity* (eq. 23), not a position, so a policy can
leave the route, skip every obstacle and still look cheap. These metrics judge the flight
against the mission itself:

- **route error**: horizontal distance between the formation centroid and the *preset route*,
  the centroid at t = 0 plus the integral of the preset velocity of the schedule
  (:func:`~uav_formation_env.core.reference.preset_displacement`; no avoidance deflection); RMS
  and max over the episode's samples t_0 = 0 .. t_T [m];
- **velocity-tracking RMSE**: RMS over samples and UAVs of ``||v_i(t) - v^d_preset(t)||`` [m/s];
- per obstacle: **met** (some UAV came within the detection distance ``d^o = radius +
  avoidance.detection_margin`` of its centre, horizontally), the closest approach of any UAV to
  its centre [m] and the first time it was met [s]; **required** if the preset route (as a
  polyline through the samples) passes within d^o of the centre;
- **collisions after t = 0**: UAV-steps flagged as collisions by the simulator (every step of
  an episode ends after t = 0) and the time of the first;
- **minimum separation after t = 0** and when it happened (the layout at t = 0 is excluded);
- **mission completed**: every required obstacle met, no collision after t = 0 and route error
  max <= ``scenario.mission.max_route_error`` (default 100 m). An episode that fails lists why.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.obstacles import obstacle_field
from uav_formation_env.core.reference import (
    CopySchedules,
    Schedule,
    copy_schedules,
    preset_displacement,
    preset_velocity,
    route_error,
)

# two-sided 95 % Student t quantiles for 1..30 degrees of freedom
_T95 = (
    12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    2.201, 2.179, 2.160, 2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086,
    2.080, 2.074, 2.069, 2.064, 2.060, 2.056, 2.052, 2.048, 2.045, 2.042,
)  # fmt: skip


def wilson_ci95(successes: int, trials: int) -> tuple[float, float]:
    """Wilson score 95 % interval (low, high) of a success rate, e.g. missions completed."""
    if trials <= 0:
        raise ValueError(f"wilson_ci95 needs trials >= 1, got {trials}")
    z, p = 1.959963984540054, successes / trials
    centre = (p + z * z / (2 * trials)) / (1 + z * z / trials)
    half = z * np.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / (1 + z * z / trials)
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))


def mean_ci95(values: np.ndarray) -> tuple[float, float]:
    """Mean and half-width of its 95 % confidence interval (Student t; 0 for one value).

    Args:
        values: (K,) one value per episode (or per training seed).
    """
    x = np.asarray(values, dtype=float).ravel()
    if x.size == 0:
        raise ValueError("mean_ci95 needs at least one value")
    mean = float(x.mean())
    if x.size < 2:
        return mean, 0.0
    df = x.size - 1
    # Beyond the table, the Cornish-Fisher correction of the normal quantile (error < 1e-3).
    t = _T95[df - 1] if df <= len(_T95) else 1.95996 + (1.95996**3 + 1.95996) / (4 * df)
    return mean, float(t * x.std(ddof=1) / np.sqrt(x.size))


@dataclass(frozen=True)
class MissionMetrics:
    """Mission metrics of B episodes with O obstacles (see the module docstring)."""

    route_error_rms: np.ndarray  # (B,) [m]
    route_error_max: np.ndarray  # (B,) [m]
    velocity_rmse: np.ndarray  # (B,) [m/s]
    obstacle_required: np.ndarray  # (B, O) bool: the preset route passes within d^o
    obstacle_met: np.ndarray  # (B, O) bool: some UAV came within d^o of the centre
    obstacle_closest: np.ndarray  # (B, O) closest approach of any UAV to the centre [m]
    obstacle_time_met: np.ndarray  # (B, O) first time within d^o [s], NaN if never
    collisions: np.ndarray  # (B,) colliding UAV-steps after t = 0
    first_collision_time: np.ndarray  # (B,) [s], NaN if none
    min_separation: np.ndarray  # (B,) smallest UAV-UAV distance after t = 0 [m]
    min_separation_time: np.ndarray  # (B,) when it happened [s]
    max_route_error: float  # the completion threshold [m]

    @property
    def completed(self) -> np.ndarray:
        """(B,) bool: the mission was completed."""
        missed = (self.obstacle_required & ~self.obstacle_met).any(axis=1)
        return (~missed) & (self.collisions == 0) & (self.route_error_max <= self.max_route_error)

    def failures(self) -> list[list[str]]:
        """Per episode, why the mission was not completed (empty if it was)."""
        reasons: list[list[str]] = []
        for b in range(len(self.collisions)):
            why = [
                f"O{o + 1} not met (closest {self.obstacle_closest[b, o]:.0f} m from its centre)"
                for o in np.flatnonzero(self.obstacle_required[b] & ~self.obstacle_met[b])
            ]
            if self.collisions[b]:
                why.append(
                    f"{int(self.collisions[b])} colliding UAV-steps, first at "
                    f"t = {self.first_collision_time[b]:.1f} s"
                )
            if self.route_error_max[b] > self.max_route_error:
                why.append(
                    f"route error max {self.route_error_max[b]:.0f} m > {self.max_route_error:g} m"
                )
            reasons.append(why)
        return reasons


def preset_route(
    scenario: Scenario,
    t: np.ndarray,
    start: np.ndarray,
    scenes: Sequence[Scenario] | None = None,
) -> np.ndarray:
    """Positions of the preset route: ``start`` plus the integral of the preset velocity.

    Args:
        scenario: its schedule (eq. 23).
        t: (T,) times [s].
        start: (B, 3) route position at t = 0 (the formation centroid) [m].
        scenes: the concrete scenario of each copy: their own (drawn) schedules.

    Returns:
        (T, B, 3) [m].
    """
    schedule = _schedule(scenario, scenes)
    if isinstance(schedule, CopySchedules):
        times = np.broadcast_to(np.asarray(t, dtype=float), (schedule.batch, len(t)))
        return start[None] + preset_displacement(schedule, times).transpose(1, 0, 2)
    return start[None] + preset_displacement(schedule, t)[:, None, :]


def _schedule(scenario: Scenario, scenes: Sequence[Scenario] | None) -> Schedule:
    """The scenario's schedule, or the scenes' own when they differ (drawn routes)."""
    if scenes is None or all(s.schedule == scenario.schedule for s in scenes):
        return scenario.schedule
    return copy_schedules([s.schedule for s in scenes])


def _segment_distance(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(B, O) distance from each obstacle centre to the polyline through ``points``.

    Args:
        points: (T, B, 2) polyline vertices [m].
        centre: (O, 2) or (B, O, 2) [m].
    """
    if len(points) < 2:
        return np.linalg.norm(points[0, :, None, :] - centre, axis=-1)
    if centre.ndim == 3:
        centre = centre[None]  # (1, B, O, 2)
    a, b = points[:-1, :, None, :], points[1:, :, None, :]  # (T-1, B, 1, 2)
    ab, ac = b - a, centre - a  # (T-1, B, O, 2)
    length2 = (ab**2).sum(-1)
    s = np.clip((ac * ab).sum(-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    closest = a + s[..., None] * ab
    return np.linalg.norm(closest - centre, axis=-1).min(axis=0)


def mission_metrics(
    scenario: Scenario,
    t: np.ndarray,
    z: np.ndarray,
    collision: np.ndarray,
    min_separation: np.ndarray,
    scenes: Sequence[Scenario] | None = None,
) -> MissionMetrics:
    """The mission metrics of B episodes from their trajectories.

    Args:
        scenario: schedule, obstacles, detection margin and completion threshold.
        t: (T+1,) sample times, t[0] = 0 [s].
        z: (T+1, B, N, 6) states [m, m/s].
        collision: (T, B, N) bool, collision flags after each step.
        min_separation: (T+1, B, N) distance of each UAV to its nearest other UAV [m].
        scenes: the concrete scenario of each episode, for a scene distribution (their
            obstacles, padded to the largest count O; padding is never required nor met).
    """
    t = np.asarray(t, dtype=float)
    p, v = z[..., :3], z[..., 3:]
    centroid = p.mean(axis=2)  # (T+1, B, 3)
    route = preset_route(scenario, t, centroid[0], scenes)  # (T+1, B, 3)
    schedule = _schedule(scenario, scenes)
    if isinstance(schedule, CopySchedules):  # per-copy schedules take the copy axis first
        times = np.broadcast_to(t, (schedule.batch, len(t)))
        start = centroid[0][:, None]  # (B, 1, 3)
        off_route = route_error(schedule, times, centroid.transpose(1, 0, 2), start).T
        v_preset = preset_velocity(schedule, times).transpose(1, 0, 2)[:, :, None, :]
    else:
        off_route = route_error(schedule, t[:, None], centroid, centroid[0])  # (T+1, B)
        v_preset = preset_velocity(schedule, t)[:, None, None, :]
    velocity_error2 = ((v - v_preset) ** 2).sum(axis=-1)  # (T+1, B, N)

    batch = z.shape[1]
    avoidances = [scenario.avoidance] * batch if scenes is None else [s.avoidance for s in scenes]
    field = obstacle_field(avoidances)
    # met at the detection distance d^o, whatever distance the topology rules activate at
    margins = np.array([a.detection_margin for a in avoidances])[:, None]  # (B, 1)
    centres, present = field.centres, field.present  # (B, O, ...)
    detection = field.radii + margins  # (B, O)
    if field.count:
        distance = np.linalg.norm(p[..., None, :2] - centres[:, None], axis=-1).min(axis=2)
        within = (distance <= detection) & present  # (T+1, B, O)
        met = within.any(axis=0)
        time_met = np.where(met, t[within.argmax(axis=0)], np.nan)
        closest = np.where(present, distance.min(axis=0), np.nan)
        required = (_segment_distance(route[..., :2], centres) <= detection) & present
    else:
        met = required = np.zeros((batch, 0), dtype=bool)
        time_met = closest = np.zeros((batch, 0))

    collided = np.asarray(collision, dtype=bool).any(axis=2)  # (T, B)
    first = collided.argmax(axis=0)
    separation = np.asarray(min_separation, dtype=float)[1:].min(axis=2)  # (T, B)
    closest_step = separation.argmin(axis=0)
    return MissionMetrics(
        route_error_rms=np.sqrt((off_route**2).mean(axis=0)),
        route_error_max=off_route.max(axis=0),
        velocity_rmse=np.sqrt(velocity_error2.mean(axis=(0, 2))),
        obstacle_required=required,
        obstacle_met=met,
        obstacle_closest=closest,
        obstacle_time_met=time_met,
        collisions=np.asarray(collision, dtype=bool).sum(axis=(0, 2)),
        first_collision_time=np.where(collided.any(axis=0), t[1:][first], np.nan),
        min_separation=separation.min(axis=0),
        min_separation_time=t[1:][closest_step],
        max_route_error=scenario.mission.max_route_error,
    )


def concatenate_missions(parts: Sequence[MissionMetrics]) -> MissionMetrics:
    """The metrics of several groups of episodes as one (episodes in the order of ``parts``);
    obstacle columns are padded to the largest count (padding is neither required nor met)."""
    count = max(m.obstacle_met.shape[1] for m in parts)

    def padded(x: np.ndarray, fill: Any) -> np.ndarray:
        return np.pad(x, ((0, 0), (0, count - x.shape[1])), constant_values=fill)

    joined: dict[str, Any] = {}
    for f in fields(MissionMetrics):
        values = [getattr(m, f.name) for m in parts]
        if f.name == "max_route_error":
            joined[f.name] = values[0]
        elif f.name.startswith("obstacle_"):
            fill = False if values[0].dtype == bool else np.nan
            joined[f.name] = np.concatenate([padded(x, fill) for x in values])
        else:
            joined[f.name] = np.concatenate(values)
    return MissionMetrics(**joined)


def _nan_min(x: np.ndarray) -> float | None:
    """Smallest value ignoring NaN (an obstacle absent from a drawn scene), None if all are."""
    return None if np.isnan(x).all() else float(np.nanmin(x))


def _list(x: np.ndarray, digits: int = 6) -> list[Any]:
    return [None if np.isnan(v) else round(float(v), digits) for v in np.asarray(x, float)]


def mission_summary(metrics: MissionMetrics, seeds: list[int]) -> dict[str, Any]:
    """JSON-ready summary: per-seed values, means with 95 % confidence half-widths, the
    completion rate and every failure with its seed and causes."""
    completed = metrics.completed
    summary: dict[str, Any] = {
        "completed": int(completed.sum()),
        "episodes": len(completed),
        "completion_rate": float(completed.mean()),
        "completed_per_seed": completed.tolist(),
        "max_route_error_threshold_m": metrics.max_route_error,
    }
    for name, values in (
        ("route_error_rms_m", metrics.route_error_rms),
        ("route_error_max_m", metrics.route_error_max),
        ("velocity_rmse_mps", metrics.velocity_rmse),
    ):
        mean, half = mean_ci95(values)
        summary[name] = mean
        summary[f"{name}_ci95"] = half
        summary[f"{name}_per_seed"] = _list(values)
    summary["collisions_after_start"] = int(metrics.collisions.sum())
    summary["collisions_after_start_per_seed"] = metrics.collisions.astype(int).tolist()
    summary["first_collision_time_s_per_seed"] = _list(metrics.first_collision_time)
    summary["min_separation_after_start_m"] = float(metrics.min_separation.min())
    summary["min_separation_after_start_m_per_seed"] = _list(metrics.min_separation)
    summary["min_separation_time_s_per_seed"] = _list(metrics.min_separation_time)
    summary["obstacles"] = {
        f"O{o + 1}": {
            "required_per_seed": metrics.obstacle_required[:, o].tolist(),
            "met": int(metrics.obstacle_met[:, o].sum()),
            "met_per_seed": metrics.obstacle_met[:, o].tolist(),
            "present_per_seed": (~np.isnan(metrics.obstacle_closest[:, o])).tolist(),
            "closest_center_m": _nan_min(metrics.obstacle_closest[:, o]),
            "closest_center_m_per_seed": _list(metrics.obstacle_closest[:, o]),
            "time_met_s_per_seed": _list(metrics.obstacle_time_met[:, o]),
        }
        for o in range(metrics.obstacle_met.shape[1])
    }
    summary["failures"] = {str(seed): why for seed, why in zip(seeds, metrics.failures()) if why}
    return summary


def mission_table(summaries: dict[str, dict[str, Any]]) -> list[str]:
    """Markdown lines: one row per policy with the cost beside the mission metrics, then the
    failed seeds and their causes.

    Args:
        summaries: label -> :func:`~uav_formation_env.evaluation.summarise` output (with its
            ``"mission"`` entry).
    """
    first = next(iter(summaries.values()))["mission"]
    obstacles = list(first["obstacles"])
    head = " | ".join(f"{name} met" for name in obstacles)
    lines = [
        "| policy | mission completed | realised J / UAV (± 95% CI) | route error RMS [m] "
        f"| route error max [m] | velocity RMSE [m/s] | {head} | collisions after t = 0 "
        "| min separation after t = 0 [m] |",
        "|---" * (8 + len(obstacles)) + "|",
    ]
    failures = []
    for label, s in summaries.items():
        m = s["mission"]
        met = " | ".join(f"{m['obstacles'][o]['met']}/{m['episodes']}" for o in obstacles)
        lines.append(
            f"| {label} | **{m['completed']}/{m['episodes']}** | "
            f"{s['realised_cost_mean']:.4g} ± {s['realised_cost_ci95']:.2g} | "
            f"{m['route_error_rms_m']:.1f} ± {m['route_error_rms_m_ci95']:.1f} | "
            f"{m['route_error_max_m']:.1f} ± {m['route_error_max_m_ci95']:.1f} | "
            f"{m['velocity_rmse_mps']:.2f} | {met} | {m['collisions_after_start']} | "
            f"{m['min_separation_after_start_m']:.1f} |"
        )
        failures += [
            f"- {label}, seed {seed}: {'; '.join(why)}" for seed, why in m["failures"].items()
        ]
    lines += [
        "",
        "Completed: every obstacle the preset route passes within its detection distance is "
        "met, no collision after t = 0, and the centroid stays within "
        f"{first['max_route_error_threshold_m']:g} m of the preset route "
        "(`mission.max_route_error`). ± is the half-width of the 95% confidence interval over "
        "seeds (Student t).",
        "",
    ]
    if failures:
        lines += ["Failed episodes:", "", *failures, ""]
    else:
        lines += ["Every episode completed the mission.", ""]
    return lines
