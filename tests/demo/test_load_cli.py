"""``virl_quad.demo.load`` for every kind of source, the gait cache, the env hookup, and the CLI."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest

from virl_quad import demo, envs, robots
from virl_quad.demo import render
from virl_quad.demo.__main__ import main

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_builtin_gait_is_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("VIRL_QUAD_CACHE", str(tmp_path))
    d = demo.load("trot", "pupper")
    (cached,) = tmp_path.glob(f"pupper_trot_checker_{demo.CACHE_VERSION}_*.npz")
    assert d.motion is not None and d.fps == 50.0
    t = time.perf_counter()
    again = demo.load("trot", "pupper")
    assert time.perf_counter() - t < 0.5
    np.testing.assert_array_equal(again.frames, d.frames)
    assert again.motion is not None and again.source == "gait:trot"
    cached.write_bytes(b"corrupt")                       # a broken cache entry is rendered again
    assert demo.load("trot", "pupper").num_frames == d.num_frames
    plain = demo.load("trot", "pupper", ground="plain")  # another ground: another entry
    assert len(list(tmp_path.glob(f"pupper_trot_plain_{demo.CACHE_VERSION}_*.npz"))) == 1
    assert plain.camera["ground"] == "plain" and np.abs(plain.frames.astype(int) - d.frames).mean() > 5


def test_cache_dir_default(monkeypatch, tmp_path):
    monkeypatch.delenv("VIRL_QUAD_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert demo.cache_dir() == tmp_path / "virl_quad"


def test_load_npz_and_video(tmp_path, gait_motions):
    d = render.render_demonstration(gait_motions[("pupper", "pace")], "pupper", min_seconds=0.5,
                                    video=tmp_path / "p.mp4", preview="frames")
    render.save_npz(d, tmp_path / "p.npz")
    assert demo.load(tmp_path / "p.npz", "pupper").motion is not None
    other = demo.load(str(tmp_path / "p.npz"), "laikago")           # another robot: resampled, no motion
    assert other.fps == pytest.approx(robots.get("laikago").control_hz) and other.motion is None
    video = demo.load(str(tmp_path / "p.mp4"), "pupper")
    assert video.motion is None and video.num_frames == d.num_frames


def test_load_motion_file(motions_dir):
    clip = demo.load(str(motions_dir / "dog_trot.txt"), "pupper")   # Laikago clip retargeted to Pupper
    assert clip.robot == "pupper" and clip.motion.robot == "pupper" and clip.fps == 50.0
    assert clip.num_frames == pytest.approx(clip.motion.duration * 50 * np.ceil(2.0 / clip.motion.duration))
    on_laikago = demo.load(str(motions_dir / "dog_trot.txt"), "laikago")
    assert on_laikago.motion.robot == "laikago" and on_laikago.displacement[-1, 0] > 1.0


def test_bad_sources(tmp_path):
    with pytest.raises(ValueError, match="built-in gait \\(trot, pace, bound, pronk, walk\\)"):
        demo.load("gallop", "pupper")
    with pytest.raises(FileNotFoundError):
        demo.load(str(tmp_path / "missing.mp4"), "pupper")
    with pytest.raises(ValueError, match="unknown robot"):
        demo.load("trot", "spot")


def test_env_uses_the_demo_with_rsi():
    d = demo.load("trot", "laikago")
    env = envs.make("laikago", demo=d, randomize=False)
    try:
        obs, _ = env.reset(seed=1, options={"demo_step": 5})
        ref = d.motion.state_at(5 / d.fps)
        s = env.unwrapped.state
        np.testing.assert_allclose(s.q, ref.q, atol=1e-6)
        np.testing.assert_allclose(s.base_pos, ref.root_pos, atol=1e-6)
        np.testing.assert_array_equal(obs["expert_image"], d.frames[5])
        obs, *_ = env.step(np.zeros(12))
        np.testing.assert_array_equal(obs["expert_image"], d.frames[6])
    finally:
        env.close()


# -- CLI ---------------------------------------------------------------------------------------
def test_cli_render_show_import(tmp_path, capsys):
    npz, mp4, png = tmp_path / "d.npz", tmp_path / "d.mp4", tmp_path / "g.png"
    assert main(["render", "--robot", "pupper", "--gait", "bound", "--out", str(npz), "--video", str(mp4),
                 "--video-size", "96", "--seconds", "0.4"]) == 0
    n = render.load_npz(npz).num_frames
    cap = cv2.VideoCapture(str(mp4))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == n
    assert main(["show", str(npz), "--out", str(png)]) == 0 and cv2.imread(str(png)) is not None
    assert main(["import", str(mp4), "--robot", "pupper", "--out", str(tmp_path / "i.npz")]) == 0
    assert render.load_npz(tmp_path / "i.npz").num_frames == n
    out = capsys.readouterr().out
    assert "wrote" in out


def test_cli_contacts_and_score(capsys, motions_dir):
    assert main(["contacts", "--dir", str(motions_dir), "--robots", "laikago", "--strict"]) == 0
    assert main(["score", "--robot", "pupper", "--seconds", "1"]) == 0
    assert main(["roundtrip", "--robot", "pupper", "--preview", "frames", "--seconds", "0.5"]) == 0
    out = capsys.readouterr().out
    assert "dog_trot.txt" in out and "quarter-cycle shift" in out and "round-trip MAE" in out


def _bad_inputs(tmp):
    (tmp / "rows.txt").write_text('{"LoopMode": "Wrap", "FrameDuration": 0.02, "Frames": [[1, 2, 3], [4, 5, 6]]}')
    (tmp / "junk.mp4").write_bytes(b"junk")
    cv2.VideoWriter(str(tmp / "empty.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 30, (32, 32)).release()
    out = str(tmp / "o.npz")
    return {
        "unknown gait": ["render", "--robot", "pupper", "--gait", "gallop", "--out", out],
        "unknown robot": ["render", "--robot", "spot", "--out", out],
        "missing motion": ["render", "--robot", "pupper", "--motion", str(tmp / "none.txt"), "--out", out],
        "row width": ["render", "--robot", "laikago", "--motion", str(tmp / "rows.txt"), "--out", out],
        "missing video": ["import", str(tmp / "none.mp4"), "--robot", "pupper", "--out", out],
        "unreadable video": ["import", str(tmp / "junk.mp4"), "--robot", "pupper", "--out", out],
        "zero-frame video": ["import", str(tmp / "empty.avi"), "--robot", "pupper", "--out", out],
        "missing npz": ["show", str(tmp / "none.npz"), "--out", str(tmp / "g.png")],
        "not an npz": ["show", str(tmp / "rows.txt"), "--out", str(tmp / "g.png")],
        "missing argument": ["render", "--robot", "pupper"],
    }


def test_cli_bad_input_in_process(tmp_path, capsys):
    for name, argv in _bad_inputs(tmp_path).items():
        assert main(argv) == 2, name
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: ") and "Traceback" not in err, (name, err)


@pytest.mark.parametrize("case", ["unknown gait", "row width", "unreadable video", "zero-frame video"])
def test_cli_bad_input_process(tmp_path, case):
    """As a real process: exit code 2, exactly one line on stderr, no traceback (native libs silenced)."""
    argv = _bad_inputs(tmp_path)[case]
    p = subprocess.run([sys.executable, "-m", "virl_quad.demo", *argv], capture_output=True, text=True,
                       cwd=REPO, timeout=120)
    assert p.returncode == 2, p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in p.stderr, p.stderr


def test_load_accepts_its_own_gait_label():
    """A demonstration's source label ("gait:trot", as stored in policy metadata) loads again."""
    from virl_quad import demo as demo_lib

    d = demo_lib.load("trot", "pupper")
    again = demo_lib.load(d.source, "pupper")
    assert d.source == "gait:trot" and np.array_equal(again.frames, d.frames)
