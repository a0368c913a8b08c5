"""Writing results: JSON with numpy values, and per-step records as CSV."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.evaluation.runner import EpisodeBatch


def json_ready(obj: Any) -> Any:
    """``obj`` with every non-finite float replaced by None (so the JSON is standard)."""
    if isinstance(obj, dict):
        return {k: json_ready(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_ready(v) for v in obj]
    if isinstance(obj, float | np.floating) and not np.isfinite(obj):
        return None
    return obj


def write_json(obj: Any, path: str | Path) -> None:
    """Standard JSON (non-finite floats as null), indented."""
    Path(path).write_text(json.dumps(json_ready(obj), indent=2, allow_nan=False))


RECORD_COLUMNS = (
    ["seed", "step", "t", "uav", "x", "y", "z", "vx", "vy", "vz", "vref_x", "vref_y", "vref_z"]
    + ["un_x", "un_y", "un_z", "u_x", "u_y", "u_z", "d_x", "d_y", "d_z"]
    + ["dhat_x", "dhat_y", "dhat_z", "group", "J_stage", "obstacle_surface_m", "min_separation_m"]
    + ["collision", "triggered", "J_pre", "J_exec"]
)


def write_records(batch: EpisodeBatch, path: str | Path, append: bool = False) -> None:
    """Per-step CSV, one row per seed, step (1..T) and UAV (1..N), columns
    :data:`RECORD_COLUMNS`: the state, reference, estimate, group and distances after the step;
    the inputs, disturbance and stage cost of the step; the policy's trigger and J values of the
    decision that produced the step's input (empty for policies without records).
    ``append``: add the rows to an existing table (no header), e.g. batch after batch."""
    T, B, N = batch.stage_cost.shape
    seed = np.broadcast_to(np.asarray(batch.seeds)[None, :, None], (T, B, N))
    step = np.broadcast_to(np.arange(1, T + 1)[:, None, None], (T, B, N))
    t = np.broadcast_to(batch.t[1:, None, None], (T, B, N))
    uav = np.broadcast_to(np.arange(1, N + 1)[None, None, :], (T, B, N))
    empty = np.full((T, B, N), np.nan)
    columns = [
        seed,
        step,
        t,
        uav,
        *np.moveaxis(batch.z[1:], -1, 0),
        *np.moveaxis(batch.reference_velocity[1:], -1, 0),
        *np.moveaxis(batch.u_n, -1, 0),
        *np.moveaxis(batch.u_applied, -1, 0),
        *np.moveaxis(batch.disturbance, -1, 0),
        *np.moveaxis(batch.estimate[1:], -1, 0),
        batch.groups[1:],
        batch.stage_cost,
        batch.obstacle_surface[1:],
        batch.min_separation[1:],
        batch.collision,
        empty if batch.triggered is None else batch.triggered,
        empty if batch.j_pre is None else batch.j_pre,
        empty if batch.j_exec is None else batch.j_exec,
    ]
    # rows ordered by seed, then step, then UAV
    table = np.stack([np.moveaxis(np.asarray(c, dtype=float), 1, 0) for c in columns], axis=-1)
    table = table.reshape(-1, len(columns))
    integer = {"seed", "step", "uav", "group", "collision", "triggered"}
    formats = ["%d" if name in integer else "%.6g" for name in RECORD_COLUMNS]
    if batch.triggered is None:
        formats[RECORD_COLUMNS.index("triggered")] = "%.6g"
    with open(path, "a" if append else "w", newline="") as stream:
        if not append:
            stream.write(",".join(RECORD_COLUMNS) + "\n")
        np.savetxt(stream, table, fmt=formats, delimiter=",")


def read_records(path: str | Path) -> list[dict[str, str]]:
    """The rows of a :func:`write_records` CSV as dicts (for tests and quick looks)."""
    with open(path, newline="") as stream:
        return list(csv.DictReader(stream))
