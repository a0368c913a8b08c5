"""The DAgger ensemble recipe in one command: students trained side by side, the best few averaged.

    python -m uav_formation_baselines.train_ensemble --scenario paper --out runs/paper_ensemble \
        [--runs 8] [--seed-start 0] [--top K] [--workers 2] [--parallel 8] [--device auto] \
        [--config hyperparams/bc_ensemble.yml] [--set rounds=4 ...]

Each of the ``--runs`` students is one DAgger run (:mod:`~uav_formation_baselines.imitation`,
seeds ``--seed-start`` on) in its own process, ``--parallel`` at a time, each flying its episodes
in ``--workers`` processes and fitting on ``--device``; the settings come from
``hyperparams/bc_ensemble.yml`` (4 rounds of 512 x 512 students, each round scored on 40
validation seeds). When all have finished, their mean becomes one policy
(:func:`~uav_formation_baselines.ensemble.build_ensemble`), or that of the ``--top K`` students
whose kept rounds scored best on their validation seeds. Evaluation seeds choose nothing.

The output directory holds the ensemble (``policy.json``, ``policy.npz``, ``scenario.yaml``;
load with
``uav-formation evaluate --policy DIR``), ``config.yaml`` (the ensemble's record with the recipe:
seeds, settings, and ``recipe_wall_time_s``, the time from the first launch to the written
ensemble) and ``members/seed_<k>/`` (every student's run and ``.log``). On one GPU machine
(16 cores) 8 students with 2 workers each run at once: 209-234 s for the paper's recipe; on 2
cores, ``--runs 3 --workers 1 --set 'hidden=[256, 256]'`` took 1368-1503 s
(baselines/RESULTS.md, "Five minutes on one GPU, or 23 on two cores").
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import yaml
from tqdm import tqdm

from uav_formation_baselines import HYPERPARAMS_DIR
from uav_formation_baselines.config import parse_set
from uav_formation_baselines.ensemble import build_ensemble
from uav_formation_baselines.imitation import config_section, load_config, resolve_device
from uav_formation_env.cli import OneLineParser
from uav_formation_env.evaluation.heldout import report_run

__all__ = ["RECIPE", "train_ensemble"]

RECIPE = HYPERPARAMS_DIR / "bc_ensemble.yml"


def _positive(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
    return value


def _student_command(
    scenario: str, out: Path, seed: int, workers: int, device: str, config: Path, sets: list[str]
) -> list[str]:
    return [
        sys.executable, "-m", "uav_formation_baselines.imitation", "--scenario", scenario,
        "--out", str(out), "--seed", str(seed), "--threads", "1", "--workers", str(workers),
        "--device", device, "--config", str(config), "--quiet", *(["--set", *sets] if sets else []),
    ]  # fmt: skip


def _stop(process: subprocess.Popen) -> None:
    """Kill a student and the worker processes it spawned (its process group on POSIX)."""
    if hasattr(os, "killpg"):
        with contextlib.suppress(ProcessLookupError):  # the group is already gone
            os.killpg(process.pid, signal.SIGKILL)
    process.kill()  # the student itself, whatever its group
    process.wait()


def _rounds_done(run: Path) -> int:
    """Rounds a running student has finished (the rows of its ``rounds.csv``)."""
    table = run / "rounds.csv"
    if not table.is_file():
        return 0
    return max(len(table.read_text(encoding="utf-8").splitlines()) - 1, 0)


def train_ensemble(
    scenario: str,
    out: str | Path,
    runs: int = 8,
    top: int | None = None,
    seed_start: int = 0,
    workers: int = 2,
    parallel: int | None = None,
    device: str = "auto",
    config: str | Path | None = None,
    sets: list[str] | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Train ``runs`` DAgger students (seeds ``seed_start`` ..), ``parallel`` at a time (None: all),
    and write the mean of all of them (or of the ``top`` best-validated) to ``out``; returns its
    ``config.yaml`` record.

    The settings (``config``, default ``hyperparams/bc_ensemble.yml``, with ``sets`` such as
    ``["rounds=2"]`` over them) and the arguments are checked before any process starts; a student
    that fails stops the others and raises a ``RuntimeError`` naming its seed and log.
    """
    runs = _positive("runs", runs)
    top = runs if top is None else _positive("top", top)
    workers = _positive("workers", workers)
    parallel = runs if parallel is None else _positive("parallel", parallel)
    if top > runs:
        raise ValueError(f"top must be at most runs ({runs}), got {top}")
    config_path = Path(config) if config is not None else RECIPE
    sets = list(sets or [])
    # bad settings fail here, once, not in every student
    settings = load_config(config_section(scenario), config_path, **parse_set(sets))
    device = resolve_device(device)
    out = Path(out)
    members = out / "members"
    members.mkdir(parents=True, exist_ok=True)
    seeds = list(range(seed_start, seed_start + runs))
    run_dirs = {seed: members / f"seed_{seed}" for seed in seeds}
    waiting, running = list(seeds), {}
    started = time.perf_counter()
    # each student sets its own torch threads; BLAS in its processes must not take every core
    one_thread = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
    env = {**os.environ, **dict.fromkeys(one_thread, "1")}
    bar = tqdm(total=runs * settings.rounds, desc="students' rounds", disable=not progress)
    try:
        while waiting or running:
            while waiting and len(running) < parallel:
                seed = waiting.pop(0)
                log = open(members / f"seed_{seed}.log", "w", encoding="utf-8")  # noqa: SIM115
                command = _student_command(
                    scenario, run_dirs[seed], seed, workers, device, config_path, sets
                )
                # a session of its own: stopping a student stops its episode workers too
                process = subprocess.Popen(
                    command, stdout=log, stderr=log, env=env, start_new_session=True
                )
                running[seed] = (process, log)
            time.sleep(0.5)
            for seed, (process, log) in list(running.items()):
                if process.poll() is None:
                    continue
                log.close()
                del running[seed]
                if process.returncode != 0:
                    lines = (members / f"seed_{seed}.log").read_text(encoding="utf-8").splitlines()
                    last = lines[-1] if lines else "(empty log)"
                    raise RuntimeError(
                        f"student seed {seed} failed (exit {process.returncode}): {last} "
                        f"[{members / f'seed_{seed}.log'}]"
                    )
            done = sum(_rounds_done(run_dirs[s]) for s in seeds)
            if done > bar.n:
                bar.update(done - bar.n)
    finally:
        for process, log in running.values():
            _stop(process)
            log.close()
        bar.close()
    record = build_ensemble([run_dirs[s] for s in seeds], out, top)
    record["recipe"] = {
        "config": str(config_path),
        "set": sets,
        "seeds": seeds,
        "workers": workers,
        "parallel": parallel,
        "device": device,
        "settings": json.loads(json.dumps(asdict(settings), default=dict)),  # tuples as lists
    }
    # every student's training, also of those left out: what the ensemble cost to make
    record["recipe_agent_steps"] = 0
    for seed in seeds:
        with open(run_dirs[seed] / "config.yaml", encoding="utf-8") as stream:
            record["recipe_agent_steps"] += int(yaml.safe_load(stream)["agent_steps"])
    record["recipe_wall_time_s"] = time.perf_counter() - started
    with open(out / "config.yaml", "w", encoding="utf-8") as stream:
        yaml.safe_dump(record, stream, sort_keys=False)
    return record


def main(argv: list[str] | None = None) -> int:
    parser = OneLineParser(description=__doc__.split("\n")[0])
    parser.add_argument("--scenario", default="paper", help="registered name or YAML path")
    parser.add_argument("--out", required=True, help="output directory")
    parser.add_argument("--runs", type=int, default=8, help="students trained")
    parser.add_argument("--top", type=int, default=None, help="students averaged (all)")
    parser.add_argument("--seed-start", type=int, default=0, help="first student's seed")
    parser.add_argument("--workers", type=int, default=2, help="episode processes per student")
    parser.add_argument("--parallel", type=int, default=None, help="students at once (all)")
    parser.add_argument("--device", default="auto", help="where students fit: auto, cpu, cuda")
    parser.add_argument("--config", default=None, help="YAML (default: bc_ensemble.yml)")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="overrides")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.add_argument(
        "--heldout-seeds",
        type=int,
        default=3,
        help="held-out seeds (0, 1, ...) flown at the end by the policy and LFPIO (0: none)",
    )
    args = parser.parse_args(argv)
    try:
        record = train_ensemble(
            args.scenario, args.out, args.runs, args.top, args.seed_start, args.workers,
            args.parallel, args.device, args.config, args.set, progress=not args.quiet,
        )  # fmt: skip
    except (ValueError, FileNotFoundError, KeyError, RuntimeError) as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    names = ", ".join(Path(m["run"]).name for m in record["members"])
    print(
        f"wrote the policy {args.out}: the mean of {len(record['members'])} of {args.runs} "
        "students "
        f"({names}) in {record['recipe_wall_time_s']:.0f} s"
    )
    report_run(args.out, args.heldout_seeds, progress=not args.quiet)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
