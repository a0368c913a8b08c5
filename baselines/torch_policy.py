"""The exported form of a learned shared policy: one TorchScript file any trainer can write.

Every learned baseline (behaviour cloning, BenchMARL's MAPPO / IPPO / MASAC, RLlib) ends as a
``policy.pt``: a TorchScript module mapping (M, dim) float32 observations to (M, 6) values, the
mean action (3, normalised, clipped to [-1, 1] by the reader) and a log standard deviation (3).
:class:`uav_formation_env.policies.learned.TorchScriptPolicy` reads it, so
``uav-formation evaluate --policy DIR/policy.pt`` and every notebook fly it without the trainer
installed.

:class:`NormalisedMLP` is the network behaviour cloning trains and exports; :func:`save_policy`
traces and saves any module of that contract, and checks that the saved file gives the same
numbers as the module on sample observations.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from uav_formation_env.core.local_observation import decode_local_observations

__all__ = [
    "ACTIVATIONS",
    "ApproachFeatures",
    "MeanEnsemble",
    "NormalisedMLP",
    "save_policy",
    "with_features",
]

BRAKING_CLIP = 100.0  # [m/s^2]: a UAV at or inside a surface needs "more than any thrust"

ACTIVATIONS: dict[str, type[nn.Module]] = {
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
    "elu": nn.ELU,
    "gelu": nn.GELU,
    "silu": nn.SiLU,
}


class ApproachFeatures(nn.Module):
    """How fast each UAV approaches each obstacle of its local observation, and the braking it
    would need: values the network would otherwise have to build from products of slots.

    Per obstacle slot q (horizontal plane; an empty slot, all zeros, gives zeros):

    - the closing speed v . c_q [m/s], c_q the unit vector from the UAV to the obstacle's centre,
    - the reference's closing speed v^d . c_q [m/s],
    - the deceleration that stops the closing motion at the surface, max(v . c_q, 0)^2 / (2 g_q)
      [m/s^2] (g_q the distance to the surface, floored at 1 m; clipped at
      :data:`BRAKING_CLIP`).

    Args:
        neighbours, obstacles, nearest: the local layout's k, m and r
            (:mod:`uav_formation_env.core.local_observation`).
    """

    def __init__(self, neighbours: int, obstacles: int, nearest: int) -> None:
        super().__init__()
        self.layout = (int(neighbours), int(obstacles), int(nearest))
        self.size = 3 * int(obstacles)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) local observations -> (M, 3 m) float32 features, slot by slot."""
        with warnings.catch_warnings():
            # decode's check of the last axis reads a shape: a constant of the trace, which is
            # right (the layout is fixed); save_policy verifies the file on another batch size
            warnings.simplefilter("ignore", torch.jit.TracerWarning)
            decoded = decode_local_observations(obs, *self.layout)
        relative = decoded.obstacle_relative  # (M, m, 2) [m]
        towards = relative / torch.linalg.vector_norm(relative, dim=-1, keepdim=True).clamp_min(
            1e-6
        )
        closing = (decoded.velocity[..., None, :2] * towards).sum(dim=-1)  # (M, m) [m/s]
        reference = (decoded.reference_velocity[..., None, :2] * towards).sum(dim=-1)
        gap = decoded.obstacle_surface.clamp_min(1.0)  # [m]
        braking = (torch.relu(closing) ** 2 / (2.0 * gap)).clamp_max(BRAKING_CLIP)
        features = torch.stack((closing, reference, braking), dim=-1)  # 0 in an empty slot
        return features.reshape(*features.shape[:-2], self.size).float()


def with_features(obs: torch.Tensor, features: nn.Module | None) -> torch.Tensor:
    """(M, dim) observations -> (M, dim + F): ``obs`` with ``features(obs)`` appended (``obs``
    itself when ``features`` is None); what :class:`NormalisedMLP` standardises."""
    return obs if features is None else torch.cat((obs, features(obs)), dim=-1)


class NormalisedMLP(nn.Module):
    """Observation standardisation, an MLP, and a state-independent log-std.

    Args:
        obs_mean: (dim,) mean of the observations the network was fitted on.
        obs_std: (dim,) their standard deviation (floored at 1e-6: constant slots stay finite).
        hidden: widths of the hidden layers.
        activation: a key of :data:`ACTIVATIONS`.
        log_std: the exported log standard deviation of the action (unused by deterministic
            evaluation; kept so the file has the TorchScript policy contract).
        masked_slots: observation slots the network never sees (set to 0 after standardising).
        features: a module (M, dim) -> (M, F) whose values are appended to the observation
            before standardising (e.g. :class:`ApproachFeatures`); ``obs_mean`` and ``obs_std``
            are then (dim + F,), the statistics of :meth:`inputs`.
    """

    def __init__(
        self,
        obs_mean: np.ndarray,
        obs_std: np.ndarray,
        hidden: Sequence[int] = (256, 256),
        activation: str = "tanh",
        log_std: float = -2.0,
        masked_slots: Sequence[int] = (),
        features: nn.Module | None = None,
    ) -> None:
        super().__init__()
        self.features = features
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(ACTIVATIONS)}, got {activation!r}")
        mean = torch.as_tensor(np.asarray(obs_mean, dtype=np.float32))
        std = torch.as_tensor(np.maximum(np.asarray(obs_std, dtype=np.float32), 1e-6))
        if mean.ndim != 1 or mean.shape != std.shape:
            raise ValueError(
                f"obs_mean and obs_std must be (dim,) vectors, got {mean.shape} and {std.shape}"
            )
        self.register_buffer("obs_mean", mean)
        self.register_buffer("obs_std", std)
        mask = torch.ones_like(mean)
        for slot in masked_slots:
            if not 0 <= int(slot) < mask.shape[0]:
                raise ValueError(f"masked_slots: slot {slot} outside 0..{mask.shape[0] - 1}")
            mask[int(slot)] = 0.0
        self.register_buffer("input_mask", mask)
        layers: list[nn.Module] = []
        width = int(mean.shape[0])
        for size in hidden:
            layers += [nn.Linear(width, int(size)), ACTIVATIONS[activation]()]
            width = int(size)
        layers.append(nn.Linear(width, 3))
        self.net = nn.Sequential(*layers)
        self.log_std = nn.Parameter(torch.full((3,), float(log_std)), requires_grad=False)

    def inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, dim + F): with the ``features`` appended, unscaled."""
        return with_features(obs, self.features)

    def mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, 3) mean normalised action (unclipped)."""
        return self.net((self.inputs(obs) - self.obs_mean) / self.obs_std * self.input_mask)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, 6): mean action and log-std."""
        mean = self.mean_action(obs)
        return torch.cat([mean, self.log_std.expand_as(mean)], dim=-1)


class MeanEnsemble(nn.Module):
    """Several policies of this contract as one: (M, dim) -> (M, 6), the members' mean of each
    output (mean action and log-std).

    Args:
        members: modules (or loaded TorchScript policies) of the same observation layout.
    """

    def __init__(self, members: Sequence[nn.Module]) -> None:
        super().__init__()
        if not members:
            raise ValueError("members: give at least one policy")
        self.members = nn.ModuleList(members)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, 6): the members' mean."""
        return torch.stack([member(obs) for member in self.members]).mean(dim=0)


def save_policy(module: nn.Module, path: str | Path, sample: np.ndarray) -> Path:
    """Trace ``module`` as TorchScript and save it as ``path``; return the path.

    Args:
        module: (M, dim) float32 -> (M, 6) (mean action, log-std).
        path: the ``.pt`` file (parents created).
        sample: (M, dim) observations the saved file must map to the module's own outputs
            (max abs difference <= 1e-6); a ``RuntimeError`` names the difference otherwise.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = module.eval()
    obs = torch.as_tensor(np.asarray(sample, dtype=np.float32))
    # traced, not scripted: scripting re-reads the module's source file, so a run that exports
    # while its source is being edited fails (seen: a 5-minute BenchMARL run lost at export)
    with torch.no_grad():
        traced = torch.jit.trace(module, obs)
    traced.save(str(path))
    loaded = torch.jit.load(str(path), map_location="cpu")
    check = torch.cat([obs, obs[:1] * 2.0 + 1.0])  # another batch size and other values
    with torch.no_grad():
        want, got = module(check), loaded(check)
    if got.shape != (check.shape[0], 6):
        raise RuntimeError(f"the exported policy returns {tuple(got.shape)}, expected (M, 6)")
    difference = float((want - got).abs().max())
    if difference > 1e-6:
        raise RuntimeError(f"the saved policy differs from the module by {difference:.3g}")
    return path
