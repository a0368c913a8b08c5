"""The "why our numbers differ" section of ``REPORT.md``, one paragraph per finding."""

from __future__ import annotations

from typing import Any

import numpy as np

from uav_formation_env.evaluation import (
    OBSERVER_WARMUP_S,
)
from uav_formation_env.reproduce.variants import (
    LABELS,
    PAPER_LFPIO_REDUCTION,
    PAPER_STEPS,
    PAPER_TRIGGER_MEAN,
)


def fmt_number(x: float | None, digits: int = 1) -> str:
    if x is None or not np.isfinite(x):
        return "–"
    return f"{x:.{digits}f}"


def reading_guide() -> list[str]:
    """The "How to read this report" section: the paper's names spelt out, each metric with
    what it measures and which way is better, and the symbols the tables use."""
    return [
        "## How to read this report",
        "",
        "The paper's swarm flies a V formation along a preset route past two obstacles "
        "(O1, O2) under wind-like disturbances. Each UAV plans its next 1 s of inputs by "
        "playing a game with its neighbours (distributed model-predictive control, DMPC: "
        "each UAV minimises its own cost J_i given its neighbours' broadcast plans).",
        "",
        "- **PIO**: pigeon-inspired optimisation, the population-based search that solves "
        "each UAV's planning problem.",
        "- **LFPIO**: Lévy-flight PIO, the paper's contribution: PIO whose pigeons also make "
        "occasional long (Lévy-distributed) jumps, to find better plans.",
        "- **NFTSMO**: non-singular fast terminal sliding-mode observer, which estimates the "
        'disturbance acting on each UAV so that the controller can cancel it. "+NFTSMO" in '
        "a variant's name means the observer is on; without it the disturbance is not "
        "compensated.",
        "- **PSO** (particle swarm optimisation), **exact** (each UAV's best plan computed "
        "exactly) and **nash** (the UAVs' best plans iterated until none can improve: a Nash "
        "equilibrium) are further solvers of the same game, for comparison.",
        "",
        "Metrics, what they measure and which way is better:",
        "",
        "- **triggered steps** (Table 2): the control steps at which a UAV re-ran its "
        "optimiser. A UAV re-plans only when the cost of keeping its previous plan (J_pre, "
        "below) exceeds a threshold (10), so **fewer is better**: less computation and "
        "communication for the same flight. The paper's headline result is that LFPIO with "
        "the observer needs the fewest.",
        "- **realised cost / UAV**: the sum over the episode of each UAV's stage cost J_i "
        "(formation-keeping error, velocity-tracking error, control effort, obstacle terms); "
        "**lower is better**.",
        "- **min dist. to obstacle centre**: the closest any UAV came to an obstacle's "
        "centre; **higher is safer** (the obstacle's radius is 30 m, its safety circle 40 m).",
        "- **min separation**, **collisions**: the closest two UAVs came (higher is safer) "
        "and the UAV-steps closer than the collision distance (**0 is the goal**).",
        "- **observer rms**: the observer's error in estimating the disturbance; **lower is "
        "better**.",
        "- **formation RMSE**: how far UAVs are from their slots in the V; **lower is "
        "better** (it includes the deliberate splits at obstacles).",
        "- **mission completed**, **route error**: whether the swarm flew the route (every "
        "obstacle on it met, no collision, route error within the limit); **more missions "
        "and a smaller route error are better**.",
        "- **Nash gap**: how much a UAV could still lower its own cost by changing its plan "
        "alone; **lower is better** (0 = an equilibrium of the game).",
        "- **s per episode**: the wall time of one episode on this machine; lower is faster.",
        "",
        "Symbols and paper references:",
        "",
        "- **J_i**: UAV i's cost in the game; **W**: the warm start, the UAV's previous plan "
        "shifted by one step; **J_pre = J_i(W)**: the cost of keeping that plan, which the "
        "trigger compares with the threshold.",
        "- **H0**: the nominal formation (the V and its communication links) before and "
        "after an obstacle.",
        "- **case 1 / case 2**: how the swarm passes an obstacle: case 1, as one group "
        "that keeps the V; case 2, split into two groups, one on each side.",
        "- **d^o**: the detection distance: an obstacle affects the swarm once a UAV comes "
        "within d^o (70 m) of its centre.",
        "- **eq. 21**: the paper's disturbance model (sinusoids plus random noise of "
        "amplitude 0.1); **eq. 23**: its preset velocity schedule, which defines the route.",
        "- docs/model.md and docs/deviations.md (in the repository) explain every choice "
        "the paper leaves open.",
        "",
    ]


def difference_paragraphs(
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
        "y ∈ [−40, 40] m, docs/model.md §8: the paper does not give them) and the disturbance's "
        "random noise (eq. 21) "
        "redrawn per seed. The spread between seeds (± above) is the scale on which a single "
        "run can differ from our mean. A seed's episode does not depend on the other seeds of "
        "its batch: every copy draws from its own generator, seeded by its episode's seed, so "
        "seed 0 of a 5-seed run is seed 0 of a 10-seed run (tests/test_seeding.py)."
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
                "disturbance keeps the cost of the previous plan, J_i(W), above the threshold 10."
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
        "(q, r, m, n) (docs/model.md §4.4 chose them by calibration), the population size N_p = 30 "
        "(docs/model.md §6: N_p = 20/30/50 gave 527/505/486 triggers in one calibration run), "
        "u_max = 5 m/s², the NFTSMO gains and the reading of '0.1 rand' (per axis, redrawn "
        "every step). docs/model.md §8's calibration with these defaults found about 469 (PIO) "
        "and 458 "
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
            f"{100 * PAPER_LFPIO_REDUCTION:.1f}%.** docs/model.md §8's calibration also found "
            "LFPIO only "
            "about 2% better. Both optimisers start from the warm start W as global best and "
            "never return anything worse"
            + (
                ""
                if has_separation
                else ", and J_i is an exactly quadratic function of the 15 inputs"
            )
            + " (budgets: LFPIO 1830 evaluations, PIO 810). With one scalar `rand` per "
            "pigeon and iteration (docs/model.md §6; a per-dimension rand raised LFPIO's lead to "
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
            f"- **O1 split at {fmt_number(act)} s (paper 10 s).** Detection when a UAV in the "
            "obstacle strip comes within the detection distance d^o = 70 m of the centre "
            "(docs/model.md §7, a proposed value); "
            "the time depends on the random start box (the leading UAV starts at x ≤ 40 m)."
        )
        later = "" if res is None else f"; ours {res - 13.6:+.1f} s"
        out.append(
            f"- **O1 restore at {fmt_number(res)} s (paper 13.6 s{later}).** The paper does not "
            "say "
            "when a UAV has passed the obstacle. Our rule (docs/deviations.md §1): a group ends "
            "when none of its members is left in the obstacle strip (all abreast of the centre "
            "or laterally clear), and the nominal formation H0 returns when every group has "
            "ended, so the restore waits for the last member of the V (the V is 20 m deep). "
            "The calibration of docs/model.md, with the guide-abreast rule, found 15.2–15.6 s."
        )
    if "O2" in events and events["O2"]["activate_s"] is not None:
        act = events["O2"]["activate_s"]
        out.append(
            f"- **O2 encounter at {fmt_number(act)} s (paper 66.2 s).** After the turn at 50 s "
            "the V "
            "heads +y stretched along the track; when it meets O2 depends on where the formation "
            "sits laterally after the turn and on the detection distance d^o (docs/model.md §7: "
            "63.6–69.8 s in calibration, "
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
            "- **O2 split in some seeds** (paper: passed as one group keeping the V, case 1): "
            + ", ".join(f"{k} {c}/{n_seeds}" for k, c in cases.items())
            + ". When the V reaches O2 straddling the obstacle's centre line it splits into two "
            "groups (case 2) as at O1; which case occurs depends on the swarm's lateral "
            "position relative to O2 when it is detected."
        )
    rms = [s["observer_rms_error"] for s in v.values() if s["observer_rms_error"] is not None]
    if rms:
        spread = (
            f"{min(rms):.4f}" if max(rms) - min(rms) < 5e-5 else (f"{min(rms):.4f}–{max(rms):.4f}")
        )
        out.append(
            f"- **Observer**: rms(estimate − d) = {spread} m/s² after "
            f"{OBSERVER_WARMUP_S:g} s (docs/model.md §8 calibration: about 0.010). The paper "
            "shows Fig. 6 "
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
            f"variants and seeds ({where}; docs/model.md §7 calibration: 37.7 m at O1, 39.5 m at "
            "O2). The "
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
