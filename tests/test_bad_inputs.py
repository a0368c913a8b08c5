"""Bad input gets a clear error that names the problem, and loses nothing.

One table across configuration, YAML, environment, policy and command line: every row is a call
that must fail with the given exception type and a message matching the given pattern. The
command-line rows must print exactly one line, ``uav-formation: error: ...``, exit with status 2
and never show a traceback.
"""

from __future__ import annotations

import re
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from uav_formation_env import env as aec_env
from uav_formation_env import parallel_env
from uav_formation_env.cli import main
from uav_formation_env.config import DynamicsConfig, ObserverConfig, Scenario
from uav_formation_env.config_io import resolve_scenario, scenario_from_dict, with_overrides
from uav_formation_env.evaluation import make_policy, run_episodes
from uav_formation_env.extras import MissingExtraError
from uav_formation_env.policies import NashDMPCPolicy
from uav_formation_env.run_folder import MARKER
from uav_formation_env.scenarios import make_scenario

ZERO = np.zeros(3, dtype=np.float32)


def fresh_env():
    e = parallel_env("paper")
    e.reset(seed=0)
    return e


def actions(**changed):
    acts = {f"uav_{i}": ZERO for i in range(5)}
    acts.update(changed)
    return acts


def scenario(data):
    return lambda: scenario_from_dict(data)


def yaml_file(text: str) -> Callable[[], object]:
    def load(tmp: Path = Path("/tmp")) -> object:
        path = tmp / f"bad_{abs(hash(text))}.yaml"
        path.write_text(text, encoding="utf-8")
        return resolve_scenario(path)

    return load


def step(changed) -> Callable[[], object]:
    return lambda: fresh_env().step(changed)


def dmpc_act(obs) -> Callable[[], object]:
    return lambda: NashDMPCPolicy("paper", "lfpio").act_batch(obs)


def vec(**kwargs):
    from uav_formation_env import vec_env

    return vec_env("paper", **kwargs)


def stiff_observer_steps(steps: int) -> None:
    """Gains that pass the tick bound together but still diverge: the run-time check names it."""
    e = parallel_env(
        observer__rho=10.0, observer__eta=20.0, observer__pi2=10.0, observer__substeps=16
    )
    e.reset(seed=0)
    for _ in range(steps):
        e.step({a: np.ones(3, np.float32) for a in e.agents})


def done_aec():
    e = aec_env(max_cycles=1)
    e.reset(seed=0)
    for _ in range(5):
        e.step(ZERO)
    return e


def corrupt(name: str) -> Path:
    folder = Path(tempfile.mkdtemp())
    path = folder / name
    path.write_bytes(np.random.default_rng(0).bytes(3000))
    return path


GOOD_OBS = parallel_env("paper").reset(seed=0)[0]
NAN_OBS = np.stack([GOOD_OBS[f"uav_{i}"] for i in range(5)])[None].astype(float)
NAN_OBS[0, 2, 4] = np.nan

# (id, call, exception type, pattern the message must match)
TABLE: list[tuple[str, Callable[[], object], type[BaseException], str]] = [
    # ---- configuration
    ("unknown top-level key", scenario({"durration": 1.0}), ValueError, r"'durration'"),
    ("unknown nested key", scenario({"observer": {"lamda2": 1.5}}), ValueError, r"observer\.lamda2"),
    (
        "obstacle without center",
        scenario({"avoidance": {"obstacles": [{"radius": 3.0}]}}),
        ValueError,
        r"missing scenario key 'avoidance\.obstacles\[0\]\.center'",
    ),
    ("negative dt", scenario({"dynamics": {"dt": -1.0}}), ValueError, r"'dynamics\.dt'.*> 0"),
    ("duration a string", scenario({"duration": "long"}), ValueError, r"'duration'.*number"),
    (
        "negative min spacing",
        scenario({"initial": {"min_spacing": -1.0}}),
        ValueError,
        r"'initial\.min_spacing'",
    ),
    (
        "min spacing too large for the box",
        scenario({"initial": {"min_spacing": 60.0}}),
        ValueError,
        r"'initial\.min_spacing'.*5 UAVs cannot be 60\.0 m apart",
    ),
    (
        "zero route-error threshold",
        scenario({"mission": {"max_route_error": 0.0}}),
        ValueError,
        r"'mission\.max_route_error'",
    ),
    (
        "unknown collision mode",
        scenario({"collision": {"mode": "explode"}}),
        ValueError,
        r"'collision\.mode'.*'explode'",
    ),
    (
        "graph without spanning tree",
        scenario(
            {
                "formation": {
                    "offsets": [[0, 0, 0, 0, 0, 0], [10, 0, 0, 0, 0, 0]],
                    "adjacency": [[0, 0], [0, 0]],
                }
            }
        ),
        ValueError,
        r"'formation\.adjacency'.*spanning tree",
    ),
    ("fractional substeps", scenario({"observer": {"substeps": 2.5}}), ValueError, r"substeps"),
    ("zero horizon", scenario({"cost": {"horizon": 0}}), ValueError, r"'cost\.horizon'"),
    (
        "override of a boolean with a string",
        lambda: parallel_env("paper", observer__enabled="yes"),
        ValueError,
        r"'observer\.enabled'.*true/false",
    ),
    ("negative max_cycles", lambda: parallel_env(max_cycles=-1), ValueError, r"'episode\.max_cycles'.*>= 0"),
    ("fractional max_cycles", lambda: parallel_env(max_cycles=2.5), ValueError, r"'episode\.max_cycles'"),
    ("observer tick too long: dt", lambda: parallel_env(dynamics__dt=4.0, duration=200.0), ValueError, r"'observer\.substeps'.*= 0\.2 s must be <= 0\.111 s"),
    ("observer tick too long: one substep", lambda: parallel_env(observer__substeps=1), ValueError, r"'observer\.substeps'.*use observer\.substeps >= 2"),
    ("more UAVs than the start sampler places", lambda: make_scenario(n_uav=100), ValueError, r"'initial\.min_spacing'.*100 UAVs .*start sampler places at most 75"),
    ("obstacle over the start box", scenario({"avoidance": {"obstacles": [{"center": [20.0, 0.0], "radius": 10.0}]}}), ValueError, r"'avoidance\.obstacles\[0\]'.*start box"),
    ("horizon of a million steps", scenario({"cost": {"horizon": 10**6}}), ValueError, r"'cost\.horizon'.*\[1, 1000\]"),
    ("Scenario(dynamics=dict)", lambda: Scenario(dynamics={"dt": 0.1}), ValueError, r"'dynamics'.*DynamicsConfig, got dict"),
    ("Scenario(duration=str)", lambda: Scenario(duration="10"), ValueError, r"'duration'.*number, got '10'"),
    ("Scenario(name=int)", lambda: Scenario(name=3), ValueError, r"'name'.*string, got 3"),
    ("ObserverConfig(enabled=str)", lambda: Scenario(observer=ObserverConfig(enabled="yes")), ValueError, r"'observer\.enabled'.*true/false"),
    ("DynamicsConfig(dt=str)", lambda: DynamicsConfig(dt="0.1"), ValueError, r"'dynamics\.dt'.*number"),
    # ---- YAML
    ("YAML duplicate key", yaml_file("observer:\n  rho: 2.0\n  rho: 3.0\n"), ValueError, r"line 3.*duplicate key 'rho'"),
    ("malformed YAML", yaml_file("duration: [1, 2\n"), ValueError, r"not valid YAML at line \d"),
    ("YAML list at top level", yaml_file("- 1\n- 2\n"), ValueError, r"expected a mapping"),
    ("YAML unknown key", yaml_file("observer:\n  gain: 2\n"), ValueError, r"'observer\.gain'"),
    (
        "YAML file missing",
        lambda: resolve_scenario("/nonexistent/scenario.yaml"),
        ValueError,
        r"scenario file not found: '/nonexistent/scenario\.yaml'",
    ),
    # ---- environment
    ("scenario of a wrong type", lambda: parallel_env(42), TypeError, r"scenario must be .* 42"),
    ("unknown scenario name", lambda: parallel_env("papper"), ValueError, r"'papper'"),
    ("bad render mode", lambda: parallel_env(render_mode="3d"), ValueError, r"render_mode.*'3d'"),
    (
        "observation space of an unknown agent",
        lambda: parallel_env().observation_space("uav_99"),
        KeyError,
        r"unknown agent 'uav_99'.*uav_0\.\.uav_4",
    ),
    ("action space of an int", lambda: parallel_env().action_space(3), KeyError, "unknown agent 3"),
    ("float seed", lambda: parallel_env().reset(seed=1.7), TypeError, r"seed .* got 1\.7"),
    ("negative seed", lambda: parallel_env().reset(seed=-1), ValueError, r"seed .* got -1"),
    ("string seed", lambda: parallel_env().reset(seed="abc"), TypeError, r"seed .* got 'abc'"),
    ("bool seed", lambda: parallel_env().reset(seed=True), TypeError, r"seed .* got True"),
    ("NaN action", step(actions(uav_0=np.array([np.nan, 0, 0]))), ValueError, r"uav_0.*NaN"),
    ("string action", step(actions(uav_1=["1", "0", "0"])), ValueError, r"uav_1.*real numbers"),
    ("complex action", step(actions(uav_2=np.ones(3) * 1j)), ValueError, r"uav_2.*real numbers"),
    ("action of shape (2,)", step(actions(uav_3=np.zeros(2))), ValueError, r"uav_3.*\(3,\)"),
    (
        "missing action",
        step({f"uav_{i}": ZERO for i in range(4)}),
        ValueError,
        r"missing action.*uav_4",
    ),
    ("unknown agent's action", step(actions(uav_7=ZERO)), ValueError, r"unknown agent.*uav_7"),
    ("step before reset", lambda: parallel_env().step(actions()), RuntimeError, r"reset\(\)"),
    ("observer diverging with stiff gains", lambda: stiff_observer_steps(5), ValueError, r"observer diverged .* raise observer\.substeps"),
    ("AEC step before reset", lambda: aec_env().step(ZERO), RuntimeError, r"call reset\(\) before step"),
    ("AEC action for a done agent", lambda: done_aec().step(ZERO), ValueError, r"uav_0 is done .* must be None"),
    ("vec_env fractional copies", lambda: vec(num_copies=2.7), TypeError, r"num_copies.*2\.7"),
    ("vec_env zero copies", lambda: vec(num_copies=0), ValueError, r"num_copies.*>= 1, got 0"),
    ("vec_env negative seed", lambda: vec(num_copies=2).seed(-1), ValueError, r"seed .* -1"),
    (
        "vec_env string actions",
        lambda: vec(num_copies=1).step_async(np.array([["a", "b", "c"]] * 5)),
        ValueError,
        r"actions must be real numbers",
    ),
    # ---- policies and evaluation
    (
        "unknown optimizer",
        lambda: NashDMPCPolicy("paper", "lbfgs"),
        ValueError,
        r"unknown optimizer 'lbfgs'",
    ),
    ("policy: NaN observation", dmpc_act(NAN_OBS), ValueError, r"NaN.*copy 0, uav_2"),
    ("policy: observation 1e20 out of range", dmpc_act(np.full((1, 5, 47), 1e20)), ValueError, r"outside the observation space .*copy 0, uav_0, slot 0 = 1e\+20"),
    (
        "policy: observation of a wrong shape",
        dmpc_act(NAN_OBS[:, :, :10]),
        ValueError,
        r"obs must have shape \(B, 5, 47\)",
    ),
    ("policy: negative seed", lambda: NashDMPCPolicy(seed=-2), ValueError, r"seed .* -2"),
    (
        "policy: seeds for fewer copies",
        lambda: NashDMPCPolicy().reset(2, seeds=[1]),
        ValueError,
        r"seeds must hold 2 seeds",
    ),
    (
        "missing model file",
        lambda: make_policy("runs/missing/model.zip", resolve_scenario("paper")),
        FileNotFoundError,
        r"file not found: 'runs/missing/model\.zip'",
    ),
    ("corrupt TorchScript file", lambda: make_policy(str(corrupt("policy.pt")), resolve_scenario("paper")), ValueError, r"TorchScript files \(\.pt\) are not read"),
    (
        "unknown policy name",
        lambda: make_policy("foo", resolve_scenario("paper")),
        ValueError,
        r"unknown policy 'foo'",
    ),
    (
        "model of another number of UAVs",
        lambda: make_policy("random_fields_dagger", resolve_scenario("n3")),
        ValueError,
        r"reads local observations of 95 values, but scenario 'n3_paper' \(3 UAVs\) gives full observations of 33",
    ),
    (
        "no seeds",
        lambda: run_episodes(resolve_scenario("paper"), make_policy("random", resolve_scenario("paper")), []),
        ValueError,
        r"seeds must be a non-empty",
    ),
    (
        "negative episode seed",
        lambda: run_episodes(resolve_scenario("paper"), make_policy("random", resolve_scenario("paper")), [-1]),
        ValueError,
        r"seeds\[0\] .* -1",
    ),
]  # fmt: skip


@pytest.mark.parametrize(
    ("call", "error", "pattern"), [r[1:] for r in TABLE], ids=[r[0] for r in TABLE]
)
def test_bad_input_names_the_problem(call, error, pattern) -> None:  # fmt: skip
    with pytest.raises(error) as caught:
        call()
    message = caught.value.args[0] if isinstance(caught.value, KeyError) else str(caught.value)
    assert re.search(pattern, str(message)), f"{message!r} does not match {pattern!r}"


def malformed_yaml(tmp_path: Path) -> str:
    path = tmp_path / "broken.yaml"
    path.write_text("observer: {enabled: true\nduration: 3\n", encoding="utf-8")
    return str(path)


def earlier_run(tmp_path: Path) -> Path:
    out = tmp_path / "earlier"
    out.mkdir()
    (out / "summary.json").write_text("{}", encoding="utf-8")
    (out / MARKER).write_text("{}", encoding="utf-8")
    return out


def foreign_folder(tmp_path: Path) -> Path:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("not a run", encoding="utf-8")
    return out


def existing_gif(tmp_path: Path) -> Path:
    out = tmp_path / "episode.gif"
    out.write_bytes(b"GIF89a")
    return out


# (id, argv (tmp_path -> list), pattern of the one error line)
CLI_TABLE: list[tuple[str, Callable[[Path], list[str]], str]] = [
    ("zero seeds", lambda t: ["evaluate", "--seeds", "0"], r"--seeds: expected an integer >= 1"),
    (
        "zero batch size",
        lambda t: ["evaluate", "--batch-size", "0"],
        r"--batch-size: expected an integer >= 1",
    ),
    ("word for seeds", lambda t: ["evaluate", "--seeds", "abc"], r"expected an integer, got 'abc'"),
    ("negative seed start", lambda t: ["evaluate", "--seed-start", "-2"], r"--seed-start"),
    ("negative duration", lambda t: ["evaluate", "--duration", "-1"], r"--duration: .*> 0"),
    ("out is a file", lambda t: ["evaluate", "--out", str(Path(__file__))], r"--out .* is a file"),
    ("missing model", lambda t: ["evaluate", "--policy", "nothere/model.zip"], r"file not found"),
    ("unknown policy", lambda t: ["evaluate", "--policy", "foo"], r"unknown policy 'foo'"),
    ("malformed YAML", lambda t: ["evaluate", "--scenario", malformed_yaml(t)], r"not valid YAML at line"),
    ("unknown scenario", lambda t: ["evaluate", "--scenario", "papper"], r"unknown scenario 'papper'"),
    ("negative jobs", lambda t: ["reproduce", "--jobs", "-3"], r"--jobs: expected an integer >= 0"),
    ("negative seed", lambda t: ["run", "--seed", "-1"], r"--seed: expected an integer >= 0"),
    ("bad observer", lambda t: ["evaluate", "--observer", "maybe"], r"invalid choice: 'maybe'"),
    ("unknown command", lambda t: ["fly"], r"invalid choice: 'fly'"),
    ("negative timesteps", lambda t: ["train", "--algo", "ppo", "--timesteps", "-5", "--out", str(t)], r"--timesteps: expected an integer >= 1"),
    ("render: bad suffix", lambda t: ["render", "--out", str(t / "movie.txt"), "--duration", "1"], r"\.gif or \.mp4"),
    ("render: zero fps", lambda t: ["render", "--fps", "0"], r"--fps: expected an integer >= 1"),
    ("TorchScript model", lambda t: ["evaluate", "--policy", str(t / "policy.pt")], r"TorchScript files \(\.pt\) are not read"),
    ("device without torch", lambda t: ["evaluate", "--device", "cuda", "--duration", "1"], r"--device cuda needs --backend torch"),
    ("unknown device", lambda t: ["evaluate", "--backend", "torch", "--device", "gpu7", "--duration", "1"], r"device must name a torch device"),
    ("reproduce: device without torch", lambda t: ["reproduce", "--device", "cpu", "--quick", "--out", str(t)], r"needs backend='torch'"),
    ("counter draws on ray", lambda t: ["evaluate", "--backend", "ray", "--random-source", "counter", "--duration", "1"], r"--random-source counter is not available with --backend ray"),
    ("shield on the full layout", lambda t: ["evaluate", "--policy", "heuristic", "--shield", "--duration", "1"], r"safety shield reads the local observation layout.*'full'"),
    ("shield on ray", lambda t: ["evaluate", "--backend", "ray", "--shield", "--duration", "1"], r"--shield is not available with --backend ray"),
    ("compare on ray", lambda t: ["evaluate", "--backend", "ray", "--compare", "lfpio", "--duration", "1"], r"--compare is not available with --backend ray"),
    ("evaluate onto an earlier run", lambda t: ["evaluate", "--policy", "heuristic", "--duration", "1", "--out", str(earlier_run(t))], r"--out .* is not empty .* --overwrite"),
    ("reproduce onto an earlier run", lambda t: ["reproduce", "--quick", "--out", str(earlier_run(t))], r"--out .* is not empty .* --overwrite"),
    ("train onto an earlier run", lambda t: ["train", "--algo", "ppo", "--timesteps", "10", "--out", str(earlier_run(t))], r"--out .* is not empty .* --overwrite"),
    ("run onto an earlier run", lambda t: ["run", "--out", str(earlier_run(t))], r"--out .* is not empty"),
    ("overwrite a folder no run wrote", lambda t: ["evaluate", "--policy", "heuristic", "--duration", "1", "--overwrite", "--out", str(foreign_folder(t))], r"no uav-formation run wrote"),
    ("render onto an existing file", lambda t: ["render", "--duration", "1", "--policy", "heuristic", "--out", str(existing_gif(t))], r"exists; pass --overwrite"),
    ("reproduce: counter draws on ray", lambda t: ["reproduce", "--backend", "ray", "--random-source", "counter", "--quick", "--out", str(t)], r"random='counter' is not available with backend='ray'"),
]  # fmt: skip


@pytest.mark.parametrize(
    ("argv", "pattern"), [r[1:] for r in CLI_TABLE], ids=[r[0] for r in CLI_TABLE]
)
def test_cli_prints_one_line_and_exits_2(argv, pattern, tmp_path, capsys) -> None:  # fmt: skip
    try:
        status = main(argv(tmp_path))
    except SystemExit as exit_:  # argparse errors exit through SystemExit
        status = exit_.code
    err = capsys.readouterr().err
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("uav-formation: error: "), err
    assert "Traceback" not in err
    assert re.search(pattern, lines[0]), lines[0]


def test_enough_bad_inputs_are_covered() -> None:
    assert len(TABLE) + len(CLI_TABLE) >= 40


def test_debug_shows_the_traceback() -> None:
    with pytest.raises(ValueError, match="unknown policy 'foo'"):
        main(["--debug", "evaluate", "--policy", "foo"])


def test_aec_view_stays_usable_after_a_rejected_action() -> None:
    e = aec_env("paper")
    e.reset(seed=0)
    for _ in range(4):  # uav_0 .. uav_3 act
        e.step(ZERO)
    assert e.agent_selection == "uav_4"
    with pytest.raises(ValueError, match="uav_4.*NaN"):
        e.step(np.array([np.nan, 0.0, 0.0], dtype=np.float32))
    assert e.agent_selection == "uav_4"  # still its turn, nothing stored
    e.step(ZERO)  # the joint step goes through
    assert e.agent_selection == "uav_0"
    reference = parallel_env("paper")
    reference.reset(seed=0)
    _, rewards, *_ = reference.step(actions())
    assert e.rewards == pytest.approx(rewards)
    e.step(ZERO)  # and the episode goes on


def test_rejected_seed_leaves_the_vec_env_usable() -> None:
    venv = vec(num_copies=2)
    venv.seed(3)
    with pytest.raises(ValueError):
        venv.seed(-1)
    first = venv.reset()
    other = vec(num_copies=2)
    other.seed(3)
    np.testing.assert_array_equal(first, other.reset())


def test_rejected_action_leaves_the_parallel_env_usable() -> None:
    e, reference = fresh_env(), fresh_env()
    with pytest.raises(ValueError):
        e.step(actions(uav_0=np.array([np.inf, 0.0, 0.0])))
    obs, rewards, *_ = e.step(actions())
    expected_obs, expected_rewards, *_ = reference.step(actions())
    assert rewards == expected_rewards
    for agent in obs:
        np.testing.assert_array_equal(obs[agent], expected_obs[agent])


def test_missing_extra_names_the_extra(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    import importlib

    real = importlib.import_module

    def without_sb3(name: str, *args, **kwargs):
        if name.startswith("stable_baselines3"):
            raise ImportError(f"No module named {name!r}")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(importlib, "import_module", without_sb3)
    with pytest.raises(
        MissingExtraError, match=r"\[rl\] extra: pip install 'uav-formation-env\[rl\]'"
    ):
        vec(num_copies=1)
    with pytest.raises(MissingExtraError, match=r"\[rl\] extra"):
        (tmp_path / "model.zip").write_bytes(b"")  # a model file: SB3 is needed to read it
        make_policy(str(tmp_path / "model.zip"), resolve_scenario("paper"))
    assert main(["train", "--algo", "ppo", "--timesteps", "10", "--out", "x"]) == 2


def test_config_validation_of_1000_uavs() -> None:
    """A 1000-UAV scenario validates (the spanning-tree check is linear in the edges; its speed
    is measured by benchmarks/bench_scale.py, not asserted here)."""
    n = 1000
    index = np.arange(n)
    adjacency = np.zeros((n, n), dtype=int)
    adjacency[index, (index - 1) % n] = 1  # a ring
    adjacency[index, (index + 7) % n] = 1
    offsets = [[float(i), 0.0, 0.0, 0.0, 0.0, 0.0] for i in range(n)]
    data = {"formation": {"offsets": offsets, "adjacency": adjacency.tolist()}}
    data["initial"] = {"position_low": [0, 0, 0], "position_high": [5000, 5000, 0]}
    data["avoidance"] = {"obstacles": [{"center": [6000.0, 0.0], "radius": 30.0}]}
    assert with_overrides(resolve_scenario("paper"), data).n_uav == n
    adjacency[:2] = 0  # uav_0 and uav_1 hear nobody: neither reaches the other
    data["formation"]["adjacency"] = adjacency.tolist()
    with pytest.raises(ValueError, match="spanning tree"):
        with_overrides(resolve_scenario("paper"), data)
