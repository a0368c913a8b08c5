"""What the ecosystem expects of an env beyond its API checkers: copies, pickles, the MPE2-style
module ``uav_formation_v0``, ``max_cycles``, a fixed agent set for TorchRL, subprocess workers."""

from __future__ import annotations

import copy
import pickle
from pathlib import Path

import numpy as np
import pytest

from uav_formation_env import env, parallel_env


def _rollout(e, seed: int, steps: int = 15) -> list:
    """Observations and rewards of ``steps`` steps of fixed pseudo-random actions."""
    e.reset(seed=seed)
    rng = np.random.default_rng(7)
    out = []
    for _ in range(steps):
        if not e.agents:
            break
        actions = {a: rng.uniform(-1, 1, 3).astype(np.float32) for a in e.agents}
        obs, rew, *_ = e.step(actions)
        out.append((obs, rew))
    return out


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(
        oa.keys() == ob.keys() and all(np.array_equal(oa[k], ob[k]) for k in oa) and ra == rb
        for (oa, ra), (ob, rb) in zip(a, b, strict=True)
    )


@pytest.mark.parametrize(
    "make",
    [
        pytest.param(lambda e: copy.deepcopy(e), id="deepcopy"),
        pytest.param(lambda e: pickle.loads(pickle.dumps(e)), id="pickle"),
    ],
)
@pytest.mark.parametrize("scenario", ["paper", "random_fields"])
def test_copies_step_as_the_original(make, scenario):
    original = parallel_env(scenario)
    twin = make(original)
    assert _same(_rollout(original, seed=3), _rollout(twin, seed=3))


def test_a_copy_taken_mid_episode_goes_on_alike():
    original = parallel_env("random_fields")
    _rollout(original, seed=2, steps=5)
    twin = pickle.loads(pickle.dumps(original))
    action = {a: np.full(3, 0.3, np.float32) for a in original.agents}
    o1, r1, *_ = original.step(action)
    o2, r2, *_ = twin.step(action)
    assert r1 == r2 and all(np.array_equal(o1[k], o2[k]) for k in o1)


def test_the_aec_view_pickles():
    aec = env()
    aec.reset(seed=1)
    twin = pickle.loads(pickle.dumps(aec))
    assert twin.agent_selection == aec.agent_selection


def test_pettingzoo_max_cycles_test_passes():
    from pettingzoo.test import max_cycles_test

    from uav_formation_env import uav_formation_v0

    max_cycles_test(uav_formation_v0)


def test_the_module_has_mpe2s_three_constructors():
    from uav_formation_env import uav_formation_v0

    aec = uav_formation_v0.raw_env(max_cycles=3)
    aec.reset(seed=0)
    assert aec.metadata["name"] == "uav_formation_v0"
    assert uav_formation_v0.parallel_env().metadata["name"] == "uav_formation_v0"


@pytest.mark.parametrize("start", ["zero", "random"])
def test_max_cycles_counts_from_the_episodes_start(start):
    """Truncation after exactly K steps wherever along the mission the episode starts, and again
    after each reset."""
    e = parallel_env("random_fields", max_cycles=6, episode__start=start)
    for seed in (1, 2):
        e.reset(seed=seed)
        for k in range(1, 7):
            _, _, term, trunc, _ = e.step({a: np.zeros(3, np.float32) for a in e.agents})
            assert not any(term.values())
            assert all(trunc.values()) == (k == 6), k
        assert e.agents == []


def test_max_cycles_is_the_scenario_option_episode_max_cycles():
    from uav_formation_env.config_io import scenario_from_dict, to_dict

    e = parallel_env(max_cycles=4)
    assert e.scenario.episode.max_cycles == 4
    assert scenario_from_dict(to_dict(e.scenario)).episode.max_cycles == 4


def test_torchrl_wraps_a_distribution_over_n_with_a_mask():
    """``random_swarm`` draws N in 3..10 per reset; TorchRL's wrapper sees one group of the
    possible agents, the mask marking this episode's, over rollouts of 50 steps from 3 resets."""
    pytest.importorskip("torchrl")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper

    swarm = parallel_env("random_swarm")
    wrapped = PettingZooWrapper(swarm, use_mask=True, done_on_any=False, seed=0)
    seen = set()
    for _ in range(3):
        td = wrapped.rollout(50, break_when_any_done=False)
        n = len(swarm.agents)  # this episode's N (first N of possible_agents)
        assert td.batch_size == (50,)
        mask = td["uav", "mask"]
        assert (mask.sum(-1) == n).all() and mask[:, :n].all()
        assert not td["next", "done"].any()  # one episode, not a reset per step
        assert td["next", "uav", "info", "neighbours"].shape == (50, 10, 10)
        assert not td["next", "uav", "info", "neighbours"][:, :, n:].any()
        seen.add(n)
    assert len(seen) > 1


def test_a_distribution_over_n_pads_the_neighbour_mask_and_ignores_absent_actions():
    swarm = parallel_env("random_swarm")
    obs, infos = swarm.reset(seed=1)
    n = len(swarm.agents)
    assert n < len(swarm.possible_agents)
    assert all(infos[a]["neighbours"].shape == (10,) for a in swarm.possible_agents)
    actions = {a: np.full(3, 0.5, np.float32) for a in swarm.possible_agents}
    _, rewards, *_, infos = swarm.step(actions)
    assert set(rewards) == set(swarm.agents)
    assert all(infos[a]["neighbours"].shape == (10,) for a in swarm.agents)
    with pytest.raises(ValueError, match="unknown agent"):
        swarm.step({**actions, "uav_10": np.zeros(3)})


NO_NUMBA_CACHE = """
import numba.core.caching as caching
caching.CacheImpl._locator_classes = []  # as with a read-only install and $HOME
import numpy as np
from uav_formation_env.cli import main
from uav_formation_env import parallel_env
env = parallel_env()
env.reset(seed=0)
env.step({a: np.zeros(3, np.float32) for a in env.agents})  # the compiled observer runs
try:
    main(["--help"])
except SystemExit as exit_:
    assert exit_.code == 0
print("ok")
"""


def test_import_and_help_without_a_writable_numba_cache():
    pytest.importorskip("numba")
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, "-c", NO_NUMBA_CACHE], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.rstrip().endswith("ok") and "usage: uav-formation" in done.stdout


SUBPROC_VEC_ENV = """
import uav_formation_env
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import SubprocVecEnv
venv = make_vec_env(
    "uav_formation_env/Formation-v0",
    n_envs=2,
    vec_env_cls=SubprocVecEnv,
    vec_env_kwargs={"start_method": "forkserver"},
)
assert venv.reset().shape == (2, 235)
venv.close()
print("ok")
"""


def test_make_vec_env_with_subprocess_workers():
    """``python -c`` (no ``__main__`` that imports the package): the plain Gymnasium id works in
    SB3's forkserver workers."""
    pytest.importorskip("stable_baselines3")
    import multiprocessing
    import subprocess
    import sys

    if "forkserver" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork server on this platform")
    done = subprocess.run(
        [sys.executable, "-c", SUBPROC_VEC_ENV], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.rstrip().endswith("ok")


def test_extras_give_ranges_and_ci_pins_exact_versions_within_them():
    from pathlib import Path

    import tomllib
    from packaging.requirements import Requirement

    root = Path(__file__).resolve().parents[1]
    project = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    extras = [Requirement(r) for reqs in project["optional-dependencies"].values() for r in reqs]
    pinned = [str(r) for r in extras if any(s.operator in ("==", "===") for s in r.specifier)]
    assert pinned == [], f"exact pins in the published extras: {pinned}"
    lines = (root / ".ci" / "constraints.txt").read_text(encoding="utf-8").splitlines()
    pins = {
        Requirement(line).name: Requirement(line)
        for line in lines
        if line.strip() and not line.startswith("#")
    }
    assert all(
        len(r.specifier) == 1 and next(iter(r.specifier)).operator == "==" for r in pins.values()
    )
    for requirement in extras:
        if requirement.name in pins:
            version = next(iter(pins[requirement.name].specifier)).version
            assert requirement.specifier.contains(version), (requirement, version)
    run = (root / ".ci" / "run").read_text(encoding="utf-8")
    assert 'PIP_CONSTRAINT="$PWD/.ci/constraints.txt"' in run


SDIST_INPUTS = (
    "pyproject.toml", "MANIFEST.in", "README.md", "LICENSE", "CHANGELOG.md", "CITATION.cff",
    "uav_formation_env", "baselines", "docs", "examples", "notebooks", "benchmarks", "tests",
)  # fmt: skip


def test_sdist_carries_what_the_tests_read_and_the_version_is_in_one_place(tmp_path):
    """The sdist (built offline) holds docs/, examples/ and tests/; its version is
    ``uav_formation_env.__version__``, which ``uav-formation --version`` prints."""
    import importlib.metadata
    import shutil
    import subprocess
    import sys
    import tarfile

    import uav_formation_env
    from uav_formation_env.cli import main

    try:
        setuptools_version = importlib.metadata.version("setuptools")
    except importlib.metadata.PackageNotFoundError:
        setuptools_version = "0"
    if int(setuptools_version.split(".")[0]) < 77:  # as tests/test_packaging.py
        pytest.skip(f"building offline needs setuptools >= 77, found {setuptools_version}")
    root = Path(__file__).resolve().parents[1]
    source = tmp_path / "source"
    source.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "models")
    for name in SDIST_INPUTS:
        path = root / name
        if path.is_dir():
            shutil.copytree(path, source / name, ignore=ignore)
        else:
            shutil.copy2(path, source / name)
    code = (
        "import sys; from setuptools import build_meta; print(build_meta.build_sdist(sys.argv[1]))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "dist")],
        cwd=source,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    name = done.stdout.strip().splitlines()[-1]
    version = uav_formation_env.__version__
    assert name == f"uav_formation_env-{version}.tar.gz"
    with tarfile.open(tmp_path / "dist" / name) as sdist:
        members = {m.split("/", 1)[1] for m in sdist.getnames() if "/" in m}
    for expected in (
        "docs/architecture.md",
        "examples",
        "tests/test_conventions.py",
        "MANIFEST.in",
    ):
        assert any(m.startswith(expected) for m in members), expected
    assert not any("__pycache__" in m for m in members)
    assert "\nversion:" not in (root / "CITATION.cff").read_text(encoding="utf-8")
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0


def test_no_progress_bars_in_logs(tmp_path):
    """Output to files or pipes (a log) gets no tqdm bars, without --quiet."""
    import subprocess
    import sys

    argv = ["evaluate", "--policy", "heuristic", "--seeds", "1", "--duration", "2"]
    done = subprocess.run(
        [sys.executable, "-m", "uav_formation_env.cli", *argv, "--out", str(tmp_path / "e")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert "%|" not in done.stderr and "step/s" not in done.stderr, done.stderr[-500:]
    assert "mission completed" in done.stdout


def test_module_docstrings_say_what_a_module_is_for_in_at_most_30_lines():
    """The package is not a lab notebook: a module docstring is a short statement of purpose;
    reference tables live in docs/."""
    import ast

    package = Path(__file__).resolve().parents[1] / "uav_formation_env"
    long = {}
    for path in sorted(package.rglob("*.py")):
        doc = ast.get_docstring(ast.parse(path.read_text(encoding="utf-8")), clean=False)
        if doc is not None and doc.count("\n") + 1 > 30:
            long[str(path.relative_to(package))] = doc.count("\n") + 1
    assert not long, f"module docstrings over 30 lines: {long}"
