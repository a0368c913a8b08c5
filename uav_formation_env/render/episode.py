"""One episode of a policy, rendered as an animated GIF or an MP4 (``uav-formation render``).

:func:`render_episode` flies one episode with the evaluation runner
(:func:`~uav_formation_env.evaluation.run_episodes`) and draws every ``every``-th state with
:class:`~uav_formation_env.render.TopViewRenderer`, frame ``k`` showing the state at time
``t[k · every]`` (the reset state first, the last state whenever ``every`` divides the number of
steps). The communication edges of a frame are the neighbour flags the UAVs observed at that
state, recorded from the observations the policy was given; the final state, which no policy
sees, keeps the previous state's edges. A GIF is written with Pillow
(:func:`~uav_formation_env.render.write_gif`), an MP4 with imageio-ffmpeg (H.264, the
``[video]`` extra).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from uav_formation_env.config import Scenario
from uav_formation_env.core.local_observation import decode_local_observations
from uav_formation_env.core.observation import decode_observations, others_index
from uav_formation_env.policies.protocol import as_batch_policy
from uav_formation_env.render.gif import write_gif
from uav_formation_env.render.top_view import TopViewRenderer

SUFFIXES = (".gif", ".mp4")
VIDEO_EXTRA_MESSAGE = "writing .mp4 needs the [video] extra: pip install 'uav-formation-env[video]'"
TRAIL_STEPS = 100  # trail length in control steps (20 s at the paper's 0.2 s), whatever `every`


def render_episode(
    scenario: Scenario,
    policy: Any,
    seed: int,
    out: str | Path,
    *,
    policy_name: str = "",
    fps: int = 10,
    every: int = 1,
    duration: float | None = None,
    progress: bool = True,
) -> Path:
    """Run one episode of ``policy`` and write its top-view animation to ``out``.

    Args:
        scenario: the scenario flown.
        policy: a policy for :func:`~uav_formation_env.evaluation.run_episodes`, built for
            ``scenario`` (e.g. by :func:`~uav_formation_env.evaluation.make_policy`).
        seed: the episode seed.
        out: ``.gif`` (Pillow) or ``.mp4`` (imageio-ffmpeg, the ``[video]`` extra); its folder
            is created.
        policy_name: label of the policy (progress bar).
        fps: frames per second of the animation (>= 1).
        every: draw every ``every``-th state (>= 1): ``len(range(0, T + 1, every))`` frames for
            T control steps.
        duration: episode length [s] (None: the scenario's). ``policy`` must have been built
            for the scenario with this duration, as the runner requires (the observations carry
            t / duration): ``make_policy(name, with_overrides(scenario, {"duration": d}))``.
        progress: tqdm bars over the simulated steps and over the frames.

    Returns:
        ``out`` as a :class:`~pathlib.Path`.

    Raises:
        ValueError: ``out`` has another suffix, ``fps < 1`` or ``every < 1``.
        RuntimeError: ``.mp4`` without imageio-ffmpeg installed (checked before the episode).
    """
    from uav_formation_env.evaluation import run_episodes

    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise ValueError(f"out must end in .gif or .mp4, got {str(out)!r}")
    if isinstance(fps, bool) or not isinstance(fps, (int, float, np.number)) or not fps >= 1:
        raise ValueError(f"fps must be >= 1 frame per second, got {fps!r}")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise ValueError(f"every must be an integer >= 1 (steps per frame), got {every!r}")
    every = int(every)
    ffmpeg = _imageio_ffmpeg() if suffix == ".mp4" else None

    recorder = AdjacencyRecorder(policy, scenario)
    batch = run_episodes(
        scenario,
        recorder,
        [seed],
        duration=duration,
        policy_name=policy_name,
        progress=progress,
        desc=f"simulate {policy_name or 'policy'} (seed {seed})",
    )
    frames = episode_frames(batch, recorder.adjacency(batch.n_steps + 1), every, progress)
    out.parent.mkdir(parents=True, exist_ok=True)
    if ffmpeg is None:
        write_gif(frames, out, fps=fps)
    else:
        _write_mp4(ffmpeg, frames, out, fps)
    return out


class AdjacencyRecorder:
    """Wraps a policy and records, at every call, copy 0's communication graph H.

    H is rebuilt from the neighbour flags in the observations: on the full layout ``h_ij`` of
    UAV i for every other UAV j (exact); on the local layout the in-neighbours in UAV i's slots
    (with the slot index that comes with the observation), so a UAV with more than k
    in-neighbours shows its k nearest. Every other attribute (``reset``, ``records``, ``plans``,
    ...) is the wrapped policy's, so the runner sees the policy itself.

    Args:
        policy: the wrapped policy.
        scenario: the scenario flown (N and the observation layout).
    """

    def __init__(self, policy: Any, scenario: Scenario) -> None:
        self.policy = policy
        self.n_uav = int(scenario.n_uav)
        self.observation = scenario.observation
        # the local layout's graph needs the slot index, whether the policy needs it or not
        self.needs_neighbour_index = self.observation.kind == "local"
        self._forward_index = as_batch_policy(policy).needs_neighbour_index
        self._adjacency: list[np.ndarray] = []

    def act_batch(self, obs: np.ndarray, neighbour_index: np.ndarray | None = None) -> np.ndarray:
        n = self.n_uav
        adjacency = np.zeros((n, n))
        if neighbour_index is None:
            flags = decode_observations(np.asarray(obs)[:1], n).neighbour[0]  # (N, N-1)
            adjacency[np.arange(n)[:, None], others_index(n)] = flags
        else:
            config = self.observation
            decoded = decode_local_observations(
                np.asarray(obs)[:1], config.neighbours, config.obstacles, config.nearest
            )
            linked = decoded.neighbour[0] & decoded.slot_present[0]  # (N, S)
            rows, slots = np.nonzero(linked)
            adjacency[rows, np.asarray(neighbour_index)[0][rows, slots]] = 1.0
        self._adjacency.append(adjacency)
        if self._forward_index:
            return self.policy.act_batch(obs, neighbour_index)
        return self.policy.act_batch(obs)

    def adjacency(self, length: int) -> np.ndarray:
        """(length, N, N) graphs of the calls so far, the last one repeated up to ``length``."""
        if not self._adjacency:
            raise RuntimeError("the policy was never called")
        graphs = self._adjacency[:length]
        graphs += [graphs[-1]] * (length - len(graphs))
        return np.stack(graphs)

    def __getattr__(self, name: str) -> Any:
        # only reached for attributes this wrapper does not have
        if name == "policy":
            raise AttributeError(name)
        return getattr(self.policy, name)


def episode_frames(
    batch: Any,
    adjacency: np.ndarray,
    every: int = 1,
    progress: bool = False,
    renderer: TopViewRenderer | None = None,
) -> Iterator[np.ndarray]:
    """Top-view frames of copy 0 of an episode batch, every ``every``-th state (a generator).

    Args:
        batch: an :class:`~uav_formation_env.evaluation.EpisodeBatch` (T steps).
        adjacency: (T + 1, N, N) communication graph of each state.
        every: steps between frames (>= 1).
        progress: a tqdm bar over the frames.
        renderer: the renderer (None: a 640 x 640 px :class:`TopViewRenderer` whose trails
            span :data:`TRAIL_STEPS` control steps).

    Yields:
        (H, W, 3) uint8 RGB images, ``len(range(0, T + 1, every))`` of them.
    """
    if renderer is None:
        trail = max(2, int(np.ceil(TRAIL_STEPS / every)))
        renderer = TopViewRenderer(batch.scenario, trail_length=trail)
    renderer.reset()
    indices = range(0, batch.n_steps + 1, every)
    bar = tqdm(indices, desc="render", unit="frame", disable=not progress)
    for k in bar:
        # collision[k - 1] is the flag after step k, i.e. at state k; none at the reset
        collided = batch.collision[k - 1, 0] if k > 0 else None
        yield renderer.frame(
            batch.z[k, 0, :, :3],
            batch.reference_velocity[k, 0],
            adjacency[k],
            batch.groups[k, 0],
            float(batch.t[k]),
            collisions=collided,
        )
    bar.close()


def _imageio_ffmpeg() -> Any:
    try:
        import imageio_ffmpeg
    except ImportError as error:
        raise RuntimeError(VIDEO_EXTRA_MESSAGE) from error
    return imageio_ffmpeg


def _write_mp4(ffmpeg: Any, frames: Iterator[np.ndarray], path: Path, fps: float) -> None:
    """H.264 MP4 (yuv420p, plays everywhere) through imageio-ffmpeg's frame writer."""
    writer = None
    try:
        for frame in frames:
            if writer is None:
                height, width = frame.shape[:2]
                writer = ffmpeg.write_frames(
                    str(path),
                    (width, height),
                    fps=fps,
                    codec="libx264",
                    pix_fmt_in="rgb24",
                    pix_fmt_out="yuv420p",
                    macro_block_size=2,  # yuv420p needs even sides; 640 x 640 needs no padding
                    quality=7,
                )
                writer.send(None)  # start ffmpeg
            writer.send(np.ascontiguousarray(frame))
    finally:
        if writer is not None:
            writer.close()
