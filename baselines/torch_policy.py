"""Torch policies to the learned-policy file format (``policy.json`` + ``policy.npz``).

Every learned baseline (behaviour cloning, BenchMARL's MAPPO / IPPO / MASAC, RLlib) ends as a
policy directory of :mod:`uav_formation_env.policies.policy_file`: arrays that numpy flies and
that load without running code, so ``uav-formation evaluate --policy DIR`` and every notebook
fly it without the trainer (or torch) installed.

:class:`NormalisedMLP` is the network behaviour cloning trains; :func:`save_policy` turns it, a
list of them (an ensemble) or any plain MLP chain into arrays, and checks that the saved file
gives the module's actions on sample observations.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from uav_formation_env.policies.policy_file import (
    load_policy_file,
    merge_members,
    save_policy_file,
)

__all__ = [
    "ACTIVATIONS",
    "NormalisedMLP",
    "policy_arrays",
    "save_policy",
]


ACTIVATIONS: dict[str, type[nn.Module]] = {
    "tanh": nn.Tanh,
    "relu": nn.ReLU,
    "elu": nn.ELU,
    "gelu": nn.GELU,
    "silu": nn.SiLU,
}


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
    """

    def __init__(
        self,
        obs_mean: np.ndarray,
        obs_std: np.ndarray,
        hidden: Sequence[int] = (256, 256),
        activation: str = "tanh",
        log_std: float = -2.0,
        masked_slots: Sequence[int] = (),
    ) -> None:
        super().__init__()
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

    def mean_action(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, 3) mean normalised action (unclipped)."""
        return self.net((obs - self.obs_mean) / self.obs_std * self.input_mask)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """(M, dim) observations -> (M, 6): mean action and log-std."""
        mean = self.mean_action(obs)
        return torch.cat([mean, self.log_std.expand_as(mean)], dim=-1)


def _layers(linears: Sequence[nn.Linear]) -> list[tuple[np.ndarray, np.ndarray]]:
    return [
        (
            layer.weight.detach().cpu().double().numpy(),
            layer.bias.detach().cpu().double().numpy(),
        )
        for layer in linears
    ]


def _activation_name(module: nn.Module) -> str:
    """The key of :data:`ACTIVATIONS` of the one activation type inside ``module``."""
    names = {
        name for sub in module.modules() for name, cls in ACTIVATIONS.items() if type(sub) is cls
    }
    if len(names) != 1:
        raise ValueError(f"expected one activation type of {sorted(ACTIVATIONS)}, found {names}")
    return names.pop()


def _mlp_part(model: NormalisedMLP) -> tuple[list, np.ndarray, np.ndarray]:
    """(layers, obs_mean, obs_std) of a :class:`NormalisedMLP`, its input mask folded into the
    first layer."""
    layers = _layers([m for m in model.net if isinstance(m, nn.Linear)])
    mask = model.input_mask.detach().cpu().double().numpy()
    layers[0] = (layers[0][0] * mask, layers[0][1])
    return layers, model.obs_mean.cpu().double().numpy(), model.obs_std.cpu().double().numpy()


def policy_arrays(
    module: nn.Module | Sequence[NormalisedMLP], exclude: Sequence[str] = ()
) -> tuple[list, np.ndarray, np.ndarray, str]:
    """The arrays of the policy file format of a torch policy: (members, obs_mean, obs_std,
    activation) for :func:`~uav_formation_env.policies.policy_file.save_policy_file`.

    Args:
        module: a :class:`NormalisedMLP`, a sequence of them (an ensemble: the mean of their
            actions), or any module whose ``nn.Linear`` layers, in registration order, form one
            MLP chain with one activation type (its last layer's first 3 outputs are the action;
            no observation statistics).
        exclude: names of submodules to skip in the chain (e.g. a critic's).
    """
    if isinstance(module, NormalisedMLP):
        module = [module]
    if isinstance(module, Sequence):
        members, mean, std = merge_members([_mlp_part(m) for m in module])
        return members, mean, std, _activation_name(nn.ModuleList(module))
    linears = [
        m
        for name, m in module.named_modules()
        if isinstance(m, nn.Linear) and not any(part in name for part in exclude)
    ]
    if not linears:
        raise ValueError("the module has no nn.Linear layers to export")
    layers = _layers(linears)
    layers[-1] = (layers[-1][0][:3], layers[-1][1][:3])  # the action; the rest is its spread
    dim = layers[0][0].shape[1]
    return [layers], np.zeros(dim), np.ones(dim), _activation_name(module)


def save_policy(
    module: nn.Module | Sequence[NormalisedMLP],
    directory: str | Path,
    sample: np.ndarray,
    *,
    observation: str,
    action: str = "clip",
    exclude: Sequence[str] = (),
    metadata: dict | None = None,
) -> Path:
    """Save a torch policy in the policy file format (``DIR/policy.json``, ``DIR/policy.npz``)
    and check it; return the directory.

    Args:
        module: see :func:`policy_arrays`; called as (M, dim) float32 -> (M, >= 3), the first 3
            columns the action before ``action`` (a sequence: the mean of its members').
        directory: the output directory (created).
        sample: (M, dim) observations on which the saved file must give the module's actions
            (max abs difference <= 1e-5, else a ``RuntimeError`` naming it).
        observation: the scenario's ``observation.kind`` (``"full"`` or ``"local"``).
        action: ``"clip"`` or ``"tanh"``, as in the file format; a module whose output is
            already squashed exports with ``"clip"``.
        exclude, metadata: see :func:`policy_arrays`; free JSON fields of ``policy.json``.
    """
    members, mean, std, activation = policy_arrays(module, exclude)
    save_policy_file(
        directory,
        members,
        mean,
        std,
        observation=observation,
        activation=activation,
        action=action,
        metadata=metadata,
    )
    obs = np.asarray(sample, dtype=np.float32)
    check = np.concatenate([obs, obs[:1] * 2.0 + 1.0])  # another batch size and other values
    modules = list(module) if isinstance(module, Sequence) else [module]
    with torch.no_grad():
        outs = [m.eval()(torch.as_tensor(check)).double()[:, :3] for m in modules]
    want = torch.stack(outs).mean(dim=0).numpy()
    want = np.tanh(want) if action == "tanh" else np.clip(want, -1.0, 1.0)
    got = load_policy_file(directory).act_flat(check)
    difference = float(np.abs(want - got).max())
    if difference > 1e-5:
        raise RuntimeError(f"the saved policy differs from the module by {difference:.3g}")
    return Path(directory)
