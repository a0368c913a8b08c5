"""``uav-formation reproduce``: Table 2, summary, figures and report of the four variants."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

from uav_formation_env.cli import main as cli_main
from uav_formation_env.reproduce import FIGURES, VARIANTS, reproduce

VARIANT_KEYS = {
    "triggers_per_uav",
    "triggers_mean",
    "min_obstacle_center_distance_m",
    "collisions",
    "observer_rms_error",
    "events",
    "seconds_per_episode",
}


@pytest.fixture(scope="module")
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("paper")
    argv = ["reproduce", "--seeds", "2", "--quick", "--quiet", "--out", str(out)]  # 20 s
    assert cli_main(argv) == 0
    return out


def test_table2_has_four_variants_with_mean_and_std(quick_run):
    with open(quick_run / "table2.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert [r["variant"] for r in rows] == list(VARIANTS)
    uavs = [f"UAV{i}" for i in range(1, 6)]
    assert list(rows[0]) == ["variant", *uavs, "mean", *[f"{c}_std" for c in [*uavs, "mean"]]]
    for row in rows:
        values = np.array([float(row[c]) for c in uavs])
        assert ((values >= 0) & (values <= 100)).all()  # 100 steps
        assert float(row["mean"]) == pytest.approx(values.mean(), abs=0.01)
        assert all(float(row[f"{c}_std"]) >= 0 for c in [*uavs, "mean"])
    # without the observer every step triggers (docs/model.md §8 / Table 2)
    assert float(rows[0]["mean"]) == 100 and float(rows[1]["mean"]) == 100


def test_summary_has_every_key_and_observer_error_only_with_observer(quick_run):
    summary = json.loads((quick_run / "summary.json").read_text())
    variants = summary["variants"]
    assert list(variants) == ["pio", "lfpio", "pio_nftsmo", "lfpio_nftsmo"]
    assert summary["seeds"] == [0, 1] and summary["n_steps"] == 100
    for name, s in variants.items():
        assert set(s) >= VARIANT_KEYS, name
        assert len(s["triggers_per_uav"]) == 5
        assert s["triggers_mean"] == pytest.approx(np.mean(s["triggers_per_uav"]))
        assert 30.0 < s["min_obstacle_center_distance_m"] < 60.0  # passed O1, outside it
        assert isinstance(s["collisions"], int)
        assert s["seconds_per_episode"] > 0
        o1 = s["events"]["O1"]
        assert o1["activate_s"] == pytest.approx(10.0, abs=1.5)  # paper: 10 s
        assert o1["restore_s"] > o1["activate_s"]
        assert o1["case_per_seed"] == [2, 2]  # split at O1 (Fig. 5)
        if VARIANTS[name][1]:
            assert 0 < s["observer_rms_error"] < 0.05
        else:
            assert s["observer_rms_error"] is None


def test_report_reads_without_the_paper(quick_run):
    """Names spelt out at their first use, the headline metric's direction, every symbol the
    report uses defined in its reading guide, and no claim that a seed depends on its batch."""
    report = (quick_run / "REPORT.md").read_text()
    for name, expansion in (
        ("PIO", "PIO (pigeon-inspired optimisation)"),
        ("LFPIO", "LFPIO (Lévy-flight PIO)"),
        ("NFTSMO", "NFTSMO (a non-singular fast terminal sliding-mode observer"),
    ):
        first = re.search(rf"\b{name}\b", report).start()
        assert report.startswith(expansion, first), report[first : first + 80]
    assert "## Table 2: triggered steps per UAV (fewer is better)" in report
    guide = report[report.index("## How to read this report") : report.index("## Table 2")]
    assert "**fewer is better**" in guide and "**lower is better**" in guide
    for symbol in (
        "**H0**",
        "**case 1 / case 2**",
        "**d^o**",
        "**J_pre",
        "**eq. 21**",
        "**eq. 23**",
    ):
        assert symbol in guide, symbol
    assert "does not depend on the other seeds of" in report
    assert "episode depends on the other seeds" not in report  # the stale claim


def test_figures_and_report(quick_run):
    for name in FIGURES:
        assert (quick_run / name).stat().st_size > 20_000, name
    report = (quick_run / "REPORT.md").read_text()
    for number in ("572", "498.6", "513", "632", "455", "560", "12.8%", "13.6", "66.2", "1000"):
        assert number in report, number
    for label in ("PIO + NFTSMO", "LFPIO + NFTSMO", "Short run"):
        assert label in report
    for name in FIGURES:
        assert f"]({name})" in report


def test_parallel_jobs_give_the_same_numbers(tmp_path):
    kwargs = dict(seeds=[5], duration=3.0, progress=False, variants=["pio", "pio_nftsmo"])
    one = reproduce(tmp_path / "one", jobs=1, **kwargs)
    two = reproduce(tmp_path / "two", jobs=2, **kwargs)
    for variant in ("pio", "pio_nftsmo"):
        a, b = one.batches[variant], two.batches[variant]
        np.testing.assert_array_equal(a.triggered, b.triggered)
        np.testing.assert_array_equal(a.stage_cost, b.stage_cost)
        np.testing.assert_array_equal(a.z, b.z)
    assert (tmp_path / "two" / "REPORT.md").is_file()


def test_trigger_outliers_finds_the_seed_and_its_window():
    from types import SimpleNamespace

    from uav_formation_env.config_io import paper_scenario
    from uav_formation_env.reproduce import trigger_outliers

    triggered = np.zeros((1000, 4, 5), dtype=bool)
    triggered[:200] = True  # every seed: the first 40 s
    triggered[400:500, 2] = True  # seed 12: 100 more steps within 80-100 s
    batch = SimpleNamespace(
        triggered=triggered, seeds=[10, 11, 12, 13], batch_size=4, scenario=paper_scenario()
    )
    [(seed, mean, start, end, excess)] = trigger_outliers(batch)
    assert (seed, mean, start, end, excess) == (12, 300.0, 80.0, 100.0, 100.0)


def test_nash_gap_table_covers_every_variant_and_exact_solvers_are_closest(quick_run):
    with open(quick_run / "nash_gap.csv", newline="") as stream:
        rows = {r["variant"]: r for r in csv.DictReader(stream)}
    assert list(rows) == [*VARIANTS, "pso_nftsmo", "exact_nftsmo", "nash_nftsmo"]
    gap = {name: float(r["gap_median"]) for name, r in rows.items()}
    assert all(g >= 0.0 for g in gap.values())
    # iterating best responses reaches the equilibrium the others only approach
    assert gap["nash_nftsmo"] < 1e-6 < gap["lfpio_nftsmo"]
    assert gap["exact_nftsmo"] < gap["lfpio_nftsmo"] and gap["exact_nftsmo"] < gap["pio_nftsmo"]
    assert (quick_run / "fig10_nash_gap.png").stat().st_size > 10_000
    report = (quick_run / "REPORT.md").read_text()
    assert "How close to a Nash equilibrium?" in report and "LFPIO vs PIO" in report
    summary = json.loads((quick_run / "summary.json").read_text())
    assert set(summary["nash_gap"]) == set(rows)
