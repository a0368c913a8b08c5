"""Figures in the manner of the paper's Figs. 5-9 from the variants' episode batches.

:func:`draw_figures` draws them (matplotlib figures keyed by the names of :data:`FIGURES`);
:func:`write_figures` writes them as PNGs. Fig. 5 has one zoom panel per obstacle under each
variant's paths; Fig. 8's title repeats its y label (:data:`FIG8_QUANTITY`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from uav_formation_env.evaluation import (
    EpisodeBatch,
)
from uav_formation_env.reproduce.variants import FIGURES, LABELS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

# what Fig. 8 plots, with its unit: its y label, repeated in its title
FIG8_QUANTITY = "log10 of J_pre averaged over UAVs [-]"


def _log10(x: np.ndarray) -> np.ndarray:
    return np.log10(np.maximum(x, 1e-12))


def _seeds(n: int) -> str:
    return f"{n} seed" if n == 1 else f"{n} seeds"


def write_figures(batches: dict[str, EpisodeBatch], out: str | Path) -> list[Path]:
    """The PNGs of :data:`FIGURES` in ``out`` (see :func:`draw_figures`)."""
    from uav_formation_env import plotting

    out = Path(out)
    written = []
    for name, fig in draw_figures(batches).items():
        fig.savefig(out / name, dpi=plotting.DPI)
        written.append(out / name)
    return written


def draw_figures(batches: dict[str, EpisodeBatch]) -> dict[str, Figure]:
    """The figures of :data:`FIGURES`, by file name, in that order (nothing written).

    Single-run panels show the first seed of each batch; Fig. 8's band and Fig. 9 (b) are over
    all seeds.
    """
    from uav_formation_env import plotting

    first = next(iter(batches.values()))
    scenario = first.scenario
    seed = first.seeds[0]
    t = first.t
    labels = {LABELS[v]: b for v, b in batches.items()}
    figures: dict[str, Figure] = {}

    zooms = "; under each variant a zoom on each obstacle" if scenario.avoidance.obstacles else ""
    figures[FIGURES[0]] = plotting.plot_variant_trajectories(
        {label: b.z[:, 0, :, :3] for label, b in labels.items()},
        scenario,
        suptitle=f"Fig. 5: trajectories (seed {seed}){zooms}",
    )

    observed = [v for v in ("lfpio_nftsmo", "pio_nftsmo") if v in batches]
    observed += [v for v, b in batches.items() if b.scenario.observer.enabled and v not in observed]
    if observed:
        b = batches[observed[0]]
        figures[FIGURES[1]] = plotting.plot_observer(
            t[1:],
            b.estimate[1:, 0, 0],
            b.disturbance[:, 0, 0],
            title=f"Fig. 6: NFTSMO estimate vs true disturbance, UAV1, {LABELS[observed[0]]} "
            f"(seed {seed})",
        )
    else:
        figures[FIGURES[1]] = plotting.plot_observer(
            t[1:],
            np.zeros_like(first.disturbance[:, 0, 0]),
            first.disturbance[:, 0, 0],
            title="Fig. 6: no variant with the observer (estimate shown as 0)",
        )

    reference_source = batches[observed[0]] if observed else first
    figures[FIGURES[2]] = plotting.plot_velocity_components(
        t,
        {label: b.z[:, 0, 0, 3:] for label, b in labels.items()},
        reference_source.reference_velocity[:, 0, 0],
        title=f"Fig. 7: velocity of UAV1 (seed {seed}); reference of "
        f"{LABELS[observed[0]] if observed else first.policy_name}",
    )

    curves, band = {}, {}
    for label, b in labels.items():
        if b.j_pre is None:
            continue
        log_mean = _log10(b.j_pre.mean(axis=2))  # (T, B)
        curves[label] = log_mean[:, 0]
        band[label] = (log_mean.min(axis=1), log_mean.max(axis=1))
    markers = _event_markers(reference_source)
    markers.update({f"turn {x:g} s": x for x in scenario.schedule.times if x < scenario.duration})
    figures[FIGURES[3]] = plotting.plot_log_cost(
        t[:-1],
        curves,
        band,
        markers,
        title=f"Fig. 8: {FIG8_QUANTITY}\n(line: seed {seed}; band: min-max over "
        f"{_seeds(len(first.seeds))})",
        ylabel=FIG8_QUANTITY,
    )

    last = scenario.n_uav - 1
    figures[FIGURES[4]] = plotting.plot_trigger_timeline(
        t[:-1],
        {label: b.triggered[:, 0, last] for label, b in labels.items() if b.triggered is not None},
        {
            label: np.cumsum(b.triggered[:, :, last], axis=0).mean(axis=1)
            for label, b in labels.items()
            if b.triggered is not None
        },
        title=f"Fig. 9: triggers of UAV{last + 1} ((a) seed {seed}; (b) mean over "
        f"{_seeds(len(first.seeds))})",
        uav_label=f"UAV{last + 1}",
    )

    figures[FIGURES[5]] = plotting.plot_trigger_raster(
        t[:-1],
        {label: b.triggered[:, 0] for label, b in labels.items() if b.triggered is not None},
        title=f"Triggered steps of every UAV (seed {seed}; count in brackets)",
    )
    return figures


def _event_markers(batch: EpisodeBatch) -> dict[str, float]:
    markers = {}
    for o in range(batch.activation_time.shape[1]):
        case = batch.case[0, o]
        kind = "split" if case == 2 else "one group"
        markers[f"O{o + 1} {kind}"] = float(batch.activation_time[0, o])
        markers[f"O{o + 1} restore"] = float(batch.restore_time[0, o])
    return markers
