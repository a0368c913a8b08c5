"""Figures in the manner of the paper's Figs. 5-9 from the variants' episode batches."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uav_formation_env.evaluation import (
    EpisodeBatch,
)
from uav_formation_env.reproduce.variants import FIGURES, LABELS


def _log10(x: np.ndarray) -> np.ndarray:
    return np.log10(np.maximum(x, 1e-12))


def write_figures(batches: dict[str, EpisodeBatch], out: str | Path) -> list[Path]:
    """The PNGs of :data:`FIGURES` (see the module docstring)."""
    from uav_formation_env import plotting

    out = Path(out)
    first = next(iter(batches.values()))
    scenario = first.scenario
    seed = first.seeds[0]
    t = first.t
    labels = {LABELS[v]: b for v, b in batches.items()}
    written = []

    path = out / FIGURES[0]
    plotting.plot_variant_trajectories(
        {label: b.z[:, 0, :, :3] for label, b in labels.items()},
        scenario,
        path,
        suptitle=f"Fig. 5: trajectories (seed {seed})",
    )
    written.append(path)

    observed = [v for v in ("lfpio_nftsmo", "pio_nftsmo") if v in batches]
    observed += [v for v, b in batches.items() if b.scenario.observer.enabled and v not in observed]
    path = out / FIGURES[1]
    if observed:
        b = batches[observed[0]]
        plotting.plot_observer(
            t[1:],
            b.estimate[1:, 0, 0],
            b.disturbance[:, 0, 0],
            path,
            title=f"Fig. 6: NFTSMO estimate vs true disturbance, UAV1, {LABELS[observed[0]]} "
            f"(seed {seed})",
        )
    else:
        plotting.plot_observer(
            t[1:],
            np.zeros_like(first.disturbance[:, 0, 0]),
            first.disturbance[:, 0, 0],
            path,
            title="Fig. 6: no variant with the observer (estimate shown as 0)",
        )
    written.append(path)

    path = out / FIGURES[2]
    reference_source = batches[observed[0]] if observed else first
    plotting.plot_velocity_components(
        t,
        {label: b.z[:, 0, 0, 3:] for label, b in labels.items()},
        reference_source.reference_velocity[:, 0, 0],
        path,
        title=f"Fig. 7: velocity of UAV1 (seed {seed}); reference of "
        f"{LABELS[observed[0]] if observed else first.policy_name}",
    )
    written.append(path)

    path = out / FIGURES[3]
    curves, band = {}, {}
    for label, b in labels.items():
        if b.j_pre is None:
            continue
        log_mean = _log10(b.j_pre.mean(axis=2))  # (T, B)
        curves[label] = log_mean[:, 0]
        band[label] = (log_mean.min(axis=1), log_mean.max(axis=1))
    markers = _event_markers(reference_source)
    markers.update({f"turn {x:g} s": x for x in scenario.schedule.times if x < scenario.duration})
    plotting.plot_log_cost(
        t[:-1],
        curves,
        band,
        markers,
        path,
        title=f"Fig. 8: log10 of J_pre averaged over UAVs (line: seed {seed}; "
        f"band: min-max over {len(first.seeds)} seeds)",
    )
    written.append(path)

    path = out / FIGURES[4]
    last = scenario.n_uav - 1
    plotting.plot_trigger_timeline(
        t[:-1],
        {label: b.triggered[:, 0, last] for label, b in labels.items() if b.triggered is not None},
        {
            label: np.cumsum(b.triggered[:, :, last], axis=0).mean(axis=1)
            for label, b in labels.items()
            if b.triggered is not None
        },
        path,
        title=f"Fig. 9: triggers of UAV{last + 1} ((a) seed {seed}; (b) mean over "
        f"{len(first.seeds)} seeds)",
        uav_label=f"UAV{last + 1}",
    )
    written.append(path)

    path = out / FIGURES[5]
    plotting.plot_trigger_raster(
        t[:-1],
        {label: b.triggered[:, 0] for label, b in labels.items() if b.triggered is not None},
        path,
        title=f"Triggered steps of every UAV (seed {seed}; count in brackets)",
    )
    written.append(path)
    return written


def _event_markers(batch: EpisodeBatch) -> dict[str, float]:
    markers = {}
    for o in range(batch.activation_time.shape[1]):
        case = batch.case[0, o]
        kind = "split" if case == 2 else "one group"
        markers[f"O{o + 1} {kind}"] = float(batch.activation_time[0, o])
        markers[f"O{o + 1} restore"] = float(batch.restore_time[0, o])
    return markers
