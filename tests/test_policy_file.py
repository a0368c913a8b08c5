"""The learned-policy file format: numbers by hand, the torch exporters, the shipped models, and
model files that must not run code when loaded."""

from __future__ import annotations

import base64
import json
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from uav_formation_env.config_io import load_scenario, resolve_scenario
from uav_formation_env.policies.policy_file import (
    FilePolicy,
    load_policy_file,
    merge_members,
    save_policy_file,
)
from uav_formation_env.policies.registry import (
    MODELS_DIR,
    POLICY_HELP,
    SHIPPED_MODELS,
    make_policy,
)


def _tiny(tmp_path: Path, **header) -> Path:
    """dim 2 -> 2 hidden (relu) -> 3: W0 = [[1, 0], [0, -1]], W1 = [[1, 1], [2, 0], [0, 0]]."""
    members = [
        [
            (np.array([[1.0, 0.0], [0.0, -1.0]]), np.array([0.0, 0.5])),
            (np.array([[1.0, 1.0], [2.0, 0.0], [0.0, 0.0]]), np.array([0.0, 0.0, -0.25])),
        ]
    ]
    options = {"observation": "full", "activation": "relu", **header}
    return save_policy_file(
        tmp_path, members, np.array([1.0, 0.0]), np.array([2.0, 1.0]), **options
    )


def test_actions_by_hand(tmp_path: Path) -> None:
    policy = load_policy_file(_tiny(tmp_path))
    # obs (3, 0.25): x = (1, 0.25); h = relu(1, -0.25 + 0.5) = (1, 0.25); out (1.25, 2, -0.25)
    np.testing.assert_allclose(policy.act_flat(np.array([[3.0, 0.25]])), [[1.0, 1.0, -0.25]])
    np.testing.assert_allclose(policy.outputs(np.array([[3.0, 0.25]])), [[1.25, 2.0, -0.25]])
    squashed = load_policy_file(_tiny(tmp_path / "t", action="tanh", observation_clip=0.5))
    # x clipped to (0.5, 0.25): h = (0.5, 0.25), out (0.75, 1, -0.25), then tanh
    np.testing.assert_allclose(
        squashed.act_flat(np.array([[3.0, 0.25]])), np.tanh([[0.75, 1.0, -0.25]])
    )
    assert policy.act_batch(np.zeros((4, 5, 2))).shape == (4, 5, 3)


def test_members_with_their_own_statistics_clip_their_own_normalisation(tmp_path: Path) -> None:
    layers = [
        (np.array([[1.0, 0.0], [0.0, -1.0]]), np.array([0.0, 0.5])),
        (np.array([[1.0, 1.0], [2.0, 0.0], [0.0, 0.0]]), np.array([0.0, 0.0, -0.25])),
    ]
    own = [(np.array([1.0, 0.0]), np.array([2.0, 1.0])), (np.array([0.0, 0.0]), np.ones(2))]
    options = {"observation": "full", "activation": "relu", "observation_clip": 0.5}
    path = save_policy_file(tmp_path, [layers, layers], *own[0], **options, member_statistics=own)
    policy = load_policy_file(path)
    # obs (3, 0.25): member 0 x = (1, 0.25) -> (0.5, 0.25), out (0.75, 1, -0.25); member 1
    # x = (3, 0.25) -> (0.5, 0.25), the same; at obs (1.2, 0): member 0 x = (0.1, 0),
    # h = (0.1, 0.5), out (0.6, 0.2, -0.25); member 1 x = (0.5, 0), the same h as at
    # (0.5, 0.5): out (1, 1, -0.25); the mean (0.8, 0.6, -0.25)
    np.testing.assert_allclose(
        policy.outputs(np.array([[3.0, 0.25], [1.2, 0.0]])),
        [[0.75, 1.0, -0.25], [0.8, 0.6, -0.25]],
    )
    parts = policy.parts()
    np.testing.assert_array_equal(parts[1][1], own[1][0])
    with pytest.raises(ValueError, match="one \\(mean, std\\) per member"):
        save_policy_file(tmp_path / "x", [layers], *own[0], **options, member_statistics=own)
    arrays = dict(np.load(path / "policy.npz"))
    np.savez(path / "policy.npz", **{k: v for k, v in arrays.items() if k != "m1.obs_std"})
    with pytest.raises(ValueError, match="missing array 'm1.obs_std'"):
        FilePolicy(path)
    np.savez(path / "policy.npz", **{k: v for k, v in arrays.items() if k != "m1.obs_mean"})
    with pytest.raises(ValueError, match="member statistics need"):
        FilePolicy(path)


def test_merged_members_keep_each_members_own_statistics(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    parts = []
    for scale in (1.0, 1e-6, 30.0):  # a near-constant slot in one member only
        layers = [
            (rng.normal(size=(8, 4)), rng.normal(size=8)),
            (rng.normal(size=(3, 8)), rng.normal(size=3)),
        ]
        parts.append((layers, rng.normal(size=4), np.full(4, scale) * rng.uniform(0.5, 2, 4)))
    obs = parts[1][1] + rng.normal(size=(50, 4)) * 1e-6  # where the near-constant member is sane
    single = [
        load_policy_file(
            save_policy_file(
                tmp_path / str(j), [layers], m, s, observation="local", activation="tanh"
            )
        )
        for j, (layers, m, s) in enumerate(parts)
    ]
    members, mean, std = merge_members(parts)
    merged = load_policy_file(
        save_policy_file(
            tmp_path / "all", members, mean, std, observation="local", activation="tanh"
        )
    )
    want = sum(p.outputs(obs) for p in single) / 3
    np.testing.assert_allclose(merged.outputs(obs), want, atol=1e-5)


@pytest.mark.parametrize(
    ("change", "pattern"),
    [
        ({"format": "other"}, r"format is 'other', expected"),
        ({"version": 2}, r"version is 2"),
        ({"activation": "swish"}, r"activation is 'swish'"),
        ({"members": 0}, r"members is 0"),
        ({"observation_clip": -1}, r"observation_clip is -1"),
    ],
)
def test_bad_header_names_the_field(tmp_path: Path, change: dict, pattern: str) -> None:
    path = _tiny(tmp_path)
    header = json.loads((path / "policy.json").read_text())
    (path / "policy.json").write_text(json.dumps({**header, **change}))
    with pytest.raises(ValueError, match=pattern):
        FilePolicy(path)


def test_missing_or_misshapen_arrays_are_named(tmp_path: Path) -> None:
    path = _tiny(tmp_path)
    arrays = dict(np.load(path / "policy.npz"))
    np.savez(path / "policy.npz", **{k: v for k, v in arrays.items() if k != "m0.b1"})
    with pytest.raises(ValueError, match="missing array 'm0.b1'"):
        FilePolicy(path)
    np.savez(path / "policy.npz", **{**arrays, "m0.w1": np.zeros((4, 2)), "m0.b1": np.zeros(4)})
    with pytest.raises(ValueError, match="last layer has 4 outputs"):
        FilePolicy(path)
    with pytest.raises(FileNotFoundError, match="policy file not found"):
        FilePolicy(tmp_path / "nowhere")


def test_policy_file_scenario_check(tmp_path: Path) -> None:
    policy = load_policy_file(_tiny(tmp_path))
    with pytest.raises(ValueError, match="reads full observations of 2 values"):
        policy.check_scenario(resolve_scenario("paper"))


# ------------------------------------------------------------------------- torch exporters
def test_torch_mlps_and_ensembles_export_their_actions(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from uav_formation_baselines.torch_policy import NormalisedMLP, save_policy

    rng = np.random.default_rng(1)
    models = []
    for k in range(3):
        torch.manual_seed(k)
        mean, std = rng.normal(size=6), rng.uniform(0.1, 3.0, 6)
        models.append(NormalisedMLP(mean, std, (16, 16), "elu", masked_slots=(k,)))
    obs = rng.normal(size=(40, 6)).astype(np.float32) * 2
    one = load_policy_file(save_policy(models[0], tmp_path / "one", obs, observation="full"))
    with torch.no_grad():
        want = models[0].mean_action(torch.as_tensor(obs)).double().numpy()
        mean = torch.stack([m.mean_action(torch.as_tensor(obs)) for m in models]).mean(0)
    np.testing.assert_allclose(one.outputs(obs), want, atol=1e-5)
    ensemble = load_policy_file(save_policy(models, tmp_path / "ens", obs, observation="full"))
    assert ensemble.header["members"] == 3
    np.testing.assert_allclose(ensemble.outputs(obs), mean.double().numpy(), atol=1e-5)


def test_a_plain_mlp_exports_its_first_three_outputs(tmp_path: Path) -> None:
    torch = pytest.importorskip("torch")
    from uav_formation_baselines.torch_policy import save_policy

    torch.manual_seed(0)
    net = torch.nn.Sequential(torch.nn.Linear(5, 8), torch.nn.GELU(), torch.nn.Linear(8, 6))
    obs = np.random.default_rng(0).normal(size=(10, 5)).astype(np.float32)
    policy = load_policy_file(save_policy(net, tmp_path, obs, observation="full", action="tanh"))
    with torch.no_grad():
        want = torch.tanh(net(torch.as_tensor(obs))[:, :3]).double().numpy()
    np.testing.assert_allclose(policy.act_flat(obs), want, atol=1e-5)


# ------------------------------------------------------------------------- shipped models
def test_shipped_models_are_named_in_the_help() -> None:
    assert sorted(SHIPPED_MODELS) == [
        "paper_ppo",
        "random_fields_dagger",
        "random_swarm_dagger",
    ]
    for name in SHIPPED_MODELS:
        assert name in POLICY_HELP
        assert (MODELS_DIR / name / "policy.json").is_file()


def test_shipped_models_load_with_deprecations_as_errors() -> None:
    code = (
        "import numpy as np\n"
        "from uav_formation_env.config_io import load_scenario\n"
        "from uav_formation_env.policies.registry import MODELS_DIR, SHIPPED_MODELS, make_policy\n"
        "for name in SHIPPED_MODELS:\n"
        "    scenario = load_scenario(MODELS_DIR / name / 'scenario.yaml')\n"
        "    policy = make_policy(name, scenario)\n"
        "    a = policy.act_batch(np.zeros((1, 4, policy.observation_size)))\n"
        "    assert a.shape == (1, 4, 3) and np.all(np.isfinite(a))\n"
        "import sys\n"
        "assert 'torch' not in sys.modules, 'loading a policy file imported torch'\n"
        "print('ok')\n"
    )
    done = subprocess.run(
        [sys.executable, "-W", "error::DeprecationWarning", "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


def test_shipped_model_by_name_flies_its_own_scenario() -> None:
    scenario = load_scenario(MODELS_DIR / "random_fields_dagger" / "scenario.yaml")
    policy = make_policy("random_fields_dagger", scenario)
    with pytest.raises(ValueError, match="reads local observations of 95 values"):
        make_policy("random_fields_dagger", resolve_scenario("random_fields"))  # full layout
    assert policy.observation_size == 95


# ------------------------------------------------------------------------- files that run code
class _Payload:
    """Unpickling it creates ``marker``: proof that loading ran code from the file."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


def _sb3_model(tmp_path: Path) -> Path:
    pytest.importorskip("stable_baselines3")
    from stable_baselines3 import PPO

    from uav_formation_env import vec_env

    model = PPO(
        "MlpPolicy", vec_env("paper", num_copies=1, duration=4.0), n_steps=16, batch_size=16
    )
    model.save(tmp_path / "model.zip")
    return tmp_path / "model.zip"


def test_pickled_statistics_are_refused_and_never_run(tmp_path: Path) -> None:
    path = _sb3_model(tmp_path)
    marker = tmp_path / "ran"
    (tmp_path / "vecnormalize.pkl").write_bytes(pickle.dumps(_Payload(marker)))
    with pytest.raises(
        ValueError, match=r"refusing to unpickle .*vecnormalize\.pkl.*--trust-pickle"
    ):
        make_policy(str(path), resolve_scenario("paper"))
    assert not marker.exists()


def test_pickled_fields_of_a_model_zip_never_run(tmp_path: Path) -> None:
    path = _sb3_model(tmp_path)
    marker = tmp_path / "ran"
    payload = base64.b64encode(pickle.dumps(_Payload(marker))).decode()
    with zipfile.ZipFile(path) as archive:
        files = {name: archive.read(name) for name in archive.namelist()}
    data = json.loads(files["data"])
    pickled = [k for k, v in data.items() if isinstance(v, dict) and ":serialized:" in v]
    assert {"lr_schedule", "policy_class", "observation_space"} <= set(pickled)
    for key in pickled:
        data[key][":serialized:"] = payload  # every pickled field replaced by the payload
    data["extra"] = {":type:": "<class 'object'>", ":serialized:": payload}
    files["data"] = json.dumps(data).encode()
    with zipfile.ZipFile(path, "w") as archive:
        for name, content in files.items():
            archive.writestr(name, content)
    policy = make_policy(str(path), resolve_scenario("paper"))
    assert policy.algo == "PPO"
    assert policy.act_batch(np.zeros((1, 5, policy.observation_size))).shape == (1, 5, 3)
    assert not marker.exists()


def test_pickles_posing_as_models_never_run(tmp_path: Path) -> None:
    marker = tmp_path / "ran"
    blob = pickle.dumps(_Payload(marker))
    (tmp_path / "model.zip").write_bytes(blob)
    with pytest.raises(ValueError, match="could not load"):
        make_policy(str(tmp_path / "model.zip"), resolve_scenario("paper"))
    (tmp_path / "policy.pt").write_bytes(blob)
    with pytest.raises(ValueError, match=r"TorchScript files \(\.pt\) are not read"):
        make_policy(str(tmp_path / "policy.pt"), resolve_scenario("paper"))
    exported = _tiny(tmp_path / "dir")
    np.save(exported / "evil.npy", np.array([_Payload(marker)], dtype=object))
    with zipfile.ZipFile(exported / "policy.npz", "a") as archive:
        archive.write(exported / "evil.npy", "m0.w0.npy")  # an object array in place of a weight
    with pytest.raises(ValueError, match="not a readable numpy archive"):
        FilePolicy(exported)
    assert not marker.exists()
