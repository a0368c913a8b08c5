"""The on-policy trainer's files: the learned-policy format (``policy.json`` + ``policy.npz``,
v1) written from an :class:`~uav_formation_baselines.onpolicy_nets.ActorCritic` and read back
into one (``--init`` from a policy directory), and atomic writes.

A per-agent (IPPO) actor is written with its leading N axis (weights (N, out, in), biases
(N, out)) and ``"agents": N`` in the header.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from uav_formation_baselines.onpolicy_nets import ActorCritic
from uav_formation_env.config import Scenario

POLICY_FORMAT = "uav-formation-policy"


def atomic_write(path: Path, write: Callable[[Path], Any]) -> None:
    """Write ``path`` through a temporary file in its directory and ``os.replace``."""
    temporary = path.with_name(f".{path.name}.tmp")
    write(temporary)
    os.replace(temporary, path)


def export_policy(
    directory: Path, model: ActorCritic, scenario: Scenario, meta: dict[str, Any]
) -> None:
    """Write the actor of ``model`` as ``policy.npz`` then ``policy.json`` (each atomically),
    with ``meta`` (algorithm, init, frames, ...) in the header."""
    arrays = model.exported_arrays()
    clip = model.obs_norm.clip
    header = {
        "format": POLICY_FORMAT,
        "version": 1,
        "observation_dim": int(model.obs_norm.dim),
        "observation": scenario.observation.kind,
        "activation": model.activation,
        "members": 1,
        "layers": len(model.actor.linears()),
        "observation_clip": float(clip) if math.isfinite(clip) else None,
        "action": "clip",
        **meta,
    }
    if model.algo == "ippo":
        header["agents"] = model.n_agents

    def write_npz(path: Path) -> None:
        with open(path, "wb") as stream:
            np.savez(stream, **arrays)

    atomic_write(directory / "policy.npz", write_npz)
    atomic_write(directory / "policy.json", lambda p: p.write_text(json.dumps(header, indent=2)))


def read_policy(
    directory: Path, member: int | None = None
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The header and arrays of a policy directory, as one network: the file's only one, or
    network ``member`` of an ensemble (``m{member}.*`` read as ``m0.*``); ``ValueError``
    naming what is wrong."""
    try:
        header = json.loads((directory / "policy.json").read_text(encoding="utf-8"))
        with np.load(directory / "policy.npz", allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (OSError, ValueError) as error:
        raise ValueError(f"--init: cannot read a policy from {str(directory)!r}: {error}") from None
    if header.get("format") != POLICY_FORMAT or header.get("version") != 1:
        raise ValueError(f"--init: {directory} is not a {POLICY_FORMAT} v1 directory")
    members = header.get("members", 1)
    if member is not None:
        if not 0 <= member < members:
            raise ValueError(
                f"--init-member: {directory} has networks 0..{members - 1}, got {member}"
            )
        prefix = f"m{member}."  # its layers (and own statistics, if any) as network 0's
        arrays = {
            ("m0." + key[len(prefix) :] if key.startswith(prefix) else key): value
            for key, value in arrays.items()
            if key.startswith(prefix) or not key.startswith("m")
        }
        for name in ("obs_mean", "obs_std"):  # a member's own statistics replace the file's
            if f"m0.{name}" in arrays:
                arrays[name] = arrays.pop(f"m0.{name}")
        header = {**header, "members": 1}
    elif members != 1:
        raise ValueError(
            f"--init: {directory} averages {members} networks; start from one of them with "
            f"--init-member K (0..{members - 1})"
        )
    if header.get("action") != "clip":
        raise ValueError(f"--init: {directory} has action {header.get('action')!r}; expected clip")
    return header, arrays


def policy_architecture(header: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """The ``hidden``, ``activation`` and ``obs_clip`` hyper-parameters a policy file implies."""
    layers = int(header["layers"])
    hidden = tuple(int(arrays[f"m0.w{index}"].shape[-2]) for index in range(layers - 1))
    clip = header.get("observation_clip")
    return {
        "hidden": hidden,
        "activation": header["activation"],
        "obs_clip": math.inf if clip is None else float(clip),
    }


def load_actor(model: ActorCritic, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> None:
    """Copy a policy file's actor and observation statistics into ``model`` (same architecture:
    see :func:`policy_architecture`; a shared actor is copied to each agent of a per-agent one);
    ``ValueError`` if a shape differs."""
    layers = model.actor.linears()
    with torch.no_grad():
        for index, layer in enumerate(layers):
            for name, target in (("w", layer.weight), ("b", layer.bias)):
                value = torch.as_tensor(arrays[f"m0.{name}{index}"])
                if value.ndim == target.ndim - 1 and value.shape == target.shape[1:]:
                    value = value.expand_as(target)  # a shared actor starts every IPPO agent
                if tuple(value.shape) != tuple(target.shape):
                    raise ValueError(
                        f"--init: m0.{name}{index} has shape {tuple(value.shape)}, this "
                        f"{model.algo} actor needs {tuple(target.shape)} (observation width, "
                        "N or algorithm differ)"
                    )
                target.copy_(value)
        norm = model.obs_norm
        std = torch.as_tensor(arrays["obs_std"], dtype=torch.float64)
        norm.mean.copy_(torch.as_tensor(arrays["obs_mean"], dtype=torch.float64))
        norm.var.copy_((std**2 - norm.eps).clamp_min(0.0))
        norm.count.fill_(1e6)  # statistics of a finished training: new data moves them slowly
