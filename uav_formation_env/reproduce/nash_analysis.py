"""How close each solver's plans come to a Nash equilibrium of the horizon game.

At every control step each UAV's plan is compared with its exact best response to the others'
plans (:func:`~uav_formation_env.policies.nash.nash_gap`): the gap ``J_i(plan) - min J_i`` is 0 at
a Nash equilibrium. Writes ``nash_gap.csv`` (one row per variant), ``fig10_nash_gap.png`` (the
gap over time) and the report's section on it.
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from uav_formation_env.evaluation import EpisodeBatch, nash_gap_summary, summarise
from uav_formation_env.reproduce.variants import variant_label

NASH_FIGURE = "fig10_nash_gap.png"
NASH_COLUMNS = (
    "variant",
    "label",
    "gap_median",
    "gap_p90",
    "gap_mean",
    "relative_gap_median",
    "relative_gap_p90",
    "in_box_fraction",
    "gap_median_triggered",
    "gap_median_untriggered",
    "realised_cost_mean",
    "triggers_mean",
    "policy_ms_per_step",
)


def nash_rows(batches: dict[str, EpisodeBatch]) -> list[dict[str, Any]]:
    """One row per variant with a measured Nash gap (columns :data:`NASH_COLUMNS`)."""
    rows = []
    for variant, batch in batches.items():
        gap = nash_gap_summary(batch)
        if gap is None or "median" not in gap:
            continue
        s = summarise(batch)
        by_trigger = {True: None, False: None}
        if batch.triggered is not None and batch.nash_gap is not None:
            for flag in by_trigger:
                pick = batch.nash_in_box & (batch.triggered == flag)
                if pick.any():
                    by_trigger[flag] = float(np.median(batch.nash_gap[pick]))
        rows.append(
            {
                "variant": variant,
                "label": variant_label(variant),
                "gap_median": gap["median"],
                "gap_p90": gap["p90"],
                "gap_mean": gap["mean"],
                "relative_gap_median": gap["relative_median"],
                "relative_gap_p90": gap["relative_p90"],
                "in_box_fraction": gap["in_box_fraction"],
                "gap_median_triggered": by_trigger[True],
                "gap_median_untriggered": by_trigger[False],
                "realised_cost_mean": s["realised_cost_mean"],
                "triggers_mean": s["triggers_mean"],
                # per batched step divided by the seeds: the time of one episode's step
                "policy_ms_per_step": 1e3 * s["policy_time_per_step_s"] / batch.batch_size,
            }
        )
    return rows


def write_nash_table(rows: list[dict[str, Any]], path: str | Path) -> None:
    """``nash_gap.csv``."""
    with open(path, "w", newline="") as stream:
        writer = csv.DictWriter(stream, fieldnames=NASH_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)


def nash_gap_figure(batches: dict[str, EpisodeBatch]) -> Figure:
    """Fig. 10: log10 of the Nash gap over time, median over UAVs and seeds (in-box plans only),
    one panel per solver (lines that would lie on one another each get their own panel)."""
    curves = {
        variant_label(variant): (batch.t[:-1], _median_log_gap(batch))
        for variant, batch in batches.items()
        if batch.nash_gap is not None and batch.nash_in_box is not None
    }
    fig = Figure(figsize=(11, 1.6 * max(len(curves), 1) + 1.2))
    FigureCanvasAgg(fig)
    axes = fig.subplots(max(len(curves), 1), 1, sharex=True, sharey=True, squeeze=False)[:, 0]
    for k, (label, (t, curve)) in enumerate(curves.items()):
        ax = axes[k]
        for other, (t_other, curve_other) in curves.items():  # the others, faint, to compare
            if other != label:
                ax.plot(t_other, curve_other, color="0.8", lw=0.6)
        ax.plot(t, curve, color=f"C{k % 10}", lw=0.9)
        ax.set_title(label, fontsize=9, loc="left")
        ax.grid(alpha=0.3)
    axes[-1].set_xlabel("t [s]")
    fig.supylabel("log10 Nash gap (median over UAVs, seeds)", fontsize=9)
    fig.suptitle(
        "Distance of the plans from a Nash equilibrium of the horizon game "
        "(one panel per solver; the others in grey)"
    )
    fig.tight_layout()
    return fig


def _median_log_gap(batch: EpisodeBatch) -> np.ndarray:
    """(T,) log10 of the median in-box Nash gap over UAVs and seeds per step (NaN at a step
    without an in-box plan)."""
    gap = np.where(batch.nash_in_box, np.maximum(batch.nash_gap, 0.0), np.nan)
    flat = gap.reshape(len(gap), -1)
    median = np.full(len(flat), np.nan)
    some = ~np.isnan(flat).all(axis=1)  # nanmedian of an all-NaN row warns
    median[some] = np.nanmedian(flat[some], axis=1)
    return np.log10(median + 1e-12)


def plot_nash_gap(batches: dict[str, EpisodeBatch], path: str | Path) -> Path:
    """Write :func:`nash_gap_figure` as a PNG (cropped to what is drawn, legend included)."""
    nash_gap_figure(batches).savefig(path, dpi=120, bbox_inches="tight")
    return Path(path)


def _value(x: float | None, digits: int = 3) -> str:
    return "–" if x is None else f"{x:.{digits}g}"


def nash_report_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The report's section: the table and what it says beyond trigger counts."""
    if not rows:
        return []
    lines = [
        "## How close to a Nash equilibrium? (beyond the paper)",
        "",
        "At every step each UAV's plan is compared with its exact best response to the plans "
        "it receives (a box-constrained QP: the prediction is linear and J_i quadratic in the "
        "own inputs). The gap J_i(plan) − min J_i is 0 at a Nash equilibrium of the horizon "
        "game. Statistics over UAV-steps whose plan lies in the UAV's box (the rest: "
        "`in box`); relative = gap / J_i(plan); ms per step: the policy's time per episode-step "
        f"(batched seeds divided by their number). Over time: [{NASH_FIGURE}]({NASH_FIGURE}).",
        "",
        "| variant | gap median | gap p90 | gap mean | relative median | relative p90 | in box "
        "| realised cost per UAV | triggers per UAV | ms per step |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['label']} | {_value(r['gap_median'])} | {_value(r['gap_p90'])} "
            f"| {_value(r['gap_mean'])} | {_value(r['relative_gap_median'])} "
            f"| {_value(r['relative_gap_p90'])} | {r['in_box_fraction']:.3f} "
            f"| {r['realised_cost_mean']:.4g} | {_value(r['triggers_mean'], 4)} "
            f"| {r['policy_ms_per_step']:.2f} |"
        )
    by_variant = {r["variant"]: r for r in rows}
    lines += ["", *_findings(by_variant), ""]
    return lines


def _split(row: dict[str, Any]) -> str:
    """Where a DMPC variant's gap lies: triggered vs untriggered steps."""
    on, off = row["gap_median_triggered"], row["gap_median_untriggered"]
    if on is None or off is None:
        return "every step was triggered" if off is None else "no step was triggered"
    return f"median {_value(on)} on triggered steps, {_value(off)} on untriggered ones"


def _findings(by_variant: dict[str, dict[str, Any]]) -> list[str]:
    out = []
    lfpio, pio = by_variant.get("lfpio_nftsmo"), by_variant.get("pio_nftsmo")
    if lfpio and pio:
        closer = "closer to" if lfpio["gap_median"] < pio["gap_median"] else "no closer to"
        out.append(
            f"- **LFPIO vs PIO.** LFPIO's plans are {closer} equilibrium than PIO's (median gap "
            f"{_value(lfpio['gap_median'])} vs {_value(pio['gap_median'])}, p90 "
            f"{_value(lfpio['gap_p90'])} vs {_value(pio['gap_p90'])}, at "
            f"{lfpio['policy_ms_per_step']:.2f} vs {pio['policy_ms_per_step']:.2f} ms per step). "
            f"LFPIO: {_split(lfpio)}; PIO: {_split(pio)}. An untriggered UAV keeps its shifted "
            "warm start, which is not a best response to its neighbours' new plans, so the "
            "event trigger trades distance from equilibrium for computation."
        )
    for key, what in (
        ("exact_nftsmo", "Solving the one best response per step exactly"),
        ("nash_nftsmo", "Iterating best responses to equilibrium on triggered steps"),
        ("pso_nftsmo", "PSO with LFPIO's evaluation budget"),
    ):
        row = by_variant.get(key)
        if row:
            out.append(
                f"- **{row['label']}.** {what}: median gap {_value(row['gap_median'])} "
                f"(p90 {_value(row['gap_p90'])}; {_split(row)}), realised cost per UAV "
                f"{row['realised_cost_mean']:.4g}, {row['policy_ms_per_step']:.2f} ms per step."
            )
    return out
