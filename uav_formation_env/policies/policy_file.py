"""The learned-policy file format (v1): a directory of plain JSON and a numpy archive that loads
without running code (``allow_pickle=False``) and flies with numpy alone.

``DIR/policy.json`` holds the architecture and free metadata; ``DIR/policy.npz`` the arrays:
``obs_mean`` / ``obs_std`` (dim,), and per member j and linear layer l ``m{j}.w{l}`` (out, in)
and ``m{j}.b{l}`` (out,). The action of one observation is: x = (obs - obs_mean) / obs_std,
clipped to +-``observation_clip`` when set; per member h = act(W h + b) through the hidden
layers and a linear last layer of 3 outputs; the members' mean; then ``"clip"`` to [-1, 1] or
``"tanh"``. An ensemble of members normalised differently (each clipping its own normalised
observation) holds ``m{j}.obs_mean`` / ``m{j}.obs_std`` (dim,) for every member j, which
replace the file's statistics for that member. Every trainer of the project that exports a
torch policy writes this format.

A file with ``"agents": N`` in its header holds one network per UAV (IPPO): every weight has a
leading N axis (``m{j}.w{l}`` (N, out, in), ``m{j}.b{l}`` (N, out)) and UAV i flies network i.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import observation_size
from uav_formation_env.policies.protocol import PolicyBase

__all__ = [
    "ACTIONS",
    "ACTIVATIONS",
    "FORMAT",
    "VERSION",
    "FilePolicy",
    "is_policy_dir",
    "load_policy_file",
    "merge_members",
    "save_policy_file",
]

FORMAT = "uav-formation-policy"
VERSION = 1
JSON_NAME, ARRAYS_NAME = "policy.json", "policy.npz"
ACTIONS = ("clip", "tanh")
OBSERVATIONS = ("full", "local")
_ERF = np.frompyfunc(math.erf, 1, 1)


def _gelu(x: np.ndarray) -> np.ndarray:
    """Exact (erf) GELU, torch's default."""
    return 0.5 * x * (1.0 + _ERF(x / math.sqrt(2.0)).astype(x.dtype))


ACTIVATIONS = {
    "tanh": np.tanh,
    "relu": lambda x: np.maximum(x, 0.0),
    "elu": lambda x: np.where(x > 0.0, x, np.expm1(np.minimum(x, 0.0))),
    "gelu": _gelu,
    "silu": lambda x: x / (1.0 + np.exp(-x)),
}


def is_policy_dir(path: str | Path) -> bool:
    """Whether ``path`` is a directory holding ``policy.json``."""
    return Path(path).is_dir() and (Path(path) / JSON_NAME).is_file()


def save_policy_file(
    directory: str | Path,
    members: Sequence[Sequence[tuple[np.ndarray, np.ndarray]]],
    obs_mean: np.ndarray,
    obs_std: np.ndarray,
    *,
    observation: str,
    activation: str,
    observation_clip: float | None = None,
    action: str = "clip",
    metadata: Mapping[str, Any] | None = None,
    member_statistics: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
) -> Path:
    """Write ``DIR/policy.json`` and ``DIR/policy.npz`` (float32 arrays); return ``directory``.

    Args:
        directory: created if missing; existing ``policy.*`` files are replaced.
        members: per member, its linear layers as ``(W (out, in), b (out,))``, the last with 3
            outputs; every member has the same number of layers.
        obs_mean, obs_std: (dim,) observation statistics (std > 0).
        observation: ``"full"`` or ``"local"``, the observation kind the network reads.
        activation: a key of :data:`ACTIVATIONS` (hidden layers).
        observation_clip: clip of the normalised observation (None: none).
        action: ``"clip"`` or ``"tanh"`` (last layer's output -> [-1, 1]).
        metadata: free JSON-serialisable fields (scenario, algorithm, frames, ...).
        member_statistics: per member, its own ``(obs_mean, obs_std)`` (None: the file's).
    """
    arrays = _statistics("obs", obs_mean, obs_std)
    mean = arrays["obs_mean"]
    layers = _check_members(members, mean.shape[0], arrays)
    if member_statistics is not None:
        if len(member_statistics) != len(members):
            raise ValueError(
                f"member_statistics: give one (mean, std) per member ({len(members)}), "
                f"got {len(member_statistics)}"
            )
        for j, (member_mean, member_std) in enumerate(member_statistics):
            own = _statistics(f"m{j}.obs", member_mean, member_std)
            if own[f"m{j}.obs_mean"].shape != mean.shape:
                raise ValueError(f"member_statistics: member {j}'s are not ({mean.shape[0]},)")
            arrays.update(own)
    header = {
        "format": FORMAT,
        "version": VERSION,
        "observation_dim": int(mean.shape[0]),
        "observation": observation,
        "activation": activation,
        "members": len(members),
        "layers": layers,
        "observation_clip": None if observation_clip is None else float(observation_clip),
        "action": action,
        **dict(metadata or {}),
    }
    _check_header(header, "save_policy_file")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    with open(directory / ARRAYS_NAME, "wb") as stream:
        np.savez(stream, **arrays)
    (directory / JSON_NAME).write_text(json.dumps(header, indent=2, default=_plain) + "\n")
    return directory


def _statistics(prefix: str, mean: np.ndarray, std: np.ndarray) -> dict[str, np.ndarray]:
    """``{prefix_mean, prefix_std}`` as float32 (dim,) vectors, or a ValueError naming them."""
    mean, std = np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64)
    if mean.ndim != 1 or std.shape != mean.shape:
        raise ValueError(
            f"{prefix}_mean and {prefix}_std: need (dim,) vectors, got {mean.shape}, {std.shape}"
        )
    if not np.all(std > 0.0):
        raise ValueError(f"{prefix}_std: every entry must be > 0")
    return {f"{prefix}_mean": mean.astype(np.float32), f"{prefix}_std": std.astype(np.float32)}


def _plain(value: Any) -> Any:
    """JSON fallback for numpy scalars and arrays in metadata."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(f"metadata: {type(value).__name__} is not JSON-serialisable")


def _check_members(members: Sequence, dim: int, arrays: dict[str, np.ndarray]) -> int:
    """Validate the members' layers and put them into ``arrays``; the number of layers."""
    if len(members) < 1:
        raise ValueError("members: give at least one network")
    depth = len(members[0])
    for j, layers in enumerate(members):
        if len(layers) != depth or depth < 1:
            raise ValueError(f"members: member {j} has {len(layers)} layers, member 0 {depth}")
        width = dim
        for index, (weight, bias) in enumerate(layers):
            weight, bias = np.asarray(weight), np.asarray(bias)
            if weight.ndim != 2 or weight.shape[1] != width or bias.shape != weight.shape[:1]:
                raise ValueError(
                    f"members: m{j}.w{index} is {weight.shape} with bias {bias.shape}, "
                    f"expected (out, {width}) and (out,)"
                )
            arrays[f"m{j}.w{index}"] = weight.astype(np.float32)
            arrays[f"m{j}.b{index}"] = bias.astype(np.float32)
            width = weight.shape[0]
        if width != 3:
            raise ValueError(f"members: member {j}'s last layer has {width} outputs, expected 3")
    return depth


def _check_header(header: Mapping[str, Any], where: str) -> None:
    """One-line ``ValueError`` naming the first bad field of a ``policy.json``."""
    checks = (
        ("format", header.get("format") == FORMAT, f"must be {FORMAT!r}"),
        ("version", header.get("version") == VERSION, f"must be {VERSION}"),
        ("observation", header.get("observation") in OBSERVATIONS, f"one of {OBSERVATIONS}"),
        ("activation", header.get("activation") in ACTIVATIONS, f"one of {sorted(ACTIVATIONS)}"),
        ("action", header.get("action") in ACTIONS, f"one of {ACTIONS}"),
        ("members", _positive_int(header.get("members")), "a positive integer"),
        ("layers", _positive_int(header.get("layers")), "a positive integer"),
        ("observation_dim", _positive_int(header.get("observation_dim")), "a positive integer"),
    )
    for name, ok, expected in checks:
        if not ok:
            raise ValueError(f"{where}: {name} is {header.get(name)!r}, expected {expected}")
    clip = header.get("observation_clip")
    if clip is not None and not (isinstance(clip, int | float) and clip > 0):
        raise ValueError(f"{where}: observation_clip is {clip!r}, expected null or a number > 0")
    agents = header.get("agents")
    if agents is not None and not _positive_int(agents):
        raise ValueError(f"{where}: agents is {agents!r}, expected null or a positive integer")


def _positive_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


Layers = list[tuple[np.ndarray, np.ndarray]]


def merge_members(
    parts: Sequence[tuple[Sequence[tuple[np.ndarray, np.ndarray]], np.ndarray, np.ndarray]],
) -> tuple[list[Layers], np.ndarray, np.ndarray]:
    """Networks with observation statistics of their own as the members of one file.

    The file's statistics ``m``, ``s`` are, per slot, those of the member with the smallest std
    there; member j's first layer absorbs the difference, since
    (x - m_j) / s_j = (x - m) / s * (s / s_j) + (m - m_j) / s_j. (With the smallest std no
    weight grows and no large terms cancel in the float32 arrays of the file.)

    Args:
        parts: per network, (its layers ``[(W, b), ...]``, ``obs_mean`` (dim,), ``obs_std``
            (dim,)).

    Returns:
        (members, obs_mean, obs_std), float64, for :func:`save_policy_file`.
    """
    if not parts:
        raise ValueError("parts: give at least one network")
    means = np.stack([np.asarray(mean, dtype=np.float64) for _, mean, _ in parts])
    stds = np.stack([np.asarray(std, dtype=np.float64) for _, _, std in parts])
    pick = np.argmin(stds, axis=0)[None]
    mean = np.take_along_axis(means, pick, axis=0)[0]
    std = np.take_along_axis(stds, pick, axis=0)[0]
    members = []
    for (layers, _, _), m_j, s_j in zip(parts, means, stds):
        weight, bias = (np.asarray(a, dtype=np.float64) for a in layers[0])
        first = (weight * (std / s_j), bias + weight @ ((mean - m_j) / s_j))
        rest = [(np.asarray(w, np.float64), np.asarray(b, np.float64)) for w, b in layers[1:]]
        members.append([first, *rest])
    return members, mean, std


def load_policy_file(directory: str | Path) -> FilePolicy:
    """The policy saved in ``directory`` (``FileNotFoundError`` / one-line ``ValueError`` naming
    the file when it is missing or malformed)."""
    return FilePolicy(directory)


class FilePolicy(PolicyBase):
    """A policy of the v1 file format, shared by every UAV: ``act_batch`` maps (B, N, dim)
    observations to (B, N, 3) actions in [-1, 1], in float64 numpy.

    Attributes:
        header: the parsed ``policy.json`` (architecture and metadata).
        observation_size: dim, the width of one observation.
    """

    def __init__(self, directory: str | Path) -> None:
        self.path = Path(directory)
        json_path, arrays_path = self.path / JSON_NAME, self.path / ARRAYS_NAME
        for file in (json_path, arrays_path):
            if not file.is_file():
                raise FileNotFoundError(f"policy file not found: {str(file)!r}")
        try:
            header = json.loads(json_path.read_text())
        except (ValueError, UnicodeDecodeError) as error:
            raise ValueError(f"{json_path}: not valid JSON ({error})") from None
        if not isinstance(header, dict):
            raise ValueError(f"{json_path}: expected a JSON object")
        _check_header(header, str(json_path))
        self.header = header
        try:
            with np.load(arrays_path, allow_pickle=False) as archive:
                arrays = {name: np.asarray(archive[name], dtype=np.float64) for name in archive}
        except Exception as error:  # noqa: BLE001 - zipfile, OSError, ValueError on bad files
            raise ValueError(f"{arrays_path}: not a readable numpy archive ({error})") from None
        self.observation_size = int(header["observation_dim"])
        self.agents: int | None = header.get("agents")
        self._mean, self._std = self._take(arrays, "obs_mean"), self._take(arrays, "obs_std")
        self._members = [
            [
                (self._take(arrays, f"m{j}.w{index}"), self._take(arrays, f"m{j}.b{index}"))
                for index in range(header["layers"])
            ]
            for j in range(header["members"])
        ]
        try:
            for networks in self._per_agent(self._members):
                _check_members(networks, self.observation_size, {})
        except ValueError as error:
            raise ValueError(f"{arrays_path}: {error}") from None
        if self._mean.shape != (self.observation_size,) or self._std.shape != self._mean.shape:
            raise ValueError(
                f"{arrays_path}: obs_mean / obs_std must be ({self.observation_size},)"
            )
        self._statistics = self._member_statistics(arrays, header["members"])
        self._activation = ACTIVATIONS[header["activation"]]

    def _member_statistics(
        self, arrays: Mapping[str, np.ndarray], members: int
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per member, the (obs_mean, obs_std) it normalises with: its own ``m{j}.obs_*`` if
        the file has them (for every member of a shared policy), else the file's."""
        own = [f"m{j}.obs_mean" in arrays for j in range(members)]
        if not any(own):
            return [(self._mean, self._std)] * members
        where = self.path / ARRAYS_NAME
        if not all(own) or self.agents is not None:
            raise ValueError(
                f"{where}: member statistics need m{{j}}.obs_mean and m{{j}}.obs_std for every "
                "member of a shared policy"
            )
        statistics = [
            (self._take(arrays, f"m{j}.obs_mean"), self._take(arrays, f"m{j}.obs_std"))
            for j in range(members)
        ]
        if any(m.shape != self._mean.shape or sd.shape != m.shape for m, sd in statistics):
            raise ValueError(f"{where}: member statistics must be ({self.observation_size},)")
        return statistics

    def _take(self, arrays: Mapping[str, np.ndarray], name: str) -> np.ndarray:
        if name not in arrays:
            raise ValueError(f"{self.path / ARRAYS_NAME}: missing array {name!r}")
        return arrays[name]

    def _per_agent(self, members: list[Layers]) -> list[list[Layers]]:
        """The members as one list per UAV's networks ([members] for a shared file); a
        ``ValueError`` when an array lacks the leading ``agents`` axis."""
        if self.agents is None:
            return [members]
        for j, layers in enumerate(members):
            for index, (weight, bias) in enumerate(layers):
                if (
                    weight.ndim != 3
                    or weight.shape[0] != self.agents
                    or bias.shape[:1] != (self.agents,)
                ):
                    raise ValueError(
                        f"m{j}.w{index} is {weight.shape} with bias {bias.shape}, expected a "
                        f"leading axis of agents = {self.agents}"
                    )
        return [
            [[(weight[a], bias[a]) for weight, bias in layers] for layers in members]
            for a in range(self.agents)
        ]

    def _shared_only(self, what: str) -> None:
        if self.agents is not None:
            raise ValueError(
                f"the model {str(self.path)!r} has one network per UAV ({self.agents}); "
                f"{what} needs a shared policy: use act_batch on (B, {self.agents}, dim)"
            )

    def parts(self) -> list[tuple[Layers, np.ndarray, np.ndarray]]:
        """Per member, (its layers, obs_mean, obs_std): the input of :func:`merge_members`."""
        self._shared_only("merging into an ensemble")
        return [(layers, *stats) for layers, stats in zip(self._members, self._statistics)]

    def check_scenario(self, scenario: Scenario) -> None:
        """``ValueError`` naming both if the file cannot act on ``scenario``'s observations."""
        kind, expected = scenario.observation.kind, observation_size(scenario)
        if kind != self.header["observation"] or expected != self.observation_size:
            raise ValueError(
                f"the model {str(self.path)!r} reads {self.header['observation']} observations "
                f"of {self.observation_size} values, but scenario {scenario.name!r} "
                f"({scenario.n_uav} UAVs) gives {kind} observations of {expected}"
            )
        if self.agents is not None and scenario.n_uav != self.agents:
            raise ValueError(
                f"the model {str(self.path)!r} has one network per UAV for {self.agents} UAVs, "
                f"but scenario {scenario.name!r} has {scenario.n_uav}"
            )

    def _mean_output(self, obs: np.ndarray) -> np.ndarray:
        """(..., dim) observations -> (..., 3) the members' mean output; with ``agents``, obs is
        (B, agents, dim) and UAV i's row goes through network i."""
        obs = np.asarray(obs, dtype=np.float64)
        clip = self.header["observation_clip"]
        total = np.zeros((*obs.shape[:-1], 3))
        normalised: dict[int, np.ndarray] = {}  # by statistics: one normalisation when shared
        for layers, (mean, std) in zip(self._members, self._statistics):
            if id(mean) not in normalised:
                x = (obs - mean) / std
                normalised[id(mean)] = x if clip is None else np.clip(x, -clip, clip)
            h = normalised[id(mean)]
            for index, (weight, bias) in enumerate(layers):
                h = _linear(h, weight, bias)
                if index < len(layers) - 1:
                    h = self._activation(h)
            total += h
        return total / len(self._members)

    def _squash(self, output: np.ndarray) -> np.ndarray:
        return np.tanh(output) if self.header["action"] == "tanh" else np.clip(output, -1.0, 1.0)

    def outputs(self, flat: np.ndarray) -> np.ndarray:
        """(M, dim) observations -> (M, 3) the members' mean output, before ``action``."""
        self._shared_only("outputs of (M, dim) observations")
        return self._mean_output(flat)

    def act_flat(self, flat: np.ndarray) -> np.ndarray:
        """(M, dim) observations -> (M, 3) actions in [-1, 1]."""
        return self._squash(self.outputs(flat))

    def act_batch(self, obs: np.ndarray) -> np.ndarray:
        """(B, N, dim) observations -> (B, N, 3) actions."""
        obs = np.asarray(obs)
        if obs.ndim != 3 or obs.shape[-1] != self.observation_size:
            raise ValueError(
                f"the model {str(self.path)!r} takes (B, N, {self.observation_size}) "
                f"observations, got {obs.shape}"
            )
        batch, n, dim = obs.shape
        if self.agents is not None:
            if n != self.agents:
                raise ValueError(
                    f"the model {str(self.path)!r} has one network per UAV for {self.agents} "
                    f"UAVs, got observations of {n}"
                )
            return self._squash(self._mean_output(obs))
        return self.act_flat(obs.reshape(batch * n, dim)).reshape(batch, n, 3)


def _linear(h: np.ndarray, weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """One layer: (M, in) @ (out, in)^T, or per agent (B, N, in) with (N, out, in) weights."""
    if weight.ndim == 3:
        return np.einsum("bni,noi->bno", h, weight) + bias
    return h @ weight.T + bias
