"""Optional dependencies: import them at the point of use, or say which extra to install."""

from __future__ import annotations

import importlib
from types import ModuleType

EXTRAS = {
    "stable_baselines3": "rl",
    "torch": "rl",
    "numba": "fast",
    "imageio": "video",
    "ray": "ray",
    "ray.rllib": "rllib",
    "imageio_ffmpeg": "video",
    "torchrl": "torchrl",
}


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message names the extra that brings it."""


def require(module: str, purpose: str) -> ModuleType:
    """Import ``module`` or raise :class:`MissingExtraError` naming the extra to install.

    Args:
        module: the import name (``"stable_baselines3"``).
        purpose: what needs it, for the message (``"vec_env"``).
    """
    try:
        return importlib.import_module(module)
    except ImportError as error:
        extra = EXTRAS.get(module, EXTRAS.get(module.split(".")[0], "rl"))
        raise MissingExtraError(
            f"{purpose} needs {module.split('.')[0]}, from the [{extra}] extra: "
            f"pip install 'uav-formation-env[{extra}]' ({error})"
        ) from error
