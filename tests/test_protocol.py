"""The runner's policy protocol: defaults for what a policy does not declare, no probing."""

from __future__ import annotations

import inspect

import numpy as np

import uav_formation_env.evaluation.runner as runner
from uav_formation_env.config_io import load_scenario, resolve_scenario
from uav_formation_env.evaluation import run_episodes
from uav_formation_env.policies.protocol import BatchPolicy, PolicyBase, as_batch_policy
from uav_formation_env.policies.registry import MODELS_DIR, make_policy


class Bare:
    """Only act_batch: zero actions."""

    def act_batch(self, obs):
        return np.zeros((*obs.shape[:2], 3))


class Seeded(Bare):
    def __init__(self) -> None:
        self.calls = []

    def reset(self, batch_size, seeds=None):
        self.calls.append((batch_size, list(seeds)))


def test_a_bare_policy_gets_the_defaults() -> None:
    policy = as_batch_policy(Bare())
    assert isinstance(policy, BatchPolicy)
    assert (policy.needs_neighbour_index, policy.accepts_tensors, policy.plans) == (
        False,
        False,
        None,
    )
    assert policy.records() is None
    policy.reset(3, seeds=[0, 1, 2])  # nothing to reset
    seeded = Seeded()
    as_batch_policy(seeded).reset(2, seeds=[4, 5])
    assert seeded.calls == [(2, [4, 5])]


def test_the_runner_flies_a_bare_policy_and_resets_a_seeded_one() -> None:
    scenario = resolve_scenario("paper")
    seeded = Seeded()
    batch = run_episodes(scenario, seeded, [3, 4], duration=1.0)
    assert batch.triggered is None and seeded.calls == [(2, [3, 4])]
    assert run_episodes(scenario, Bare(), [0], duration=1.0).z.shape[1] == 1


def test_every_policy_of_the_package_declares_the_protocol() -> None:
    paper = resolve_scenario("paper")
    student = load_scenario(MODELS_DIR / "random_fields_dagger" / "scenario.yaml")
    for name, scenario in (("lfpio", paper), ("heuristic", paper), ("random", paper)):
        policy = make_policy(name, scenario)
        assert isinstance(policy, PolicyBase) and as_batch_policy(policy) is policy
    assert isinstance(make_policy("random_fields_dagger", student), PolicyBase)
    assert "hasattr" not in inspect.getsource(runner)
