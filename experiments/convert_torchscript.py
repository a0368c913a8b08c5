"""Convert the TorchScript students (``policy.pt``: a mean of NormalisedMLP members) into the
learned-policy file format, and check that both give the same actions (max |diff| <= 1e-5).

    python experiments/convert_torchscript.py OLD_DIR NEW_DIR [OLD_DIR NEW_DIR ...]

OLD_DIR holds ``policy.pt`` and ``scenario.yaml`` (e.g. a checkout of the commit before the format
changed: ``git show REV:baselines/models/X/policy.pt``); NEW_DIR receives ``policy.json``,
``policy.npz``, ``scenario.yaml`` and ``config.yaml``. The weights keep 16 of float32's 23 mantissa
bits (:func:`rounded`): the three shipped models then fit a wheel of <= 3 MB. The check compares the
actions of both on the observations of the first 60 s of the TorchScript policy's own episodes
(seeds 0-7).
"""

from __future__ import annotations

import shutil
import sys
from pathlib import Path

import numpy as np
import torch

from uav_formation_env.config_io import load_scenario
from uav_formation_env.episode import FormationEpisodes
from uav_formation_env.policies.policy_file import load_policy_file, merge_members, save_policy_file
from uav_formation_env.scenes import seeds_by_n_uav


def parts_of(state: dict[str, torch.Tensor]) -> list:
    """(layers, obs_mean, obs_std) per member of a NormalisedMLP ensemble's state dict."""
    prefixes = sorted({k.rsplit("obs_mean", 1)[0] for k in state if k.endswith("obs_mean")})
    parts = []
    for prefix in prefixes:
        arrays = {
            k[len(prefix) :]: v.double().numpy() for k, v in state.items() if k.startswith(prefix)
        }
        indices = sorted(int(k.split(".")[1]) for k in arrays if k.endswith(".weight"))
        layers = [(arrays[f"net.{i}.weight"], arrays[f"net.{i}.bias"]) for i in indices]
        layers[0] = (layers[0][0] * arrays["input_mask"], layers[0][1])
        parts.append((layers, arrays["obs_mean"], arrays["obs_std"]))
    return parts


DROPPED_BITS = 7  # of float32's 23 mantissa bits: weights kept to a relative 2**-17 (7.6e-6)


def rounded(weight: np.ndarray, bits: int = DROPPED_BITS) -> np.ndarray:
    """``weight`` as float32 rounded to nearest with its ``bits`` lowest mantissa bits zero:
    the same values to ~2**-(24 - bits), and a file that compresses by a quarter."""
    word = np.asarray(weight, dtype=np.float32).view(np.uint32).astype(np.uint64)
    word = ((word + (1 << (bits - 1))) >> bits) << bits
    return word.astype(np.uint32).view(np.float32)


def sample(module, scenario, seeds=range(8), steps=300) -> np.ndarray:
    """(M, dim) float32 observations of the module's own episodes: every 10th of ``steps``."""
    rows = []
    for n_uav, group in seeds_by_n_uav(scenario, list(seeds)).items():
        episodes = FormationEpisodes(scenario, len(group), n_uav=n_uav)
        obs = episodes.reset(seed=group).observation
        for step in range(steps):
            if step % 10 == 0:
                rows.append(obs.reshape(-1, obs.shape[-1]).astype(np.float32))
            with torch.no_grad():
                flat = torch.as_tensor(obs.reshape(-1, obs.shape[-1]).astype(np.float32))
                action = module(flat)[:, :3].clamp(-1, 1).double().numpy()
            obs = episodes.step(action.reshape(*obs.shape[:-1], 3)).observation
    return np.concatenate(rows)


def convert(old: Path, new: Path) -> float:
    module = torch.jit.load(str(old / "policy.pt"), map_location="cpu").eval()
    scenario = load_scenario(old / "scenario.yaml")
    members, mean, std = merge_members(parts_of(module.state_dict()))
    members = [[(rounded(w), b) for w, b in layers] for layers in members]
    save_policy_file(
        new,
        members,
        mean,
        std,
        observation=scenario.observation.kind,
        activation="tanh",
        metadata={"scenario": scenario.name, "algorithm": "dagger"},
    )
    for name in ("scenario.yaml", "config.yaml"):
        shutil.copyfile(old / name, new / name)
    obs = sample(module, scenario)
    with torch.no_grad():
        want = np.clip(module(torch.as_tensor(obs))[:, :3].double().numpy(), -1, 1)
    got = load_policy_file(new).act_flat(obs)
    return float(np.abs(want - got).max())


if __name__ == "__main__":
    pairs = sys.argv[1:]
    for old, new in zip(pairs[::2], pairs[1::2]):
        difference = convert(Path(old), Path(new))
        print(f"{old} -> {new}: max |action difference| {difference:.3g} on sample observations")
        if difference > 1e-5:
            raise SystemExit(f"{new}: differs by {difference:.3g} > 1e-5")
