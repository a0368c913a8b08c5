"""Reproduction of the paper's experiment: Table 2 and Figs. 5-9 for the four variants.

The variants are {PIO, LFPIO} x {NFTSMO off, on} (SPEC §8), flown on the same seeds. Each variant
runs all its seeds as one batch (:func:`~uav_formation_env.evaluation.run_episodes`: one
``FormationSim`` of B = seeds copies and one ``NashDMPCPolicy.act_batch`` call per step); the
variants run in parallel processes (``jobs``; default one per CPU), which changes no number.
:func:`reproduce` writes to ``out``:

- ``table2.csv``: triggered steps per UAV, one row per variant, mean and sample std over seeds;
- ``summary.json``: ``{"variants": {"pio": ..., "lfpio": ..., "pio_nftsmo": ...,
  "lfpio_nftsmo": ...}, ...}``, each variant with the metrics of
  :func:`~uav_formation_env.evaluation.summarise` (triggers, realised cost, distances,
  collisions, observer error, events, timing);
- ``fig5_trajectories.png`` (paths per variant), ``fig6_observer.png`` (estimate vs true
  disturbance of UAV1), ``fig7_velocity_uav1.png`` (UAV1's v_x and v_y vs reference),
  ``fig8_log_cost.png`` (log10 of J_pre averaged over UAVs), ``fig9_triggers_uav5.png`` and
  ``fig9_triggers_all_uavs.png`` (trigger timelines); single-run figures show the first seed;
- ``REPORT.md``: our numbers beside the paper's, and why they differ;
- with ``records=True``, ``records_<variant>.csv`` (per-step records of every seed).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import queue as queue_module
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import resolve_scenario, to_dict, with_overrides
from uav_formation_env.evaluation import (
    OBSERVER_WARMUP_S,
    EpisodeBatch,
    json_ready,
    make_policy,
    run_episodes,
    summarise,
    write_json,
    write_records,
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


def _worker(args: tuple) -> tuple[str, EpisodeBatch]:
    variant, base, seeds, duration, policy_seed, channel = args

    def report(done: int) -> None:
        channel.put(done)

    return variant, run_variant(variant, base, seeds, duration, policy_seed, report)


@dataclass
class Reproduction:
    """What :func:`reproduce` produced: the episode batches and the summary it wrote."""

    batches: dict[str, EpisodeBatch]
    summary: dict[str, Any]
    out: Path


def reproduce(
    out: str | Path,
    seeds: Sequence[int] = range(5),
    scenario: str | Path | Scenario = "paper",
    duration: float | None = None,
    jobs: int = 0,
    progress: bool = True,
    records: bool = False,
    policy_seed: int | None = None,
    variants: Sequence[str] = tuple(VARIANTS),
) -> Reproduction:
    """Fly the four variants on the same seeds and write the tables, figures and report.

    Args:
        out: output directory (created).
        seeds: the episode seeds, shared by every variant.
        scenario: base scenario (name, YAML path or object); the observer is set per variant.
        duration: episode length [s] (None: the scenario's, 200 s for the paper).
        jobs: variants run in parallel processes (1: one after the other in this process;
            0: one per available CPU, at most one per variant). The numbers do not depend on it.
        progress: tqdm progress bars.
        records: also write per-step CSVs per variant.
        policy_seed: seed of the DMPC optimisers' generator (None: the first episode seed).
        variants: subset of :data:`VARIANTS` to run (all four for the report's comparison).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    base = resolve_scenario(scenario)
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise ValueError("need at least one seed")
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        raise ValueError(f"unknown variant(s) {unknown}; expected some of {list(VARIANTS)}")
    if policy_seed is None:
        policy_seed = seeds[0]
    if int(jobs) <= 0:
        jobs = available_cpus()
    jobs = max(1, min(int(jobs), len(variants)))
    start = time.perf_counter()
    batches = _run_all(list(variants), base, seeds, duration, policy_seed, jobs, progress)
    wall = time.perf_counter() - start
    batches = {v: batches[v] for v in variants}

    summary = json_ready(build_summary(batches, seeds, wall, jobs))
    write_table2(batches, out / "table2.csv")
    write_json(summary, out / "summary.json")
    write_figures(batches, out)
    (out / "REPORT.md").write_text(build_report(batches, summary))
    if records:
        for variant, batch in batches.items():
            write_records(batch, out / f"records_{variant}.csv")
    return Reproduction(batches, summary, out)


def _run_all(
    variants: list[str],
    base: Scenario,
    seeds: list[int],
    duration: float | None,
    policy_seed: int,
    jobs: int,
    progress: bool,
) -> dict[str, EpisodeBatch]:
    if jobs == 1:
        return {v: run_variant(v, base, seeds, duration, policy_seed, progress) for v in variants}
    # slowest first (LFPIO spends about twice PIO's evaluations)
    order = sorted(variants, key=lambda v: VARIANTS[v][0] != "lfpio")
    n_steps = variant_scenario(base, variants[0], duration).n_steps
    context = multiprocessing.get_context("spawn")
    with context.Manager() as manager:
        channel = manager.Queue()
        bar = tqdm(
            total=n_steps * len(variants),
            desc=f"{len(variants)} variants x {len(seeds)} seeds",
            unit="step",
            disable=not progress,
        )
        results: dict[str, EpisodeBatch] = {}
        with ProcessPoolExecutor(max_workers=jobs, mp_context=context) as pool:
            futures = [
                pool.submit(_worker, (v, base, seeds, duration, policy_seed, channel))
                for v in order
            ]
            pending = set(futures)
            while pending:
                with contextlib.suppress(queue_module.Empty):
                    bar.update(channel.get(timeout=0.2))
                for future in [f for f in pending if f.done()]:
                    pending.discard(future)
                    variant, batch = future.result()
                    results[variant] = batch
        bar.close()
    return results


def available_cpus() -> int:
    """CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# ---------------------------------------------------------------------------------------- tables
def _trigger_counts(batch: EpisodeBatch) -> np.ndarray:
    """(B, N) triggered steps per seed and UAV."""
    if batch.triggered is None:
        raise ValueError(f"variant {batch.policy_name} has no trigger records")
    return batch.triggered.sum(axis=0)


def _std(x: np.ndarray) -> np.ndarray:
    return x.std(axis=0, ddof=1) if x.shape[0] > 1 else np.zeros(x.shape[1:])


def table2_rows(batches: dict[str, EpisodeBatch]) -> list[dict[str, Any]]:
    """Table 2 as rows: variant, UAV1..UAVN and mean (means over seeds), then their std."""
    rows = []
    for variant, batch in batches.items():
        counts = _trigger_counts(batch).astype(float)  # (B, N)
        per_seed = np.concatenate((counts, counts.mean(axis=1, keepdims=True)), axis=1)
        names = [f"UAV{i + 1}" for i in range(counts.shape[1])] + ["mean"]
        row: dict[str, Any] = {"variant": variant}
        row.update({n: float(v) for n, v in zip(names, per_seed.mean(axis=0))})
        row.update({f"{n}_std": float(v) for n, v in zip(names, _std(per_seed))})
        rows.append(row)
    return rows


def write_table2(batches: dict[str, EpisodeBatch], path: str | Path) -> None:
    """``table2.csv``: columns variant, UAV1..UAVN, mean, UAV1_std..UAVN_std, mean_std."""
    rows = table2_rows(batches)
    header = list(rows[0])
    lines = [",".join(header)]
    for row in rows:
        lines.append(
            ",".join(
                row[h] if isinstance(row[h], str) else f"{row[h]:.2f}".rstrip("0").rstrip(".")
                for h in header
            )
        )
    Path(path).write_text("\n".join(lines) + "\n")


def build_summary(
    batches: dict[str, EpisodeBatch], seeds: list[int], wall: float, jobs: int
) -> dict[str, Any]:
    """The content of ``summary.json``."""
    first = next(iter(batches.values()))
    variants = {}
    for variant, batch in batches.items():
        s = summarise(batch)
        s["label"] = LABELS[variant]
        per_seed_mean = _trigger_counts(batch).mean(axis=1)  # (B,)
        s["triggers_std_over_seeds"] = float(_std(per_seed_mean[:, None])[0])
        s["paper_triggers_per_uav"] = list(PAPER_TRIGGERS[variant])
        s["paper_triggers_mean"] = PAPER_TRIGGER_MEAN[variant]
        variants[variant] = s
    return {
        "variants": variants,
        "seeds": seeds,
        "duration_s": float(first.scenario.duration),
        "n_steps": first.n_steps,
        "wall_time_s": wall,
        "jobs": jobs,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "cost": to_dict(first.scenario.cost),
        "paper": {
            "triggers_per_uav": {k: list(v) for k, v in PAPER_TRIGGERS.items()},
            "triggers_mean": PAPER_TRIGGER_MEAN,
            "events_s": PAPER_EVENTS_S,
        },
    }


# ---------------------------------------------------------------------------------------- figures
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


# ---------------------------------------------------------------------------------------- report
def _fmt(x: float | None, digits: int = 1) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    return f"{x:.{digits}f}"


def _range(values: Sequence[float | None], digits: int = 1) -> str:
    v = np.array([np.nan if x is None else x for x in values], dtype=float)
    if np.isnan(v).all():
        return "never"
    text = _fmt(float(np.nanmean(v)), digits)
    if len(v) > 1:
        text += f" [{_fmt(float(np.nanmin(v)), digits)}, {_fmt(float(np.nanmax(v)), digits)}]"
    missing = int(np.isnan(v).sum())
    if missing:
        text += f" ({missing} seed(s): never)"
    return text


def trigger_outliers(
    batch: EpisodeBatch, margin: float = 40.0, window_s: float = 20.0
) -> list[tuple[int, float, float, float, float]]:
    """Seeds whose mean trigger count exceeds the seeds' median by more than ``margin``, with
    the time window where most of the excess lies.

    Returns:
        ``(seed, mean triggers, window start [s], window end [s], excess in the window)`` per
        outlier seed.
    """
    if batch.triggered is None or batch.batch_size < 3:
        return []
    per_step = batch.triggered.mean(axis=2)  # (T, B), mean over UAVs
    per_seed = per_step.sum(axis=0)
    median = np.median(per_seed)
    steps = max(1, int(round(window_s / batch.scenario.dynamics.dt)))
    found = []
    for b in np.flatnonzero(per_seed > median + margin):
        excess = []
        for start in range(0, per_step.shape[0], steps):
            block = per_step[start : start + steps].sum(axis=0)
            excess.append(block[b] - np.median(block))
        k = int(np.argmax(excess))
        t0 = k * steps * batch.scenario.dynamics.dt
        t1 = min(t0 + window_s, batch.scenario.duration)
        found.append((batch.seeds[b], float(per_seed[b]), t0, t1, float(excess[k])))
    return found


def build_report(batches: dict[str, EpisodeBatch], summary: dict[str, Any]) -> str:
    """``REPORT.md``: our numbers beside the paper's and the reasons for each difference."""
    v = summary["variants"]
    rows = {r["variant"]: r for r in table2_rows(batches)}
    first = next(iter(batches.values()))
    n_seeds, n_steps = len(first.seeds), first.n_steps
    n_uav = first.scenario.n_uav
    full = n_steps == PAPER_STEPS
    seeds = first.seeds
    lines = [
        "# Reproduction of Yuan, Deng, Luo, Duan: Table 2 and Figs. 5–9",
        "",
        f"Generated by `uav-formation reproduce` on {summary['created']}: "
        f"{n_seeds} seed(s) ({', '.join(map(str, seeds))}), the same for every variant; "
        f"{first.scenario.duration:g} s episodes ({n_steps} steps of "
        f"{first.scenario.dynamics.dt:g} s); scenario `{first.scenario.name}`; "
        f"wall time {summary['wall_time_s']:.1f} s with {summary['jobs']} job(s). "
        "Each variant's seeds ran as one batch (one simulator and one DMPC call per step).",
        "",
        "Cost weights: "
        + ", ".join(f"{k} = {val}" for k, val in summary["cost"].items())
        + ". Paper: one run; ours: mean ± sample std over seeds.",
        "",
    ]
    if not full:
        lines += [
            f"**Short run**: {n_steps} steps instead of the paper's {PAPER_STEPS}, so trigger "
            "counts and events after the end are not comparable with the paper's.",
            "",
        ]

    # Table 2
    head = " | ".join(f"UAV{i + 1}" for i in range(n_uav))
    lines += [
        "## Table 2: triggered steps per UAV",
        "",
        f"| variant | {head} | mean | paper (UAV1–5) | paper mean |",
        "|---" * (n_uav + 4) + "|",
    ]
    for variant, row in rows.items():
        cells = [f"{row[f'UAV{i + 1}']:.1f} ± {row[f'UAV{i + 1}_std']:.1f}" for i in range(n_uav)]
        paper = " / ".join(f"{x:g}" for x in PAPER_TRIGGERS[variant])
        lines.append(
            f"| {LABELS[variant]} | "
            + " | ".join(cells)
            + f" | **{row['mean']:.1f} ± {row['mean_std']:.1f}** | {paper} | "
            f"{PAPER_TRIGGER_MEAN[variant]:g} |"
        )
    lines += ["", "Triggers per seed (mean over UAVs), and seeds far above the median:", ""]
    for variant, batch in batches.items():
        per_seed = _trigger_counts(batch).mean(axis=1)
        text = ", ".join(f"{seed}: {x:.1f}" for seed, x in zip(batch.seeds, per_seed))
        lines.append(f"- {LABELS[variant]}: median {np.median(per_seed):.1f}; {text}")
        for seed, mean, start, end, excess in trigger_outliers(batch):
            lines.append(
                f"  - seed {seed} ({mean:.1f}): {excess:.0f} more triggers per UAV than the "
                f"seeds' median within {start:g}–{end:g} s"
            )
    lines.append("")

    # Events
    ref = "lfpio_nftsmo" if "lfpio_nftsmo" in v else next(iter(v))
    events = v[ref]["events"]
    lines += [
        f"## Events ({LABELS[ref]}; mean [min, max] over seeds, in s)",
        "",
        "| event | paper | ours |",
        "|---|---|---|",
    ]
    o1, o2 = events.get("O1"), events.get("O2")
    if o1:
        split = sum(c == 2 for c in o1["case_per_seed"])
        lines.append(
            f"| O1 topology change ({split}/{n_seeds} seeds split, case 2) | 10 | "
            f"{_range(o1['activate_s_per_seed'])} |"
        )
        lines.append(f"| O1 restore | 13.6 | {_range(o1['restore_s_per_seed'])} |")
    if o2:
        one = sum(c == 1 for c in o2["case_per_seed"])
        lines.append(
            f"| O2 encounter ({one}/{n_seeds} seeds one group, case 1) | 66.2 | "
            f"{_range(o2['activate_s_per_seed'])} |"
        )
        lines.append(f"| O2 restore | – | {_range(o2['restore_s_per_seed'])} |")
    lines += ["", "Other variants (activation / restore means, s):", ""]
    for variant, s in v.items():
        parts = [
            f"{name} {_fmt(e['activate_s'])} / {_fmt(e['restore_s'])}"
            for name, e in s["events"].items()
        ]
        lines.append(f"- {LABELS[variant]}: " + "; ".join(parts))
    lines.append("")

    # Safety, observer, cost, timing
    lines += [
        "## Safety, observer, cost and timing",
        "",
        "| variant | min dist. to obstacle centre [m] | min separation [m] | collisions "
        f"| observer rms (t > {OBSERVER_WARMUP_S:g} s) [m/s²] | formation RMSE [m] "
        "| realised cost / UAV | s per episode |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for variant, s in v.items():
        rms = (
            "null (no observer)"
            if s["observer_rms_error"] is None
            else (f"{s['observer_rms_error']:.4f}")
        )
        lines.append(
            f"| {LABELS[variant]} | {_fmt(s['min_obstacle_center_distance_m'])} | "
            f"{_fmt(s['min_separation_m'])} | {s['collisions']} | {rms} | "
            f"{_fmt(s['formation_rmse_m'])} | {s['realised_cost_mean']:.4g} | "
            f"{s['seconds_per_episode']:.2f} |"
        )
    lines += [
        "",
        "Safety circle R_s = 40 m from the centre (obstacle radius 30 m). The realised cost is "
        "Σ over the episode of UAV i's stage cost J_i (the env's −reward), mean over UAVs and "
        "seeds. Seconds per episode = the variant's batch wall time / seeds.",
        "",
    ]

    lines += ["## Figures", ""]
    captions = {
        "fig5_trajectories.png": "Fig. 5: top view of the paths per variant with the obstacles "
        "and safety circles.",
        "fig6_observer.png": "Fig. 6: NFTSMO estimate (d̂ + s0) against the true disturbance, "
        "UAV1, three axes.",
        "fig7_velocity_uav1.png": "Fig. 7: UAV1's v_x and v_y for the four variants against "
        "the reference.",
        "fig8_log_cost.png": "Fig. 8: log10 of J_pre (the warm-start cost the trigger "
        "compares) averaged over UAVs, events and turns marked.",
        "fig9_triggers_uav5.png": "Fig. 9: triggered steps of UAV5 per variant and their "
        "cumulative count.",
        "fig9_triggers_all_uavs.png": "Triggered steps of every UAV per variant.",
    }
    for name in FIGURES:
        lines.append(f"- [{name}]({name}): {captions[name]}")
    lines.append("")
    lines += ["## Why our numbers differ from the paper's", ""]
    lines += _explanations(v, rows, n_seeds, n_steps, full, summary["cost"])
    return "\n".join(lines) + "\n"


def _explanations(
    v: dict[str, Any],
    rows: dict[str, dict],
    n_seeds: int,
    n_steps: int,
    full: bool,
    cost: dict[str, Any],
) -> list[str]:
    out: list[str] = []
    has_separation = bool(cost.get("separation", 0))
    out.append(
        f"- **Mean over {n_seeds} seed(s) vs one run.** The paper reports a single run; "
        "we report the mean over seeds with the start positions drawn at random (x ∈ [0, 40] m, "
        "y ∈ [−40, 40] m, SPEC §8: the paper does not give them) and the eq. 21 noise "
        "redrawn per seed. The spread between seeds (± above) is the scale on which a single "
        "run can differ from our mean. A seed's episode also depends on the other seeds of its "
        "batch: the DMPC's optimisers of all copies draw from one random generator, so seed 0 "
        "of a 5-seed run is not seed 0 of a 10-seed run (same statistics, different samples)."
    )
    for variant in ("pio", "lfpio"):
        if variant not in rows:
            continue
        counts = np.asarray(v[variant]["triggers_per_uav_per_seed"])
        missed = int(counts.size * n_steps - counts.sum())
        if missed == 0:
            out.append(
                f"- **{LABELS[variant]} without observer: every UAV triggered at all {n_steps} "
                f"steps in every seed{', as in the paper' if full else ''}.** The uncompensated "
                "disturbance keeps J_i(W) above the threshold 10."
            )
        else:
            out.append(
                f"- **{LABELS[variant]} without observer: {rows[variant]['mean']:.1f} of "
                f"{n_steps} steps** (paper: 1000 of 1000): {missed} of {counts.size * n_steps} "
                "UAV-steps over all seeds had J_i(W) ≤ 10, rare moments when the uncompensated "
                "disturbance (eq. 21 sinusoids plus the 0.1 rand noise) left the warm start's "
                "predicted errors small. The paper's single run had none."
            )
    obs_variants = [x for x in ("pio_nftsmo", "lfpio_nftsmo") if x in rows]
    unstated = (
        "The trigger count depends on parameters the paper does not give: the cost weights "
        "(q, r, m, n) (SPEC §4.4 chose them by calibration), the population size N_p = 30 "
        "(SPEC §6: N_p = 20/30/50 gave 527/505/486 triggers in one calibration run), "
        "u_max = 5 m/s², the NFTSMO gains and the reading of '0.1 rand' (per axis, redrawn "
        "every step). SPEC §8's calibration with these defaults found about 469 (PIO) and 458 "
        "(LFPIO) with 1–2 seeds."
    )
    for variant in obs_variants:
        mean = rows[variant]["mean"]
        paper = PAPER_TRIGGER_MEAN[variant]
        if full:
            out.append(
                f"- **{LABELS[variant]}: {mean:.1f} ± {rows[variant]['mean_std']:.1f} vs the "
                f"paper's {paper:g} ({100 * (mean / paper - 1):+.1f}%).** " + unstated
            )
        else:
            out.append(
                f"- **{LABELS[variant]}: {mean:.1f} of {n_steps} steps** (paper: {paper:g} of "
                f"{PAPER_STEPS}). Not comparable: the first seconds (formation assembly from the "
                "random start box, the O1 avoidance) trigger almost every step; the paper's "
                "savings come from the straight legs later on. " + unstated
            )
    if len(obs_variants) == 2:
        pio = rows["pio_nftsmo"]["mean"]
        lf = rows["lfpio_nftsmo"]["mean"]
        reduction = 1 - lf / pio if pio > 0 else float("nan")
        pio_seeds = np.asarray(v["pio_nftsmo"]["triggers_per_uav_per_seed"], dtype=float)
        lf_seeds = np.asarray(v["lfpio_nftsmo"]["triggers_per_uav_per_seed"], dtype=float)
        diff = pio_seeds.mean(axis=1) - lf_seeds.mean(axis=1)  # paired by seed
        wins = int((diff > 0).sum())
        sem = diff.std(ddof=1) / np.sqrt(len(diff)) if len(diff) > 1 else float("nan")
        ratio_pio = v["pio_nftsmo"].get("optimiser_cost_ratio_median")
        ratio_lf = v["lfpio_nftsmo"].get("optimiser_cost_ratio_median")
        ratios = ""
        if ratio_pio is not None and ratio_lf is not None:
            ratios = (
                f" Measured in this run: on a triggered step the optimiser's output costs "
                f"(median) {100 * ratio_pio:.2f}% of the warm start's J_i with PIO and "
                f"{100 * ratio_lf:.2f}% with LFPIO. Most of J_i is formation and velocity error "
                "that the UAV's own five inputs cannot remove within the 1 s horizon: a one-off "
                "check (seed 0, 0–80 s, L-BFGS-B on the exact quadratic J_i of the paper, without "
                "separation term, over the same box) "
                "put the true optimum only about 0.1% below J_i(W) as well, and both optimisers "
                "closed about three quarters of that small gap. So a better optimiser has "
                "almost nothing to gain per step, and PIO and LFPIO leave the swarm in nearly "
                "the same state."
            )
        direction = (
            f"{100 * reduction:.1f}% fewer triggers with LFPIO"
            if reduction >= 0
            else f"{-100 * reduction:.1f}% more triggers with LFPIO"
        )
        medians = [np.median(x.mean(axis=1)) for x in (pio_seeds, lf_seeds)]
        out.append(
            f"- **LFPIO vs PIO with the observer: {direction} (medians over seeds "
            f"{medians[0]:.1f} vs {medians[1]:.1f}; paired difference PIO − LFPIO "
            f"{np.mean(diff):.1f} ± {sem:.1f} (s.e.) triggers per UAV, "
            f"LFPIO lower in {wins}/{n_seeds} seeds) vs the paper's "
            f"{100 * PAPER_LFPIO_REDUCTION:.1f}%.** SPEC §8's calibration also found LFPIO only "
            "about 2% better. Both optimisers start from the warm start W as global best and "
            "never return anything worse"
            + (
                ""
                if has_separation
                else ", and J_i is an exactly quadratic function of the 15 inputs"
            )
            + " (budgets: LFPIO 1830 evaluations, PIO 810). With one scalar `rand` per "
            "pigeon and iteration (SPEC §6; a per-dimension rand raised LFPIO's lead to "
            "about 8% in one calibration seed) the Lévy step is the only difference left."
            + ratios
            + " The paper's 12.8% comes from one run. Single seeds can also add about 100 "
            "triggers per UAV when the formation takes long to re-form after an avoidance (see "
            "the per-seed list under Table 2): with a few seeds, which variant draws such a seed "
            "decides the comparison."
        )
    ref = "lfpio_nftsmo" if "lfpio_nftsmo" in v else next(iter(v))
    events = v[ref]["events"]
    if "O1" in events:
        act, res = events["O1"]["activate_s"], events["O1"]["restore_s"]
        out.append(
            f"- **O1 split at {_fmt(act)} s (paper 10 s).** Detection when a UAV in the "
            "obstacle strip comes within d^o = 70 m of the centre (SPEC §7, a proposed value); "
            "the time depends on the random start box (the leading UAV starts at x ≤ 40 m)."
        )
        later = "" if res is None else f"; ours {res - 13.6:+.1f} s"
        out.append(
            f"- **O1 restore at {_fmt(res)} s (paper 13.6 s{later}).** The paper does not say "
            "when a UAV has passed the obstacle. Our rule (docs/deviations.md §1): a group ends "
            "when none of its members is left in the obstacle strip (all abreast of the centre "
            "or laterally clear), and H0 returns when every group has ended, so the restore "
            "waits for the last member of the V (the V is 20 m deep). SPEC's calibration, with "
            "the guide-abreast rule, found 15.2–15.6 s."
        )
    if "O2" in events and events["O2"]["activate_s"] is not None:
        act = events["O2"]["activate_s"]
        out.append(
            f"- **O2 encounter at {_fmt(act)} s (paper 66.2 s).** After the turn at 50 s the V "
            "heads +y stretched along the track; when it meets O2 depends on where the formation "
            "sits laterally after the turn and on d^o (SPEC §7: 63.6–69.8 s in calibration, "
            "depending on the weights)."
        )
    elif "O2" in events and full:
        out.append("- **O2 was never activated** in this run (the paper meets it at 66.2 s).")
    cases = {
        LABELS[k]: sum(c == 2 for c in s["events"]["O2"]["case_per_seed"])
        for k, s in v.items()
        if "O2" in s["events"]
    }
    if any(cases.values()):
        out.append(
            "- **O2 split in some seeds** (paper: passed as one group, case 1): "
            + ", ".join(f"{k} {c}/{n_seeds}" for k, c in cases.items())
            + ". When the V reaches O2 straddling the obstacle's centre line it splits (case 2) "
            "as at O1; which case occurs depends on the swarm's lateral position relative to "
            "O2 when it is detected."
        )
    rms = [s["observer_rms_error"] for s in v.values() if s["observer_rms_error"] is not None]
    if rms:
        spread = (
            f"{min(rms):.4f}" if max(rms) - min(rms) < 5e-5 else (f"{min(rms):.4f}–{max(rms):.4f}")
        )
        out.append(
            f"- **Observer**: rms(estimate − d) = {spread} m/s² after "
            f"{OBSERVER_WARMUP_S:g} s (SPEC §8 calibration: about 0.010). The paper shows Fig. 6 "
            "only qualitatively. Our error looks like white noise at the step rate (Fig. 6, "
            "bottom panel), consistent with the observer lagging the 0.1 rand noise, which is "
            "redrawn every step."
            + (
                " It is the same in both observer variants: the observer knows the applied "
                "input, so its error does not depend on the controller, and the disturbance "
                "depends only on the seed."
                if len(rms) > 1 and max(rms) - min(rms) < 1e-9
                else ""
            )
        )
    dists = [s["min_obstacle_center_distance_m"] for s in v.values()]
    dists = [d for d in dists if d is not None]
    if dists:
        closest = min(dists)
        where = (
            "outside the safety circle"
            if closest >= 40.0
            else f"{40.0 - closest:.1f} m inside the 40 m safety circle, outside the 30 m obstacle"
            if closest >= 30.0
            else "INSIDE the obstacle"
        )
        out.append(
            f"- **Clearance**: closest approach to an obstacle centre {closest:.1f} m over all "
            f"variants and seeds ({where}; SPEC §7 calibration: 37.7 m at O1, 39.5 m at O2). The "
            "tangent reference enters only through the cost's velocity term and is not a hard "
            "constraint, so UAVs can come inside the safety circle. The paper gives no "
            "distances."
        )
    collisions = {LABELS[k]: s["collisions"] for k, s in v.items() if s["collisions"]}
    if has_separation:
        separation = (
            f"Our J_i adds a separation penalty (weight {cost['separation']:g} below "
            f"{cost.get('separation_distance', float('nan')):g} m, docs/deviations.md), which "
            "the paper's does not have; it acts only within the 1 s horizon."
        )
    else:
        separation = "The paper's J_i has no separation term and neither has ours here."
    if collisions:
        ranges = [s["collision_time_range_s"] for s in v.values() if s["collisions"]]
        first = min(r[0] for r in ranges)
        last = max(r[1] for r in ranges)
        o1 = [s["events"].get("O1", {}).get("activate_s") for s in v.values()]
        o1 = [x for x in o1 if x is not None]
        when = f"between t = {first:g} s and {last:g} s"
        if o1 and last < min(o1):
            when += (
                ", all before O1: UAVs starting at random positions in the box cross each "
                "other's paths while they assemble the V"
            )
        out.append(
            "- **Collisions** (UAV-steps closer than the collision distance to another UAV, "
            "summed over seeds): "
            + ", ".join(f"{k} {c}" for k, c in collisions.items())
            + f", {when}. {separation} The paper reports none."
        )
    out.append(
        "- **Timing**: the paper gives no computation times. Ours are wall times of this "
        "machine for the batched runs (all seeds of a variant in one simulator and one "
        "policy call per step)."
    )
    return out
