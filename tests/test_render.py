"""TopViewRenderer, write_gif and render_episode: frame format, content, trails, edges,
determinism, GIF output, one policy's episode as a GIF or MP4."""

from __future__ import annotations

import dataclasses
import re
import sys

import numpy as np
import pytest
from matplotlib.colors import to_rgb
from PIL import Image, ImageSequence

from uav_formation_env.config import Scenario
from uav_formation_env.config_io import with_overrides
from uav_formation_env.episode import observations_of
from uav_formation_env.evaluation import make_policy, run_episodes
from uav_formation_env.render import (
    COLLISION_COLOR,
    OBSTACLE_COLOR,
    TopViewRenderer,
    group_edges,
    render_episode,
    write_gif,
)
from uav_formation_env.render.episode import (
    VIDEO_EXTRA_MESSAGE,
    AdjacencyRecorder,
    episode_frames,
)
from uav_formation_env.sim import FormationSim

SCENARIO = Scenario()  # paper: 5 UAVs, obstacles at (300, 0) and (1050, 400), radius 30 m
N = SCENARIO.n_uav
OFFSETS = np.asarray(SCENARIO.formation.offsets)[:, :3]
ADJACENCY = np.asarray(SCENARIO.formation.adjacency, dtype=float)
VELOCITY = np.tile([20.0, 0.0, 0.0], (N, 1))
ONE_GROUP = np.zeros(N, dtype=np.int64)


def rgb255(color: str) -> np.ndarray:
    return np.round(np.asarray(to_rgb(color)) * 255).astype(np.uint8)


def count_color(image: np.ndarray, color: str) -> int:
    return int((image == rgb255(color)).all(axis=-1).sum())


def draw(renderer: TopViewRenderer, at=(0.0, 0.0), adjacency=ADJACENCY, groups=ONE_GROUP, **kw):
    positions = OFFSETS + np.array([at[0], at[1], 0.0])
    return renderer.frame(positions, VELOCITY, adjacency, groups, kw.pop("t", 1.0), **kw)


@pytest.mark.parametrize("size", [(640, 640), (320, 240), (333, 517)])
@pytest.mark.parametrize("show_ticks", [False, True])
def test_frame_shape_dtype(size, show_ticks):
    width, height = size
    image = draw(TopViewRenderer(SCENARIO, width=width, height=height, show_ticks=show_ticks))
    assert image.shape == (height, width, 3)
    assert image.dtype == np.uint8
    assert image.flags.c_contiguous


def test_uavs_are_labelled_from_one_as_in_every_figure():
    renderer = TopViewRenderer(SCENARIO, 320, 320)
    draw(renderer)
    assert [label.get_text() for label in renderer._labels] == ["1", "2", "3", "4", "5"]


def test_frame_is_not_blank():
    image = draw(TopViewRenderer(SCENARIO, 320, 320))
    colours = np.unique(image.reshape(-1, 3), axis=0)
    assert len(colours) > 50
    assert (image == 255).all(axis=-1).mean() > 0.5  # mostly background


def test_obstacle_drawn_when_in_view_and_not_when_far():
    renderer = TopViewRenderer(SCENARIO)
    image = draw(renderer, at=(215.0, 0.0))  # swarm just before the obstacle at (300, 0)
    row, col = np.round(renderer.data_to_pixel([[300.0, 0.0]])[0]).astype(int)
    assert 0 <= row < renderer.height and 0 <= col < renderer.width
    assert np.array_equal(image[row, col], rgb255(OBSTACLE_COLOR))
    # filled disc: about pi r^2 pixels at 640 px / 300 m
    px_per_m = renderer.width / renderer.view_span
    area = np.pi * (30.0 * px_per_m) ** 2
    assert 0.8 * area < count_color(image, OBSTACLE_COLOR) < 1.1 * area

    # dashed safety circle at R_s = 40 m: partly, not fully, inked
    angles = np.linspace(0.0, 2 * np.pi, 720, endpoint=False)
    ring = np.stack([300.0 + 40.0 * np.cos(angles), 40.0 * np.sin(angles)], axis=1)
    rows, cols = np.round(renderer.data_to_pixel(ring)).astype(int).T
    inked = (image[rows, cols] < 235).any(axis=-1).mean()
    assert 0.3 < inked < 0.9
    inside_margin = 300.0 + 35.0 * np.cos(angles), 35.0 * np.sin(angles)
    rows, cols = np.round(renderer.data_to_pixel(np.stack(inside_margin, axis=1))).astype(int).T
    assert (image[rows, cols] > 200).all(axis=-1).mean() > 0.9  # between disc and circle: empty

    far = draw(TopViewRenderer(SCENARIO), at=(-2000.0, -2000.0))
    assert count_color(far, OBSTACLE_COLOR) == 0


def test_trails_grow_then_are_capped_and_reset_clears():
    renderer = TopViewRenderer(SCENARIO, 200, 200, trail_length=4)
    assert renderer.trail.shape == (0, N, 3)
    for k in range(7):
        draw(renderer, at=(5.0 * k, 0.0))
        assert renderer.trail.shape == (min(k + 1, 4), N, 3)
    np.testing.assert_allclose(renderer.trail[:, 0, 0], [15.0, 20.0, 25.0, 30.0])  # oldest first
    renderer.reset()
    assert renderer.trail.shape == (0, N, 3)


def test_trails_are_drawn():
    with_trail = TopViewRenderer(SCENARIO, 320, 320, trail_length=50)
    for k in range(20):
        image = draw(with_trail, at=(5.0 * k, 0.0), t=2.0)
    fresh = draw(TopViewRenderer(SCENARIO, 320, 320, trail_length=50), at=(95.0, 0.0), t=2.0)
    no_trail = TopViewRenderer(SCENARIO, 320, 320, trail_length=0)
    for k in range(20):
        image_no_trail = draw(no_trail, at=(5.0 * k, 0.0), t=2.0)
    assert not np.array_equal(image, fresh)
    assert np.array_equal(image_no_trail, fresh)
    with_trail.reset()
    assert np.array_equal(draw(with_trail, at=(95.0, 0.0), t=2.0), fresh)


def test_group_edges_inside_groups_only():
    complete = np.ones((4, 4)) - np.eye(4)
    edges = group_edges(complete, np.array([0, 0, 1, 1]))
    assert sorted(map(tuple, edges)) == [(0, 1), (1, 0), (2, 3), (3, 2)]
    assert group_edges(np.zeros((4, 4)), np.zeros(4, dtype=int)).shape == (0, 2)
    # the diagonal is never an edge; (receiver, sender) = (row, column)
    assert sorted(map(tuple, group_edges(np.eye(3) + np.eye(3, k=1), np.zeros(3)))) == [
        (0, 1),
        (1, 2),
    ]


def test_edges_change_the_frame_and_only_inside_groups():
    renderer = TopViewRenderer(SCENARIO, 320, 320, trail_length=0)
    complete = np.ones((N, N)) - np.eye(N)
    none = draw(renderer, adjacency=np.zeros((N, N)))
    full = draw(renderer, adjacency=complete)
    assert not np.array_equal(none, full)
    # every UAV in its own group: no edge survives
    alone = draw(renderer, adjacency=complete, groups=np.arange(N))
    assert np.array_equal(alone, none)
    split = draw(renderer, adjacency=complete, groups=np.array([0, 0, 1, 0, 1]))
    assert not np.array_equal(split, full) and not np.array_equal(split, none)


def test_collisions_highlighted():
    renderer = TopViewRenderer(SCENARIO, 320, 320, trail_length=0)
    plain = draw(renderer)
    hit = draw(renderer, collisions=np.array([False, True, False, False, False]))
    assert count_color(plain, COLLISION_COLOR) == 0
    assert count_color(hit, COLLISION_COLOR) > 20


def test_frames_are_deterministic():
    def episode(renderer):
        renderer.reset()
        return [draw(renderer, at=(7.0 * k, 3.0 * k), t=0.2 * k) for k in range(5)]

    a, b = TopViewRenderer(SCENARIO, 256, 256), TopViewRenderer(SCENARIO, 256, 256)
    first, second, again = episode(a), episode(b), episode(a)
    for x, y, z in zip(first, second, again):
        assert np.array_equal(x, y)
        assert np.array_equal(x, z)
    assert not np.array_equal(first[0], first[1])


def test_frame_from_step_matches_frame():
    result = FormationSim(SCENARIO).reset(seed=0)
    a = TopViewRenderer(SCENARIO, 256, 256).frame_from_step(result)
    b = TopViewRenderer(SCENARIO, 256, 256).frame(
        result.z[0, :, :3],
        result.reference_velocity[0],
        result.adjacency[0],
        result.groups[0],
        float(result.t[0]),
        collisions=result.collision[0],
    )
    assert np.array_equal(a, b)


def test_view_follows_swarm_and_fits_it():
    renderer = TopViewRenderer(SCENARIO, 320, 320, view_span=100.0)
    draw(renderer, at=(500.0, -200.0))
    centre = renderer.data_to_pixel(np.mean(OFFSETS[:, :2], axis=0) + [[500.0, -200.0]])[0]
    np.testing.assert_allclose(centre, [160.0, 160.0], atol=1.0)
    # a swarm wider than view_span widens the view: every UAV is in the image
    spread = np.array([[-300.0, 0.0, 0.0], [300.0, 0.0, 0.0], [0.0, 50.0, 0], [0, -50, 0], [0] * 3])
    renderer.frame(spread, VELOCITY, ADJACENCY, ONE_GROUP, 0.0)
    rows, cols = renderer.data_to_pixel(spread[:, :2]).T
    assert ((rows >= 0) & (rows < 320) & (cols >= 0) & (cols < 320)).all()
    # equal aspect: one metre is as many pixels along x as along y
    (r0, c0), (r1, c1) = renderer.data_to_pixel([[0.0, 0.0], [10.0, 10.0]])
    assert abs(c1 - c0) == pytest.approx(abs(r1 - r0))


def test_non_finite_positions_do_not_crash():
    positions = OFFSETS.copy()
    positions[2] = np.nan
    image = TopViewRenderer(SCENARIO, 128, 128).frame(positions, VELOCITY, ADJACENCY, ONE_GROUP, 0)
    assert image.shape == (128, 128, 3)


def test_bad_inputs_rejected():
    renderer = TopViewRenderer(SCENARIO, 128, 128)
    with pytest.raises(ValueError, match="positions"):
        renderer.frame(OFFSETS[:3], VELOCITY, ADJACENCY, ONE_GROUP, 0.0)
    with pytest.raises(ValueError, match="adjacency"):
        renderer.frame(OFFSETS, VELOCITY, ADJACENCY[:2], ONE_GROUP, 0.0)
    with pytest.raises(ValueError, match="collisions"):
        renderer.frame(OFFSETS, VELOCITY, ADJACENCY, ONE_GROUP, 0.0, collisions=[True])
    with pytest.raises(ValueError, match="trail_length"):
        TopViewRenderer(SCENARIO, trail_length=-1)


def test_write_gif_round_trip(tmp_path):
    renderer = TopViewRenderer(SCENARIO, 160, 120)
    frames = [draw(renderer, at=(10.0 * k, 0.0), t=0.2 * k) for k in range(4)]
    path = write_gif(frames, tmp_path / "episode.gif", fps=10)
    assert path == tmp_path / "episode.gif"
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.size == (160, 120)
        assert gif.n_frames == 4
        assert gif.info["duration"] == 100
        decoded = [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(gif)]
    assert len(decoded) == 4
    # palette quantisation is lossy, but each decoded frame stays close to its source
    for source, back in zip(frames, decoded):
        assert np.abs(source.astype(int) - back.astype(int)).mean() < 3.0


def test_write_gif_rejects_bad_frames(tmp_path):
    with pytest.raises(ValueError, match="at least one"):
        write_gif([], tmp_path / "a.gif")
    good = np.zeros((8, 8, 3), dtype=np.uint8)
    with pytest.raises(ValueError, match="shape"):
        write_gif([good, np.zeros((8, 9, 3), dtype=np.uint8)], tmp_path / "b.gif")
    with pytest.raises(ValueError, match="dtype"):
        write_gif([good.astype(float)], tmp_path / "c.gif")


def test_write_gif_takes_a_generator(tmp_path):
    frames = (np.full((8, 8, 3), 40 * k, dtype=np.uint8) for k in range(3))
    with Image.open(write_gif(frames, tmp_path / "g.gif")) as gif:
        assert gif.n_frames == 3


# ------------------------------------------------------------------ render_episode
SHORT = with_overrides(SCENARIO, {"duration": 12.0})  # 60 steps; seed 0 splits at O1 at 9.8 s


@pytest.mark.parametrize("every", [2, 7])
def test_render_episode_writes_a_gif_with_one_frame_every_k_steps(tmp_path, every):
    out = tmp_path / "new" / "folder" / "episode.gif"  # the folder is created
    policy = make_policy("heuristic", SHORT)
    path = render_episode(SHORT, policy, 0, out, fps=5, every=every, progress=False)
    assert path == out
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.size == (640, 640)
        assert gif.n_frames == len(range(0, SHORT.n_steps + 1, every))  # 31 or 9
        assert gif.info["duration"] == 200  # 5 fps


def test_render_episode_frames_are_the_renderer_on_the_simulated_states():
    """Frame k is TopViewRenderer on the state after k steps: positions, references, groups,
    the observed communication graph (split at O1 in the last frames) and collisions."""
    policy = make_policy("heuristic", SHORT)
    recorder = AdjacencyRecorder(policy, SCENARIO)
    batch = run_episodes(SHORT, recorder, [0])
    adjacency = recorder.adjacency(batch.n_steps + 1)
    # a 60 m view: the UAVs far enough apart in pixels for the edges to show between markers
    frames = list(
        episode_frames(
            batch, adjacency, 1, renderer=TopViewRenderer(SHORT, 160, 160, view_span=60.0)
        )
    )

    sim = FormationSim(SHORT)
    result = sim.reset(seed=0)
    reference = TopViewRenderer(SHORT, 160, 160, view_span=60.0)
    expected = [reference.frame_from_step(result)]
    for _ in range(SHORT.n_steps):
        actions = policy.act_batch(observations_of(sim, result))
        result = sim.step(np.clip(actions, -1.0, 1.0) * sim.u_max)
        expected.append(reference.frame_from_step(result))
    assert len(frames) == len(expected) == 61
    # the episode ends split at O1: the split graph, not H0, is drawn in the last frames
    assert result.groups[0].max() == 1
    assert not np.array_equal(result.adjacency[0], ADJACENCY)
    for k, (frame, want) in enumerate(zip(frames, expected)):
        assert np.array_equal(frame, want), k

    # no collision in this episode: flag UAV3 after step 21, the ring shows at state 21 only
    assert not batch.collision.any()
    collision = batch.collision.copy()
    collision[20, 0, 2] = True
    flagged = dataclasses.replace(batch, collision=collision)
    renderer = TopViewRenderer(SHORT, 160, 160, trail_length=0)
    red = [
        count_color(f, COLLISION_COLOR)
        for f in episode_frames(flagged, adjacency, 1, False, renderer)
    ]
    assert [k for k, pixels in enumerate(red) if pixels > 20] == [21]


def test_render_episode_rejects_bad_arguments(tmp_path):
    policy = make_policy("heuristic", SHORT)
    for name in ("episode.png", "episode", "episode.gif.txt"):
        with pytest.raises(ValueError, match=r"^out must end in \.gif or \.mp4"):
            render_episode(SHORT, policy, 0, tmp_path / name, progress=False)
    with pytest.raises(ValueError, match="^fps"):
        render_episode(SHORT, policy, 0, tmp_path / "a.gif", fps=0, progress=False)
    for every in (0, -1, 1.5):
        with pytest.raises(ValueError, match="^every"):
            render_episode(SHORT, policy, 0, tmp_path / "a.gif", every=every, progress=False)
    assert not list(tmp_path.iterdir())


def test_render_episode_mp4_without_imageio_ffmpeg_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # `import imageio_ffmpeg` fails
    policy = make_policy("heuristic", SHORT)
    with pytest.raises(RuntimeError, match=re.escape(VIDEO_EXTRA_MESSAGE)) as error:
        render_episode(SHORT, policy, 0, tmp_path / "episode.mp4", progress=False)
    assert str(error.value) == (
        "writing .mp4 needs the [video] extra: pip install 'uav-formation-env[video]'"
    )
    assert not (tmp_path / "episode.mp4").exists()


def test_render_episode_mp4(tmp_path):
    ffmpeg = pytest.importorskip("imageio_ffmpeg")  # the [video] extra
    policy = make_policy("heuristic", SHORT)
    path = render_episode(SHORT, policy, 0, tmp_path / "episode.mp4", every=2, progress=False)
    frames, seconds = ffmpeg.count_frames_and_secs(str(path))
    assert frames == 31
    assert seconds == pytest.approx(3.1)


def test_render_a_swarm_of_100_on_the_local_layout(tmp_path):
    """The local layout's graph is the in-neighbours in each UAV's slots: at N = 100 (4-nearest
    graph) every recorded link is a link of H, and a UAV with at most k in-neighbours shows them
    all; render_episode writes the swarm's animation."""
    from uav_formation_env.config_io import resolve_scenario
    from uav_formation_env.episode import FormationEpisodes

    swarm = with_overrides(resolve_scenario("swarm_100"), {"duration": 2.0})
    policy = make_policy("heuristic", swarm)
    recorder = AdjacencyRecorder(policy, swarm)
    assert recorder.needs_neighbour_index
    episodes = FormationEpisodes(swarm, 1)
    step = episodes.reset(seed=0)
    k = swarm.observation.neighbours
    for _ in range(3):
        actions = recorder.act_batch(step.observation, step.neighbour_index)
        recorded, true = recorder._adjacency[-1], step.result.adjacency[0]
        assert (recorded <= true).all() and recorded.sum() > 100
        few = true.sum(axis=1) <= k
        np.testing.assert_array_equal(recorded[few], true[few])
        step = episodes.step(actions)
    out = render_episode(swarm, policy, 0, tmp_path / "swarm.gif", every=5, progress=False)
    with Image.open(out) as gif:
        assert gif.n_frames == len(range(0, swarm.n_steps + 1, 5))
