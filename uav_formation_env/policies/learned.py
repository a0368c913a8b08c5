"""Saved stable-baselines3 models shared by every UAV (parameter sharing), loaded without
unpickling anything unless the caller accepts the risk.

A SB3 ``model.zip`` keeps some fields as pickles; :func:`safe_custom_objects` replaces every one
of them with a plain value rebuilt from the file's readable JSON, so loading runs no code from
the file. The observation statistics are read from ``obs_stats.npz`` (arrays, no pickle), which
the project's SB3 trainer writes; SB3's own ``vecnormalize.pkl`` is a pickle and is refused unless
``trust_pickle=True`` (``--trust-pickle``: only for files you made yourself). stable-baselines3
is imported only when a model is opened (the ``[rl]`` extra).
"""

from __future__ import annotations

import json
import pickle
import re
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import observation_size
from uav_formation_env.extras import require
from uav_formation_env.policies.protocol import PolicyBase

__all__ = [
    "NORMALIZER_PICKLE",
    "OBS_STATS_FILE",
    "SB3_ALGORITHMS",
    "ObsStats",
    "SB3Policy",
    "safe_custom_objects",
]

SB3_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")  # tried in this order on a model file
OBS_STATS_FILE = "obs_stats.npz"
NORMALIZER_PICKLE = "vecnormalize.pkl"
_TORCH_ACTIVATIONS = ("Tanh", "ReLU", "ELU", "GELU", "SiLU", "LeakyReLU")


class ObsStats:
    """SB3 ``VecNormalize``'s observation transform as plain arrays:
    ``clip((obs - mean) / sqrt(var + epsilon), -clip_obs, clip_obs)``.

    Args:
        mean, var: (dim,) running statistics.
        clip_obs: the clip of the normalised observation.
        epsilon: added to the variance.
    """

    def __init__(self, mean: np.ndarray, var: np.ndarray, clip_obs: float, epsilon: float):
        self.mean, self.var = np.asarray(mean, np.float64), np.asarray(var, np.float64)
        self.clip_obs, self.epsilon = float(clip_obs), float(epsilon)

    @classmethod
    def of(cls, normalizer: Any) -> ObsStats | None:
        """The statistics of a ``VecNormalize`` (None if it does not normalise observations)."""
        if normalizer is None or not normalizer.norm_obs:
            return None
        rms = normalizer.obs_rms
        return cls(rms.mean, rms.var, normalizer.clip_obs, normalizer.epsilon)

    def save(self, path: str | Path) -> None:
        """Write the statistics as a numpy archive (no pickle)."""
        with open(path, "wb") as stream:
            np.savez(
                stream, mean=self.mean, var=self.var, clip_obs=self.clip_obs, epsilon=self.epsilon
            )

    @classmethod
    def load(cls, path: str | Path) -> ObsStats:
        """Read an archive written by :meth:`save` (``allow_pickle=False``)."""
        try:
            with np.load(path, allow_pickle=False) as data:
                return cls(
                    data["mean"], data["var"], float(data["clip_obs"]), float(data["epsilon"])
                )
        except Exception as error:  # noqa: BLE001 - zipfile, KeyError, ValueError on bad files
            raise ValueError(f"{path}: not an observation-statistics archive ({error})") from None

    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """(M, dim) observations -> (M, dim) normalised float32."""
        out = (obs - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(out, -self.clip_obs, self.clip_obs).astype(np.float32)


def _numbers(text: str) -> np.ndarray:
    return np.array(text.replace("[", " ").replace("]", " ").split(), dtype=np.float64)


def safe_custom_objects(path: str | Path, algo_class: type) -> dict[str, Any]:
    """For every pickled field of a SB3 ``model.zip``, a plain value rebuilt from its readable
    JSON: the spaces (Box), the policy class (the algorithm's ``MlpPolicy``), ``policy_kwargs``
    (``net_arch``, a torch activation by name, plain values), constant schedules, and None for
    training state (buffers, last observations). A ``ValueError`` names a field it cannot
    rebuild."""
    from gymnasium import spaces
    from torch import nn

    try:
        with zipfile.ZipFile(path) as archive:
            data = json.loads(archive.read("data"))
    except (zipfile.BadZipFile, KeyError, ValueError, OSError) as error:
        raise ValueError(f"{path}: not a stable-baselines3 model file ({error})") from None
    objects: dict[str, Any] = {}
    for key, item in data.items():
        if not (isinstance(item, dict) and ":serialized:" in item):
            continue
        if key in ("observation_space", "action_space"):
            dtype = np.dtype(item["dtype"])
            low, high = _numbers(item["low"]).astype(dtype), _numbers(item["high"]).astype(dtype)
            objects[key] = spaces.Box(low, high, dtype=dtype)
        elif key == "policy_class":
            objects[key] = algo_class.policy_aliases["MlpPolicy"]
        elif key == "policy_kwargs":
            kwargs = {k: v for k, v in item.items() if not k.startswith(":")}
            if "activation_fn" in kwargs:
                match = re.fullmatch(
                    r"<class 'torch\.nn\.modules\.activation\.(\w+)'>", str(kwargs["activation_fn"])
                )
                if match is None or match.group(1) not in _TORCH_ACTIVATIONS:
                    raise ValueError(
                        f"{path}: policy_kwargs.activation_fn "
                        f"{kwargs['activation_fn']!r} is not a known activation"
                    )
                kwargs["activation_fn"] = getattr(nn, match.group(1))
            for name, value in kwargs.items():
                if isinstance(value, str) and name != "activation_fn":
                    raise ValueError(
                        f"{path}: policy_kwargs.{name} is a pickled object "
                        f"({value[:60]!r}); it cannot be loaded without unpickling"
                    )
            objects[key] = kwargs
        elif key == "train_freq":  # off-policy training only; loading needs a valid value
            aliases = require("stable_baselines3.common.type_aliases", "a stable-baselines3 model")
            objects[key] = aliases.TrainFreq(1, aliases.TrainFrequencyUnit.STEP)
        elif "value_schedule" in item:  # lr_schedule, clip_range: a constant is all predict needs
            found = re.search(r"val=([-+0-9.eE]+)", str(item["value_schedule"]))
            value = float(found.group(1)) if found else 0.0
            objects[key] = lambda _progress, value=value: value
        else:
            objects[key] = None  # training state: buffers, last observations, episode infos
    return objects


class SB3Policy(PolicyBase):
    """A saved stable-baselines3 model shared by every UAV (parameter sharing).

    The algorithm is ``algo`` or, if None, the first of :data:`SB3_ALGORITHMS` that loads the file
    (loaded with :func:`safe_custom_objects`: no code from the file runs). Observations are
    normalised with ``obs_stats.npz`` beside the model if present; a ``vecnormalize.pkl`` alone
    is refused unless ``trust_pickle``. Predictions are deterministic, on ``(B·N, dim)``.

    Args:
        path: the model's ``.zip``.
        algo: algorithm class name (``"PPO"``, ``"SAC"``, ...) or None to try each.
        device: torch device.
        trust_pickle: unpickle ``vecnormalize.pkl`` (runs code from the file: only for files you
            made yourself).
    """

    def __init__(
        self,
        path: str | Path,
        algo: str | None = None,
        device: str = "cpu",
        trust_pickle: bool = False,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_file() and self.path.with_suffix(".zip").is_file():
            self.path = self.path.with_suffix(".zip")
        if not self.path.is_file():
            raise FileNotFoundError(f"model file not found: {str(path)!r}")
        self.stats = self._stats(self.path.parent, trust_pickle)
        stable_baselines3 = require("stable_baselines3", "a stable-baselines3 model policy")
        names = [algo.upper()] if algo else list(SB3_ALGORITHMS)
        errors = []
        self.model = None
        for name in names:
            cls = getattr(stable_baselines3, name, None)
            if cls is None:
                errors.append(f"{name}: not a stable-baselines3 algorithm")
                continue
            try:
                custom = safe_custom_objects(self.path, cls)
                self.model = cls.load(str(self.path), device=device, custom_objects=custom)
                self.algo = name
                break
            except Exception as error:  # noqa: BLE001 - try the next algorithm
                errors.append(f"{name}: {type(error).__name__}: {error}")
        if self.model is None:
            raise ValueError(f"could not load {self.path} as {names}: " + "; ".join(errors))

    @staticmethod
    def _stats(directory: Path, trust_pickle: bool) -> ObsStats | None:
        if (directory / OBS_STATS_FILE).is_file():
            return ObsStats.load(directory / OBS_STATS_FILE)
        pickled = directory / NORMALIZER_PICKLE
        if not pickled.is_file():
            return None
        if not trust_pickle:
            raise ValueError(
                f"refusing to unpickle {str(pickled)!r} (a pickle can run code); pass "
                "--trust-pickle (trust_pickle=True) only for files you made yourself"
            )
        with open(pickled, "rb") as stream:
            return ObsStats.of(pickle.load(stream))  # noqa: S301 - accepted by trust_pickle

    @classmethod
    def from_model(cls, model: Any, normalizer: Any | None = None) -> SB3Policy:
        """A policy from a model in memory (e.g. during training) and its VecNormalize, whose
        statistics are read, never updated, by :meth:`act_batch`."""
        policy = cls.__new__(cls)
        policy.path, policy.model = None, model
        policy.stats = ObsStats.of(normalizer)
        policy.algo = type(model).__name__
        return policy

    @property
    def observation_size(self) -> int:
        """Number of observation values the model takes."""
        return int(np.prod(self.model.observation_space.shape))

    def check_scenario(self, scenario: Scenario) -> None:
        """``ValueError`` naming both sizes if the model cannot act on ``scenario``'s
        observations."""
        expected = observation_size(scenario)
        if self.observation_size != expected:
            raise ValueError(
                f"the model {self._name()} takes observations of {self.observation_size} values, "
                f"but scenario {scenario.name!r} ({scenario.n_uav} UAVs) gives {expected}: it was "
                "trained on a scenario with another number of UAVs"
            )

    def _name(self) -> str:
        return repr(str(self.path)) if self.path is not None else "in memory"

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """(B, N, dim) observations -> (B, N, 3) deterministic actions in [-1, 1]."""
        obs = np.asarray(obs, dtype=np.float32)
        batch, n, dim = obs.shape
        if dim != self.observation_size:
            raise ValueError(
                f"the model {self._name()} takes observations of {self.observation_size} values, "
                f"got {dim} ({n} UAVs)"
            )
        flat = obs.reshape(batch * n, dim)
        if self.stats is not None:
            flat = self.stats.normalize(flat)
        actions, _ = self.model.predict(flat, deterministic=True)
        return np.clip(np.asarray(actions, dtype=float).reshape(batch, n, 3), -1.0, 1.0)
