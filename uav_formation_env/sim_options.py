"""``SimOptions``: how a simulator holds and computes its arrays (the scenario says what it
simulates). One frozen value passed from every view and trainer down to
:class:`~uav_formation_env.sim.FormationSim`."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from uav_formation_env.core.array_api import backend_device

__all__ = ["BACKENDS", "NOISE_SOURCES", "SimOptions"]

BACKENDS = ("numpy", "torch")  # SimOptions.backend
NOISE_SOURCES = ("generator", "counter")  # SimOptions.noise


@dataclass(frozen=True)
class SimOptions:
    """The array library, device, compilation and noise source of a simulator.

    Attributes:
        backend: ``"numpy"`` or ``"torch"``, the library of the state (float64 on both).
        device: where a torch state lives (``"cpu"``, ``"cuda"``, ...; None: the CPU); numpy runs
            on ``"cpu"`` only.
        compile: the whole step through ``torch.compile``, as two graphs: the simulator's
            (:meth:`~uav_formation_env.sim.FormationSim._advance`: dynamics, disturbance,
            observer, topology, cost) and the episode layer's (observations, rewards, flags).
            torch only; the first step compiles; where compilation fails, one warning and the
            eager step (the same numbers to rounding).
        noise: the disturbance noise, ``"generator"`` (blocks from each copy's numpy generator,
            moved to the device: the paper reproduction's numbers) or ``"counter"`` (counter-based
            draws on the device, keyed by each copy's seed and counted by its step; a seed names
            the same scene and start either way, not the same noise).
    """

    backend: str = "numpy"
    device: Any = None
    compile: bool = False
    noise: str = "generator"

    def __post_init__(self) -> None:
        if self.backend not in BACKENDS:
            raise ValueError(f"backend must be one of {BACKENDS}, got {self.backend!r}")
        if self.noise not in NOISE_SOURCES:
            raise ValueError(f"noise must be one of {NOISE_SOURCES}, got {self.noise!r}")
        if not isinstance(self.compile, bool):
            raise ValueError(f"compile must be true or false, got {self.compile!r}")
        if self.compile and self.backend != "torch":
            raise ValueError(f"compile=True needs backend='torch' (got backend={self.backend!r})")
        backend_device(self.backend, self.device)  # a device the backend has (names it if not)

    def resolved_device(self) -> Any:
        """The device of the state: ``"cpu"`` for numpy, a ``torch.device`` for torch."""
        return backend_device(self.backend, self.device)
