"""Reproduction of the paper's experiment: Table 2 and Figs. 5-9 for the four variants.

The variants are {PIO, LFPIO} x {NFTSMO off, on} (docs/model.md §8), flown on the same seeds. Each
variant
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

from uav_formation_env.reproduce.figures import write_figures
from uav_formation_env.reproduce.report import build_report, trigger_outliers
from uav_formation_env.reproduce.run import Reproduction, available_cpus, reproduce
from uav_formation_env.reproduce.tables import build_summary, table2_rows, write_table2
from uav_formation_env.reproduce.variants import (
    FIGURES,
    LABELS,
    PAPER_EVENTS_S,
    PAPER_TRIGGER_MEAN,
    PAPER_TRIGGERS,
    QUICK_DURATION_S,
    VARIANTS,
    run_variant,
    variant_scenario,
)

__all__ = [
    "FIGURES",
    "LABELS",
    "PAPER_EVENTS_S",
    "PAPER_TRIGGERS",
    "PAPER_TRIGGER_MEAN",
    "QUICK_DURATION_S",
    "VARIANTS",
    "Reproduction",
    "available_cpus",
    "build_report",
    "build_summary",
    "reproduce",
    "run_variant",
    "table2_rows",
    "trigger_outliers",
    "variant_scenario",
    "write_figures",
    "write_table2",
]
