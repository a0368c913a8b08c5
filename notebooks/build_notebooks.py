"""Write the notebooks of this folder from the cell sources below (run after editing them).

    python notebooks/build_notebooks.py

The notebooks hold no logic beyond calls into the package and plotting. Sizes are chosen by the
environment variable ``UAV_NOTEBOOK_SIZE``: ``full`` (default: the paper's sizes) or ``small``
(what ``tests/test_notebooks.py`` uses in CI).
"""

from __future__ import annotations

from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).resolve().parent

SIZE_CELL = """%matplotlib inline
import os

SMALL = os.environ.get("UAV_NOTEBOOK_SIZE", "full") == "small"
print("size:", "small (CI)" if SMALL else "full")"""

REPRODUCE = [
    new_markdown_cell(
        "# 01 · Reproducing the paper\n\n"
        "Yuan, Deng, Luo, Duan, *Distributed game strategy for UAV formation with external "
        "disturbances and obstacles*: five UAVs fly a V formation past two cylindrical obstacles "
        "under the disturbance of eq. 21, controlled by a distributed-MPC Nash game solved by PIO "
        "or LFPIO, with or without the NFTSMO disturbance observer.\n\n"
        "This notebook runs `uav_formation_env.reproduce.reproduce` (the same code as "
        "`uav-formation reproduce`) and shows Table 2 and Figs. 5-9 beside the paper's numbers. "
        "With `UAV_NOTEBOOK_SIZE=small` it flies 2 seeds for 40 s (CI); the default is 5 seeds "
        "over the full 200 s (about half a minute on two cores)."
    ),
    new_code_cell(SIZE_CELL),
    new_code_cell(
        """import tempfile
from pathlib import Path

from IPython.display import Image, Markdown, display

from uav_formation_env.reproduce import (
    LABELS,
    PAPER_EVENTS_S,
    PAPER_TRIGGER_MEAN,
    PAPER_TRIGGERS,
    VARIANTS,
    reproduce,
)

out = Path(tempfile.mkdtemp(prefix="reproduce_"))
seeds = range(2) if SMALL else range(5)
duration = 40.0 if SMALL else None  # None: the paper's 200 s
result = reproduce(out, seeds=seeds, duration=duration, progress=False)
print("wrote", sorted(p.name for p in out.iterdir()))"""
    ),
    new_markdown_cell(
        "## Table 2: triggered steps per UAV\n\n"
        "Mean over seeds (the paper reports one run). Without the observer every UAV re-solves at "
        "nearly every step; with NFTSMO the compensated disturbance keeps J_i under the "
        "threshold on about half of the steps."
    ),
    new_code_cell(
        """variants = result.summary["variants"]
rows = ["| variant | UAV1..UAV5 (ours) | mean (ours) | UAV1..UAV5 (paper) | mean (paper) |",
        "|---|---|---|---|---|"]
for name in VARIANTS:
    ours = variants[name]["triggers_per_uav"]
    rows.append(
        f"| {LABELS[name]} | {' / '.join(f'{x:.0f}' for x in ours)} "
        f"| {variants[name]['triggers_mean']:.1f} "
        f"| {' / '.join(str(x) for x in PAPER_TRIGGERS[name])} | {PAPER_TRIGGER_MEAN[name]} |"
    )
if SMALL:
    rows.append("")
    rows.append("(small run: counts are over the first 40 s only, not comparable to the paper's)")
display(Markdown("\\n".join(rows)))"""
    ),
    new_markdown_cell("## Safety, observer and events"),
    new_code_cell(
        """rows = ["| variant | collisions | min distance to obstacle centres [m] | observer rms "
        "[m/s^2] | O1 activation [s] | s / episode |", "|---|---|---|---|---|---|"]
for name in VARIANTS:
    v = variants[name]
    rms = v["observer_rms_error"]
    o1 = v["events"].get("O1", {}).get("activate_s")
    rows.append(
        f"| {LABELS[name]} | {v['collisions']} | {v['min_obstacle_center_distance_m']:.1f} "
        f"| {'–' if rms is None else f'{rms:.4f}'} | {o1} | {v['seconds_per_episode']:.2f} |"
    )
display(Markdown("\\n".join(rows)))
print("paper's events [s]:", PAPER_EVENTS_S)"""
    ),
    new_markdown_cell("## Figures 5-9"),
    new_code_cell(
        """for png in sorted(out.glob("fig*.png")):
    display(Markdown(f"**{png.name}**"))
    display(Image(filename=str(png), width=720))"""
    ),
    new_markdown_cell(
        "`REPORT.md` in the output folder explains every difference from the paper's numbers."
    ),
    new_code_cell("""print((out / "REPORT.md").read_text()[:3000])"""),
]

RL_VS_REFERENCE = [
    new_markdown_cell(
        "# 02 · Learned baselines against the reference policy: cost *and* mission\n\n"
        "The shipped model of the paper task (`paper_ppo`, installed with the package; one "
        "policy shared by every UAV): PPO trained from the bounded training reward alone, no "
        "teacher (`python -m uav_formation_baselines.onpolicy --algo ppo --task hold,track,paper` "
        "with the recipe of docs/training.md: the local observation layout, route weight 0.5, "
        "separation weight 0.3, termination penalty 30, entropy coefficient 0.01, a 2 m obstacle "
        "margin in training). It flies "
        "the same seeds through the "
        "same code as the LFPIO distributed-MPC reference, PIO, the consensus heuristic and "
        "random actions: `uav_formation_env.evaluation.make_policy`, `run_episodes` and "
        "`summarise`, which is what `uav-formation evaluate` and "
        "`python -m uav_formation_baselines.evaluate` run. Each model flies the scenario of its "
        "run directory (`scenario.yaml`: the PPO model reads the route offset of its slot and "
        "commands velocity set-points, flown through its set-point loop under the evaluation's "
        "rules, `tasks.evaluation_scenario`); the physics, the seeds and so the episodes' "
        "scenes are the paper's.\n\n"
        "The paper's game cost J_i tracks the preset **velocity**, not a position, so a low "
        "cost does not mean the mission was flown. The table puts the realised cost beside the "
        'mission metrics of `summarise(batch)["mission"]`: missions completed, route error of '
        "the formation centroid against the preset route, obstacles met and collisions after "
        "t = 0 (see `baselines/RESULTS.md` for every algorithm over three training seeds).\n\n"
        "Full size: 20 seeds of the full 200 s, the held-out seeds of `baselines/RESULTS.md` "
        "(a few minutes on two cores). With `UAV_NOTEBOOK_SIZE=small` the episodes last 30 s "
        "and 2 seeds (CI only: the obstacles come later, so those numbers say nothing about the "
        "mission)."
    ),
    new_code_cell(SIZE_CELL),
    new_code_cell(
        """import matplotlib.pyplot as plt
import numpy as np
from IPython.display import Markdown, display

from uav_formation_baselines.evaluate import format_failures, format_markdown
from uav_formation_env.config_io import resolve_scenario, with_overrides
from uav_formation_env.evaluation import make_policy, preset_route, run_episodes, summarise
from uav_formation_env.plotting import draw_obstacles
from uav_formation_env.policies.registry import model_scenario  # a shipped model's scenario
from uav_formation_env.tasks import evaluation_scenario

seeds = list(range(2)) if SMALL else list(range(20))


def short(scenario):
    return with_overrides(scenario, {"duration": 30.0}) if SMALL else scenario


scenario = short(resolve_scenario("paper"))
policies = {}  # label -> (policy name or model path, the scenario it flies)
# a model flies the scenario (observation layout) it was trained on
trained = evaluation_scenario(resolve_scenario(model_scenario("paper_ppo")))
policies["PPO"] = ("paper_ppo", short(trained))
for name in ("lfpio", "pio", "heuristic", "random"):
    policies[name] = (name, scenario)
print({label: name for label, (name, _) in policies.items()})"""
    ),
    new_code_cell(
        """batches, summaries = {}, {}
for label, (name, flown) in policies.items():
    batch = run_episodes(flown, make_policy(name, flown), seeds, policy_name=label)
    batches[label], summaries[label] = batch, summarise(batch)"""
    ),
    new_markdown_cell(
        "## Cost beside the mission\n\n"
        "Realised J per UAV (Σ of the stage cost over the episode) and its ratio to LFPIO's; "
        "mission completed = every obstacle on the preset route met, no collision after t = 0 and "
        "route error max <= 100 m. Means over seeds ± the half-width of their 95 % confidence "
        "interval. The same table as `python -m uav_formation_baselines.evaluate` writes."
    ),
    new_code_cell("""display(Markdown(format_markdown(summaries, reference="lfpio")))"""),
    new_markdown_cell('Why each failed seed failed (`summarise(batch)["mission"]["failures"]`):'),
    new_code_cell("""display(Markdown(format_failures(summaries, markdown=True)))"""),
    new_markdown_cell(
        "## Formation centroid against the preset route\n\n"
        "One panel per policy, every seed: the formation centroid (solid) and the preset route "
        "from the same start (`uav_formation_env.evaluation.preset_route`, dashed), with the "
        "obstacles. Each panel has its own scale: a policy that leaves the route shows it."
    ),
    new_code_cell(
        """cols = 3
rows = -(-len(batches) // cols)
fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 4.5 * rows), squeeze=False)
for ax, (label, batch) in zip(axes.flat, batches.items()):
    centroid = batch.z[..., :3].mean(axis=2)  # (T+1, seeds, 3): the formation centroid
    route = preset_route(scenario, batch.t, centroid[0])
    draw_obstacles(ax, scenario)
    for b in range(batch.batch_size):
        ax.plot(route[:, b, 0], route[:, b, 1], "k--", lw=0.8, alpha=0.5,
                label="preset route" if b == 0 else None)
        ax.plot(centroid[:, b, 0], centroid[:, b, 1], lw=1, color="C3",
                label="centroid" if b == 0 else None)
    mission = summaries[label]["mission"]
    ax.set_title(f"{label}: completed {mission['completed']}/{mission['episodes']}, "
                 f"route error max {mission['route_error_max_m']:.0f} m", fontsize=10)
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=8, loc="best")
for ax in list(axes.flat)[len(batches):]:
    ax.set_visible(False)
fig.tight_layout()"""
    ),
    new_markdown_cell("## Realised stage cost over time (mean over UAVs and seeds)"),
    new_code_cell(
        """fig, ax = plt.subplots(figsize=(8, 4))
for label, batch in batches.items():
    ax.plot(batch.t[1:], np.log10(batch.stage_cost.mean(axis=(1, 2)) + 1e-12), label=label)
ax.set_xlabel("t [s]")
ax.set_ylabel("log10 mean stage J")
ax.legend()
fig.tight_layout()"""
    ),
    new_markdown_cell(
        "## New scenes: the scene distributions\n\n"
        "Every seed of `random_fields` (N = 5, 1-4 obstacles on a drawn route) and "
        "`random_swarm` (N drawn in 3-10, any formation shape, fields, wind) draws its own "
        "scene. The shipped student of each distribution (the DAgger recipe on two cores, "
        "`python -m uav_formation_baselines.train_ensemble --scenario TASK`; one policy for every "
        "N, on the N-independent local observation) flies held-out seeds beside LFPIO; "
        "`run_episode_groups` flies one batch per drawn N and `summarise_groups` joins them. "
        "Full size: seeds 0-19 of each (`baselines/RESULTS.md` has 100); small: one scene of "
        "each, for the full 200 s (a drawn scene fills its episode's duration)."
    ),
    new_code_cell(
        """from uav_formation_env.evaluation import run_episode_groups, summarise_groups
from uav_formation_env.scenes import seeds_by_n_uav

students = {"random_fields": "random_fields_dagger", "random_swarm": "random_swarm_dagger"}
task_summaries = {}
for task, run in students.items():
    drawn = resolve_scenario(task)
    task_seeds = list(range(20))
    if SMALL:  # the first scene of the smallest N among them: the cheapest full-length episode
        by_n = seeds_by_n_uav(drawn, task_seeds)
        task_seeds = by_n[min(by_n)][:1]
    flown = {"lfpio": ("lfpio", drawn)}
    # the student flies its own observation layout, on the same scenes
    flown[run] = (run, resolve_scenario(model_scenario(run)))
    task_summaries[task] = {
        label: summarise_groups(
            run_episode_groups(scene, make_policy(name, scene), task_seeds, policy_name=label)
        )
        for label, (name, scene) in flown.items()
    }
    display(Markdown(f"### `{task}`: seeds {task_seeds}" if SMALL else f"### `{task}`: seeds 0-19"))
    display(Markdown(format_markdown(task_summaries[task], reference="lfpio")))
    display(Markdown(format_failures(task_summaries[task], markdown=True)))"""
    ),
    new_markdown_cell(
        "Each scene's route error max against its realised cost: a policy can be cheap and far "
        "off the route; a mission fails above the dashed line (100 m) whatever its cost."
    ),
    new_code_cell(
        """fig, axes = plt.subplots(1, len(task_summaries), figsize=(6 * len(task_summaries), 4))
for ax, (task, by_policy) in zip(np.atleast_1d(axes), task_summaries.items()):
    for label, summary in by_policy.items():
        ax.scatter(summary["realised_cost_per_seed"],
                   summary["mission"]["route_error_max_m_per_seed"], label=label, s=18)
    ax.axhline(100.0, color="k", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("realised J per UAV")
    ax.set_ylabel("route error max [m]")
    ax.set_title(task)
    ax.legend(fontsize=8)
fig.tight_layout()"""
    ),
]

CUSTOM = [
    new_markdown_cell(
        "# 03 · A custom scenario\n\n"
        "Scenarios are frozen, validated dataclasses (`uav_formation_env.config`). Here: six "
        "UAVs in a line-abreast formation with a ring-shaped communication graph, three "
        "obstacles of our own, a constant cross wind and gusts, flown by the LFPIO reference "
        "policy with the observer on. With `UAV_NOTEBOOK_SIZE=small` the flight lasts 30 s."
    ),
    new_code_cell(SIZE_CELL),
    new_code_cell(
        """import dataclasses

import numpy as np
from IPython.display import Image, display

from uav_formation_env import parallel_env
from uav_formation_env.config import (
    AvoidanceConfig,
    DisturbanceConfig,
    FormationConfig,
    InitialStateConfig,
    ObstacleConfig,
    Scenario,
)

n = 6
spacing = 15.0  # lateral distance between neighbours [m]
offsets = tuple((0.0, spacing * (i - (n - 1) / 2), 0.0, 0.0, 0.0, 0.0) for i in range(n))
ring = tuple(tuple(int(j in ((i - 1) % n, (i + 1) % n)) for j in range(n)) for i in range(n))
scenario = dataclasses.replace(
    Scenario(),
    name="line_abreast_6",
    duration=30.0 if SMALL else 120.0,
    formation=FormationConfig(offsets=offsets, adjacency=ring),
    avoidance=AvoidanceConfig(
        obstacles=(
            ObstacleConfig(center=(350.0, 20.0), radius=25.0),
            ObstacleConfig(center=(1300.0, 300.0), radius=40.0),
            ObstacleConfig(center=(700.0, 900.0), radius=30.0),
        )
    ),
    disturbance=DisturbanceConfig(wind=(0.0, 0.3, 0.0), gust_std=0.2),
    initial=InitialStateConfig(position_low=(0.0, -60.0, 0.0), position_high=(30.0, 60.0, 0.0)),
)
print(scenario.n_uav, "UAVs,", len(scenario.avoidance.obstacles), "obstacles")"""
    ),
    new_markdown_cell(
        "Invalid settings fail on construction with a message naming the field, for example a "
        "graph without a spanning tree:"
    ),
    new_code_cell(
        """try:
    FormationConfig(offsets=offsets, adjacency=tuple((0,) * n for _ in range(n)))
except ValueError as error:
    print("ValueError:", error)"""
    ),
    new_markdown_cell(
        "## Fly it with the reference policy\n\n"
        "`parallel_env` accepts the scenario object; the policy acts on the agents' "
        "observations only."
    ),
    new_code_cell(
        """from uav_formation_env.evaluation import make_policy, run_episodes, summarise
from uav_formation_env.plotting import plot_trajectories

policy = make_policy("lfpio", scenario, seed=0)
batch = run_episodes(scenario, policy, seeds=[0], policy_name="lfpio")
summary = summarise(batch)
for key in ("realised_cost_mean", "formation_rmse_m", "min_obstacle_surface_distance_m",
            "min_separation_m", "collisions", "triggers_mean"):
    print(f"{key:35s} {summary[key]}")
fig = plot_trajectories(batch.z[:, 0, :, :3], scenario, title=scenario.name)"""
    ),
    new_markdown_cell("## The same scenario as a PettingZoo env, rendered"),
    new_code_cell(
        """import tempfile
from pathlib import Path

from uav_formation_env.render import write_gif

env = parallel_env(scenario, render_mode="rgb_array")
observations, infos = env.reset(seed=0)
frames = [env.render()]
policy = make_policy("heuristic", scenario)
for _ in range(40 if SMALL else 300):
    obs = np.stack([observations[a] for a in env.agents])[None]
    actions = policy.act_batch(obs)[0]
    observations, rewards, terms, truncs, infos = env.step(dict(zip(env.agents, actions)))
    frames.append(env.render())
    if not env.agents:
        break
env.close()
gif = write_gif(frames[::2], Path(tempfile.mkdtemp()) / "custom_scenario.gif", fps=10)
display(Image(filename=str(gif)))"""
    ),
]


def write(name: str, cells: list) -> None:
    notebook = new_notebook(cells=cells)
    notebook.metadata["kernelspec"] = {
        "display_name": "Python 3",
        "language": "python",
        "name": "python3",
    }
    nbformat.write(notebook, HERE / name)


if __name__ == "__main__":
    write("01_reproduce_paper.ipynb", REPRODUCE)
    write("02_rl_vs_reference.ipynb", RL_VS_REFERENCE)
    write("03_custom_scenario.ipynb", CUSTOM)
