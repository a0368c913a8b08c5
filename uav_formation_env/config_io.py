"""Scenario <-> dict / YAML, strict about keys, and the registry of named scenarios.

``scenario_from_dict`` rejects unknown keys by their dotted path (``observer.lamda2`` is an
error, not a silently ignored typo) and re-runs every validation rule of
:mod:`uav_formation_env.config`.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Union

import yaml

from uav_formation_env.config import REWARD_CHOICES, TRAINING_PRESET, FormationConfig, Scenario
from uav_formation_env.scenarios import (
    hold_scenario,
    make_scenario,
    random_fields_scenario,
    random_routes_scenario,
    random_swarm_scenario,
    swarm_scenario,
    track_scenario,
    windy_scenario,
)

_T = typing.TypeVar("_T")


_SCALARS = (int, float, bool, str, type(None))
# libyaml's safe loader and dumper where PyYAML has them: the pure-Python ones took 29 s for the
# 10^6 adjacency entries of N = 1000
_SAFE_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_SAFE_DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)


class _UniqueKeyLoader(_SAFE_LOADER):  # type: ignore[misc, valid-type]
    """The safe loader, refusing a mapping that repeats a key (YAML says keys are unique; PyYAML
    keeps the last silently)."""

    def construct_mapping(self, node, deep=False):  # noqa: ANN001, ANN201 - PyYAML's signature
        seen = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=deep)
            if key in seen:
                raise yaml.constructor.ConstructorError(
                    None, None, f"duplicate key {key!r}", key_node.start_mark
                )
            seen.add(key)
        return super().construct_mapping(node, deep=deep)


def to_dict(obj: Any) -> Any:
    """Plain-data (dict/list/float) form of a config dataclass, fit for YAML or JSON."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_dict(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple | list):
        # a row of scalars in one step: an adjacency of N = 1000 has 10^6 entries
        if all(type(item) in _SCALARS for item in obj):
            return list(obj)
        return [to_dict(item) for item in obj]
    return obj


def _convert(value: Any, hint: Any, path: str) -> Any:
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        return _build(hint, value, path)
    if origin is tuple:
        if not isinstance(value, list | tuple):
            raise ValueError(f"invalid scenario field '{path}': expected a list, got {value!r}")
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            scalar = _SCALAR_CHECKS.get(args[0])
            if scalar is not None and all(scalar(item) for item in value):
                # a row of valid scalars at once (10^6 adjacency entries for N = 1000); any bad
                # entry takes the item-by-item path below, which names it
                return tuple(float(item) for item in value) if args[0] is float else tuple(value)
            return tuple(_convert(item, args[0], f"{path}[{k}]") for k, item in enumerate(value))
        if len(value) != len(args):
            raise ValueError(
                f"invalid scenario field '{path}': expected {len(args)} entries, got {len(value)}"
            )
        return tuple(_convert(item, arg, path) for item, arg in zip(value, args))
    if origin in (Union, types.UnionType):
        # "X | None" (the optional sections and ranges of Scenario.scene): None stays None, any
        # other value is converted (and checked) as an X, so a nested mapping becomes its
        # dataclass and its unknown keys are named
        args = [arg for arg in typing.get_args(hint) if arg is not type(None)]
        if value is None and len(args) < len(typing.get_args(hint)):
            return None
        if len(args) == 1:
            return _convert(value, args[0], path)
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise ValueError(f"invalid scenario field '{path}': expected true/false, got {value!r}")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ValueError(f"invalid scenario field '{path}': expected an integer, got {value!r}")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ValueError(f"invalid scenario field '{path}': expected a number, got {value!r}")
        return float(value)
    if hint is str:
        if not isinstance(value, str):
            raise ValueError(f"invalid scenario field '{path}': expected a string, got {value!r}")
        return value
    return value


_SCALAR_CHECKS: dict[Any, Any] = {
    int: lambda x: type(x) is int,
    float: lambda x: type(x) in (int, float),
}


# save_scenario writes a graph of at least this many UAVs as an edge list (the dense N x N matrix
# of N = 1000 took 7.4 s to write and 9.1 s to read; its 4-nearest edge list a fraction of that)
SPARSE_GRAPH_MIN_UAVS = 50


def _dense_adjacency(data: Mapping[str, Any], path: str) -> Mapping[str, Any]:
    """A formation mapping whose ``adjacency`` is ``{edges: [[receiver, sender], ...]}`` with the
    edge list turned into the dense 0/1 matrix (N = the number of offsets); else unchanged."""
    edges_form = data.get("adjacency")
    if not isinstance(edges_form, Mapping):
        return data
    where = f"{path + '.' if path else ''}adjacency"
    unknown = sorted(set(edges_form) - {"edges"}, key=str)
    if unknown or "edges" not in edges_form:
        named = ", ".join(f"'{where}.{key}'" for key in unknown) or f"'{where}.edges' missing"
        raise ValueError(
            f"invalid scenario field {named}: a sparse graph is {{edges: [[receiver, sender], "
            "...]}}"
        )
    n = len(data.get("offsets", FormationConfig().offsets))
    matrix = [[0] * n for _ in range(n)]
    edges = edges_form["edges"]
    if not isinstance(edges, list | tuple):
        raise ValueError(f"invalid scenario field '{where}.edges': expected a list of pairs")
    for k, edge in enumerate(edges):
        valid = (
            isinstance(edge, list | tuple)
            and len(edge) == 2
            and all(type(i) is int and 0 <= i < n for i in edge)
        )
        if not valid:
            raise ValueError(
                f"invalid scenario field '{where}.edges[{k}]': expected [receiver, sender], "
                f"UAV indices in 0..{n - 1}, got {edge!r}"
            )
        matrix[edge[0]][edge[1]] = 1
    return {**data, "adjacency": matrix}


def _sparse_adjacency(formation: dict[str, Any]) -> dict[str, Any]:
    """The inverse of :func:`_dense_adjacency` for large formations (see
    :data:`SPARSE_GRAPH_MIN_UAVS`)."""
    matrix = formation["adjacency"]
    if len(matrix) < SPARSE_GRAPH_MIN_UAVS:
        return formation
    edges = [[i, j] for i, row in enumerate(matrix) for j, h in enumerate(row) if h]
    return {**formation, "adjacency": {"edges": edges}}


def _build(cls: type[_T], data: Any, path: str) -> _T:
    if isinstance(data, cls):
        return data
    if not isinstance(data, Mapping):
        where = path or "scenario"
        raise ValueError(f"invalid scenario field '{where}': expected a mapping, got {data!r}")
    if cls is FormationConfig:
        data = _dense_adjacency(data, path)
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - names, key=str)
    if unknown:
        dotted = ", ".join(f"'{path + '.' if path else ''}{key}'" for key in unknown)
        raise ValueError(f"unknown scenario key {dotted}; allowed here: {sorted(names)}")
    required = [
        f.name
        for f in dataclasses.fields(cls)  # type: ignore[arg-type]
        if f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
        and f.name not in data
    ]
    if required:
        dotted = ", ".join(f"'{path + '.' if path else ''}{key}'" for key in required)
        raise ValueError(f"missing scenario key {dotted} (required)")
    kwargs = {
        key: _convert(value, hints[key], f"{path + '.' if path else ''}{key}")
        for key, value in data.items()
    }
    return cls(**kwargs)


def scenario_from_dict(data: Mapping[str, Any]) -> Scenario:
    """Build a validated scenario; missing keys take the paper's defaults."""
    return _build(Scenario, data, "")


def _merge(base: dict[str, Any], patch: Mapping[str, Any], path: str) -> dict[str, Any]:
    merged = dict(base)
    for key, value in patch.items():
        dotted = f"{path}.{key}" if path else key
        if key not in merged:
            raise ValueError(f"unknown scenario key '{dotted}'; allowed here: {sorted(merged)}")
        if isinstance(value, Mapping) and isinstance(merged[key], dict):
            merged[key] = _merge(merged[key], value, dotted)
        else:
            merged[key] = to_dict(value)
    return merged


def with_overrides(scenario: Scenario, overrides: Mapping[str, Any]) -> Scenario:
    """A copy of ``scenario`` with single fields changed, validated like a new scenario.

    Keys may be nested mappings (``{"observer": {"enabled": False}}``), dotted paths
    (``"observer.enabled"``) or double-underscore paths (``observer__enabled``, for keyword use).
    """
    patch: dict[str, Any] = {}
    for key, value in overrides.items():
        parts = key.replace("__", ".").split(".")
        node = patch
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        node[parts[-1]] = value
    return scenario_from_dict(_merge(to_dict(scenario), patch, ""))


def load_scenario(path: str | Path) -> Scenario:
    """Read a scenario from a YAML file (missing keys default to the paper's values).

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is not valid YAML (with the line and column), or not a valid
            scenario (naming the key).
    """
    with open(path, encoding="utf-8") as stream:
        try:
            data = yaml.load(stream, Loader=_UniqueKeyLoader)
        except yaml.YAMLError as error:
            mark = getattr(error, "problem_mark", None)
            where = "" if mark is None else f" at line {mark.line + 1}, column {mark.column + 1}"
            problem = getattr(error, "problem", None) or str(error).splitlines()[0]
            raise ValueError(f"{path}: not valid YAML{where}: {problem}") from None
    return scenario_from_dict({} if data is None else data)


def save_scenario(scenario: Scenario, path: str | Path) -> None:
    """Write every field of a scenario to a YAML file (the communication graph of a formation of
    :data:`SPARSE_GRAPH_MIN_UAVS` or more as ``adjacency: {edges: [[receiver, sender], ...]}``)."""
    data = to_dict(scenario)
    data["formation"] = _sparse_adjacency(data["formation"])
    with open(path, "w", encoding="utf-8") as stream:
        yaml.dump(data, stream, Dumper=_SAFE_DUMPER, sort_keys=False)


def paper_scenario() -> Scenario:
    """The paper's scenario (docs/model.md §8): 5 UAVs, V formation, two obstacles, 200 s."""
    return Scenario()


SCENARIOS: dict[str, typing.Callable[[], Scenario]] = {
    "paper": paper_scenario,
    # the task ladder's lower rungs (uav_formation_env.tasks)
    "hold": hold_scenario,
    "track": track_scenario,
    "open_field": lambda: make_scenario(obstacles="none"),
    "windy": windy_scenario,
    "random_obstacles": lambda: make_scenario(obstacles="random", seed=0),
    "n3": lambda: make_scenario(n_uav=3),
    "n8": lambda: make_scenario(n_uav=8),
    # templates: a scene drawn per reset (uav_formation_env.scenes.draw_scene)
    "random_fields": random_fields_scenario,
    "random_routes": random_routes_scenario,
    "random_swarm": random_swarm_scenario,
    # large swarms, concrete
    "swarm_20": lambda: swarm_scenario(20),
    "swarm_50": lambda: swarm_scenario(50),
    "swarm_100": lambda: swarm_scenario(100),
}


def resolve_scenario(scenario: str | Path | Scenario | Mapping[str, Any] = "paper") -> Scenario:
    """A scenario object from a registered name, a YAML path, a mapping or a scenario."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, Mapping):
        return scenario_from_dict(scenario)
    if not isinstance(scenario, str | Path):
        raise TypeError(
            f"scenario must be a registered name {sorted(SCENARIOS)}, a YAML path, a mapping or "
            f"a Scenario, got {scenario!r} ({type(scenario).__name__})"
        )
    if isinstance(scenario, str) and scenario in SCENARIOS:
        return SCENARIOS[scenario]()
    path = Path(scenario)
    if path.suffix in (".yaml", ".yml"):
        if not path.is_file():
            raise ValueError(f"scenario file not found: {str(path)!r}")
        return load_scenario(path)
    raise ValueError(
        f"unknown scenario {str(scenario)!r}: expected one of {sorted(SCENARIOS)}, "
        "a path to an existing .yaml file, or a Scenario"
    )


def resolve_with_overrides(
    scenario: str | Path | Scenario | Mapping[str, Any], overrides: Mapping[str, Any]
) -> Scenario:
    """A scenario from a name / YAML path / mapping / object, with validated field overrides.

    The override ``reward="train"`` puts the scenario under the training preset
    (:data:`~uav_formation_env.config.TRAINING_PRESET`) before the others; ``reward="paper"``
    (or None) keeps the scenario's own reward, -J_i by default. ``max_cycles``, PettingZoo's
    name, stands for ``episode.max_cycles``.
    """
    overrides = dict(overrides)
    if "max_cycles" in overrides:
        overrides["episode.max_cycles"] = overrides.pop("max_cycles")
    reward = overrides.pop("reward", None)
    if reward not in REWARD_CHOICES:
        raise ValueError(f"reward must be one of {REWARD_CHOICES}, got {reward!r}")
    if reward == "train":
        overrides = {**TRAINING_PRESET, **overrides}
    resolved = resolve_scenario(scenario)
    return with_overrides(resolved, overrides) if overrides else resolved
