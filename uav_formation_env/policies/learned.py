"""Saved learned policies, shared by every UAV (parameter sharing): a stable-baselines3 model or a
TorchScript module (the RLlib recipe's export).

stable-baselines3 is never imported at module import: :class:`SB3Policy` loads it through
:func:`uav_formation_env.extras.require` when a model file is opened (the ``[rl]`` extra).
"""

from __future__ import annotations

import pickle
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import observation_size
from uav_formation_env.extras import require

__all__ = ["SB3_ALGORITHMS", "SB3Policy", "TorchScriptPolicy"]

SB3_ALGORITHMS = ("PPO", "SAC", "TD3", "A2C", "DDPG")  # tried in this order on a model file


class SB3Policy:
    """A saved stable-baselines3 model shared by every UAV (parameter sharing).

    stable-baselines3 is imported only here, when the model is loaded (the ``[rl]`` extra). The
    algorithm is ``algo`` or, if None, the first of :data:`SB3_ALGORITHMS` that loads the file.
    If ``vecnormalize.pkl`` lies beside the model, observations are normalised with its running
    statistics (not updated). Predictions are deterministic, on ``(B·N, dim)`` observations.

    Args:
        path: the model's ``.zip``.
        algo: algorithm class name (``"PPO"``, ``"SAC"``, ...) or None to try each.
        device: torch device.
    """

    def __init__(self, path: str | Path, algo: str | None = None, device: str = "cpu") -> None:
        self.path = Path(path)
        if not self.path.is_file() and self.path.with_suffix(".zip").is_file():
            self.path = self.path.with_suffix(".zip")
        if not self.path.is_file():
            raise FileNotFoundError(f"model file not found: {str(path)!r}")
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
                self.model = cls.load(str(self.path), device=device)
                self.algo = name
                break
            except Exception as error:  # noqa: BLE001 - try the next algorithm
                errors.append(f"{name}: {type(error).__name__}: {error}")
        if self.model is None:
            raise ValueError(f"could not load {self.path} as {names}: " + "; ".join(errors))
        self.normalizer = None
        stats = self.path.parent / "vecnormalize.pkl"
        if stats.is_file():
            with open(stats, "rb") as stream:
                self.normalizer = pickle.load(stream)  # VecNormalize without its venv
            self.normalizer.training = False

    @classmethod
    def from_model(cls, model: Any, normalizer: Any | None = None) -> SB3Policy:
        """A policy from a model in memory (e.g. during training) and its VecNormalize.

        The normaliser's statistics are read, never updated, by :meth:`act_batch`.
        """
        policy = cls.__new__(cls)
        policy.path, policy.model, policy.normalizer = None, model, normalizer
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
        obs = np.asarray(obs, dtype=np.float32)
        batch, n, dim = obs.shape
        if dim != self.observation_size:
            raise ValueError(
                f"the model {self._name()} takes observations of {self.observation_size} values, "
                f"got {dim} ({n} UAVs)"
            )
        flat = obs.reshape(batch * n, dim)
        if self.normalizer is not None:
            flat = self.normalizer.normalize_obs(flat)
        actions, _ = self.model.predict(flat, deterministic=True)
        return np.clip(np.asarray(actions, dtype=float).reshape(batch, n, 3), -1.0, 1.0)


class TorchScriptPolicy:
    """A policy exported as TorchScript (e.g. the RLlib recipe's ``policy.pt``), shared by every
    UAV: observations (B·N, dim) float32 -> (B·N, 2·3) the Gaussian's mean and log-std; the
    action is the mean, clipped to [-1, 1]. Needs torch only (the ``[rl]`` extra), not the
    trainer that made it.

    Args:
        path: the ``.pt`` file.
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"model file not found: {str(path)!r}")
        torch = require("torch", "a TorchScript policy")
        self._torch = torch
        self.module = torch.jit.load(str(self.path), map_location="cpu").eval()

    def check_scenario(self, scenario: Scenario) -> None:
        """``ValueError`` naming both sizes if the module cannot take the scenario's observation
        (tried on one observation of zeros)."""
        dim = observation_size(scenario)
        try:
            self._forward(np.zeros((1, dim), dtype=np.float32))
        except Exception as error:  # noqa: BLE001 - torch raises several kinds on a size mismatch
            width = self.input_width()
            takes = "" if width is None else f" (it takes {width})"
            raise ValueError(
                f"the model {str(self.path)!r} cannot act on observations of {dim} values{takes} "
                f"(scenario {scenario.name!r}, {scenario.n_uav} UAVs): {type(error).__name__}; "
                "was it trained on another scenario or observation layout?"
            ) from None

    def input_width(self) -> int | None:
        """The input width of the module's first weight matrix (its first linear layer, in
        every exporter of this project), or None if it has none."""
        for parameter in self.module.parameters():
            if parameter.ndim == 2:
                return int(parameter.shape[1])
        return None

    def _forward(self, flat: np.ndarray) -> np.ndarray:
        with self._torch.no_grad():
            out = self.module(self._torch.as_tensor(flat)).numpy()
        return out[:, :3]  # the mean of the diagonal Gaussian

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=np.float32)
        batch, n, dim = obs.shape
        mean = self._forward(obs.reshape(batch * n, dim))
        return np.clip(mean.astype(float).reshape(batch, n, 3), -1.0, 1.0)
