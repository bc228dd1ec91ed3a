"""The video speed term: the ground's slide measured in a follow camera's frames."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from virl_quad.reward import egomotion as eg

SKY, DARK, LIGHT, ROBOT = 255, 95, 150, 40


def _scene(offsets: np.ndarray, square: int = 10) -> np.ndarray:
    """[T, 48, 48] uint8: sky over a checker ground shifted right by ``offsets[t]`` px, with a
    still dark block (the followed robot) in front of it."""
    yy, xx = np.mgrid[0:48, 0:48]
    out = np.empty((len(offsets), 48, 48), dtype=np.uint8)
    for t, off in enumerate(offsets):
        board = ((xx - int(off)) // square + yy // square) % 2
        img = np.where(board == 0, DARK, LIGHT).astype(np.uint8)
        img[:16] = SKY
        img[12:30, 16:32] = ROBOT
        out[t] = img
    return out


@pytest.mark.parametrize("shift", [-5, -3, 0, 2, 6])
def test_a_known_slide_of_the_ground_is_measured(shift: int) -> None:
    frames = _scene(np.array([0, shift]))
    levels = eg.ground_levels(frames)
    assert DARK in levels and LIGHT in levels and SKY not in levels and ROBOT not in levels
    got = eg.ground_shift(frames[:1], frames[1:], levels)
    assert abs(float(got[0]) - shift) < 0.3


def test_a_textured_ground_is_measured_over_its_range_of_levels() -> None:
    """A checker blended between neighbouring frames (a video resampled to the control rate) has
    no flat levels, only a range; its slide is measured over that range, and the agent's own
    frames on the flat checker are measured by their own levels."""
    frames = _scene(np.round(-1.0 * np.arange(41)).astype(int)).astype(np.float32)
    blended = np.clip(0.5 * (frames[:-1] + frames[1:]) + np.random.default_rng(0).normal(0, 4, (40, 48, 48)),
                      0, 255).astype(np.uint8)                   # many ground levels, and the robot block kept
    levels = eg.ground_levels(blended)
    assert levels[0] > ROBOT + 10 and levels[-1] < SKY - 50 and len(levels) > 40
    k = eg.window_steps(50.0)
    assert eg.clip_speed(blended, 50.0, levels, k) == pytest.approx(-k, abs=0.5)
    term = eg.VideoSpeedTerm(-float(k), 50.0, levels, 1, k)
    flat = _scene(np.round(-1.0 * np.arange(3 * k)).astype(int))
    assert list(term.find_agent_ground(flat)) == list(eg.ground_levels(flat))
    reward, valid, shift = term.rollout(torch.from_numpy(flat[:, None]), torch.zeros(3 * k, 1, dtype=torch.bool))
    assert bool(valid.any()) and float(shift[valid].mean()) == pytest.approx(-k, abs=0.5)


def test_no_pattern_no_shift() -> None:
    plain = np.full((2, 48, 48), 120, np.uint8)
    plain[:, :16] = SKY
    assert torch.isnan(eg.ground_shift(plain[:1], plain[1:], eg.ground_levels(plain))).all()
    assert eg.clip_speed(np.repeat(plain, 20, axis=0), 50.0) is None


def test_built_in_demonstrations_travel_forwards_at_their_own_speed() -> None:
    from virl_quad import demo

    speeds = {g: eg.clip_speed(demo.load(g, "pupper").frames, 50.0) for g in ("pace", "bound")}
    assert speeds["pace"] < 0 and speeds["bound"] < 0            # forwards: the ground slides left
    assert speeds["bound"] < 1.4 * speeds["pace"]                 # 0.3 m/s against 0.2 m/s
    pace = demo.load("pace", "pupper").frames
    assert eg.clip_speed(pace[::-1].copy(), 50.0) == pytest.approx(-speeds["pace"], abs=0.05)
    assert eg.clip_speed(demo.load("trot", "pupper", ground="plain").frames, 50.0) is None


def test_a_slide_that_would_alias_gets_a_shorter_window() -> None:
    slow = _scene(np.round(0.5 * np.arange(40)))               # 0.5 px per frame: 4 px per 8 frames
    assert eg.clip_window(slow, 50.0) == eg.window_steps(50.0)
    fast = _scene(np.round(-1.6 * np.arange(40)))              # 12.8 px per 8 frames: past half the 20 px period
    k = eg.clip_window(fast, 50.0)
    assert 1 <= k < eg.window_steps(50.0) and 1.6 * k < 5.0    # short enough for twice the slide
    assert eg.clip_speed(fast, 50.0) == pytest.approx(-1.6 * k, abs=0.3)   # forwards, per its window
    assert eg.clip_speed(fast, 50.0, window=eg.window_steps(50.0)) > 0   # the default window reads it backwards


def test_the_laikago_trot_travels_forwards() -> None:
    from virl_quad import demo

    frames = demo.load("trot", "laikago").frames                 # ~0.8 m/s at Laikago's camera scale, 33 Hz
    assert eg.clip_window(frames, 33.33) < eg.window_steps(33.33)
    assert eg.clip_speed(frames, 33.33) < 0


def _rollout(steps: int, envs: int, speed: float) -> np.ndarray:
    return np.stack([_scene(np.round(speed * np.arange(steps) + 3 * n)) for n in range(envs)], axis=1)


def test_the_term_pays_the_demonstration_speed_and_carries_over_rollouts() -> None:
    k = eg.window_steps(50.0)
    target = -4.0                                                 # px per window
    frames = torch.from_numpy(_rollout(40, 3, target / k))
    dones = torch.zeros(40, 3, dtype=torch.bool)
    dones[17, 1] = True                                           # env 1 starts again at step 18
    whole = eg.VideoSpeedTerm(target, 50.0, np.array([DARK, LIGHT]), 3, k)
    r, valid, given = whole.rollout(frames, dones)
    assert not valid[:k].any() and valid[k:, 0].all()             # the first block has no measure yet
    assert not valid[18:18 + k, 1].any() and valid[18 + k:, 1].all()
    assert float(r[valid].min()) > 0.9                            # walking at the demonstration's speed
    halves = eg.VideoSpeedTerm(target, 50.0, np.array([DARK, LIGHT]), 3, k)
    parts = [halves.rollout(frames[a:b], dones[a:b]) for a, b in ((0, 13), (13, 40))]
    assert torch.equal(torch.cat([p[1] for p in parts]), valid)
    assert torch.allclose(torch.cat([p[0] for p in parts]), r)


def test_each_block_reads_the_shift_of_its_own_two_frames() -> None:
    k, steps = 4, 25
    frames = torch.from_numpy(_rollout(steps, 2, -0.6))
    term = eg.VideoSpeedTerm(-2.4, 50.0, np.array([DARK, LIGHT]), 2, k)
    _, _, given = term.rollout(frames, torch.zeros(steps, 2, dtype=torch.bool))
    for t in range(k, steps, k):                                  # blocks end at steps k, 2k, ...: each frame
        alone = eg.ground_shift(frames[t - k], frames[t], term.agent_levels)   # blurred once for two blocks
        assert torch.isfinite(alone).all() and torch.allclose(given[t], alone), t


@pytest.mark.parametrize("speed, low, high", [(0.0, 0.3, 0.45), (4.0, 0.0, 0.02)])
def test_standing_or_going_backwards_earns_less(speed: float, low: float, high: float) -> None:
    k = eg.window_steps(50.0)
    frames = torch.from_numpy(_rollout(3 * k, 1, speed / k))
    term = eg.VideoSpeedTerm(-4.0, 50.0, np.array([DARK, LIGHT]), 1, k)
    r, valid, _ = term.rollout(frames, torch.zeros(3 * k, 1, dtype=torch.bool))
    assert valid.any() and low <= float(r[valid].mean()) <= high  # exp(-1) in place; exp(-4) backwards


def test_the_search_stops_at_half_the_patterns_period() -> None:
    """Pupper's camera sees the checker at ~25 px a period: the full search. A ground that repeats
    every 10 px is searched to 5 px, past which a shift reads as well the other way."""
    from virl_quad import demo

    assert eg.search_reach(_scene(np.arange(6), square=10)) == eg.MAX_DX
    assert eg.search_reach(demo.load("trot", "pupper").frames) == eg.MAX_DX
    assert eg.search_reach(_scene(np.arange(6), square=5)) == 5


def _replay(travel: float, draw_as: str | None = "laikago", steps: int = 120) -> np.ndarray:
    """Pupper's built-in trot, its travel x ``travel``, drawn on ``draw_as``'s body (None: Pupper's
    own), gray [T, 48, 48]."""
    from virl_quad import demo, robots
    from virl_quad.sim.shadow import Shadow
    from virl_quad.sim.world import World

    pupper = robots.get("pupper")
    motion = demo.load("trot", "pupper").motion
    shadow = Shadow(pupper, robots.get(draw_as), "checker") if draw_as else None
    world = None if shadow else World(pupper, ground="checker")
    frames = np.empty((steps, 48, 48), np.uint8)
    try:
        for i in range(steps):
            pos, quat, q = motion.pose_at(i / 50.0)
            pos = np.array(pos, dtype=np.float64)
            pos[0] *= travel
            if shadow:
                frames[i] = shadow.render(pos, quat, pupper.clip_to_limits(q))
            else:
                world.set_pose(pos, quat, pupper.clip_to_limits(q))
                frames[i] = world.render()
    finally:
        (shadow or world).close()
    return frames


def test_a_laikago_cameras_slide_reads_in_proportion_to_its_travel() -> None:
    """The Laikago's camera stands off 2.6x as far and sees the checker at ~10 px a period; its
    sharp renders of a trot going ~3.3 px per 2 frames read, searched to 8 px, as often 6-7 px
    the other way. Searched to half the period, half the travel reads half the slide."""
    fast, slow = _replay(3.5), _replay(1.75)
    levels, reach = eg.ground_levels(fast), eg.search_reach(fast)
    assert reach < eg.MAX_DX
    v_fast = eg.clip_speed(fast, 50.0, levels, window=2, reach=reach)
    v_slow = eg.clip_speed(slow, 50.0, levels, window=2, reach=reach)
    assert v_fast < -2.5 and v_slow / v_fast == pytest.approx(0.5, abs=0.07)


def test_a_fast_clips_window_keeps_its_slide_within_the_search() -> None:
    """Pupper's trot at 2.6x its travel slides ~9.6 px in the default 8 frames, past the 8 px
    searched: read there, it stops growing. The window shrinks until an agent 1.5x as fast
    still fits, and half the travel reads half the slide."""
    fast, slow = _replay(2.6, None), _replay(1.3, None)
    levels = eg.ground_levels(fast)
    k = eg.clip_window(fast, 50.0, levels)
    assert k < eg.window_steps(50.0)
    v_fast = eg.clip_speed(fast, 50.0, levels, window=k)
    assert eg.HEADROOM * abs(v_fast) <= eg.MAX_DX - 0.5
    assert eg.clip_speed(slow, 50.0, levels, window=k) / v_fast == pytest.approx(0.5, abs=0.07)


def test_a_search_under_two_px_is_refused_by_the_term_too() -> None:
    frames = _scene(np.array([0, 2]))
    with pytest.raises(ValueError, match="reach"):
        eg.ground_shift(frames[:1], frames[1:], np.array([DARK, LIGHT]), reach=1)
    with pytest.raises(ValueError, match="reach"):                # when the term is built
        eg.VideoSpeedTerm(-2.0, 50.0, np.array([DARK, LIGHT]), 1, 1, reach=1)


def test_the_speed_term_gates_the_distance_reward() -> None:
    distance = np.array([0.20, 0.02, 0.10])        # the video's gait, another gait, half-way
    speed = np.array([0.0, 1.0, 0.5])              # standing, travelling at the video's speed, between
    r = eg.gated(distance, speed, 0.3)
    assert r == pytest.approx(distance * np.array([0.7, 1.0, 0.85]))
    assert r[0] > r[1]                             # another gait that travels stays under the video's own
    for scale in (0.5, 0.1):                       # a narrower range of distance rewards ranks alike
        assert np.argsort(eg.gated(scale * distance, speed, 0.3)).tolist() == np.argsort(r).tolist()
    t = eg.gated(torch.tensor([0.2]), torch.tensor([1.0]), 0.3)
    assert isinstance(t, torch.Tensor) and float(t) == pytest.approx(0.2)
