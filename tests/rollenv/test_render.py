"""The renderer of RocketRoll-v0 (:mod:`rollenv.render`): frames and the window fallback."""

from __future__ import annotations

import dataclasses
import sys
import warnings

import numpy as np
import pytest

from rollenv.history import EpisodeHistory
from rollenv.render import _FIN_TIP_R, Renderer, _fin_polygons, wrap_deg

WIDTH, HEIGHT = 720, 480


def snapshot(
    task: str = "angle",
    n: int = 100,
    roll_deg: float = 20.0,
    fin_deg: float = 10.0,
    t_end_s: float = 12.3,
) -> EpisodeHistory:
    """A plausible 10-s history ending at ``roll_deg`` and ``fin_deg``."""
    t = t_end_s - 0.1 * np.arange(n)[::-1]
    wave = np.sin(1.3 * t)
    setpoint = np.full(n, 30.0 if task == "angle" else 60.0)
    return EpisodeHistory(
        time_s=t,
        angle_deg=roll_deg + 8.0 * (wave - wave[-1]),
        rate_dps=10.4 * np.cos(1.3 * t),
        fin_deg=np.r_[12.0 * wave[:-1], fin_deg],
        command_deg=15.0 * wave,
        u_d_deg=2.0 * np.cos(3.1 * t),
        setpoint=setpoint,
        error=setpoint - roll_deg,
        reward=np.zeros(n),
        task=task,
        fin_range_deg=40.0,
        label="trace test-0 · test",
    )


def tail_view(frame: np.ndarray) -> np.ndarray:
    """The middle of the left panel (the rocket seen from its tail), without its text."""
    height, width = frame.shape[:2]
    return frame[int(0.15 * height) : int(0.8 * height), int(0.03 * width) : int(0.47 * width)]


@pytest.fixture(scope="module")
def renderer():
    """One renderer for the module: its first frame builds the figure (~0.1 s)."""
    r = Renderer("rgb_array", fps=10.0)
    yield r
    r.close()


def test_frames_keep_shape_dtype_and_layout(renderer: Renderer) -> None:
    snaps = [
        snapshot(),
        snapshot(n=1),
        snapshot(n=37, roll_deg=-700.0, fin_deg=-40.0),
        dataclasses.replace(snapshot(), rate_dps=np.full(100, 950.0)),  # axis limits grow
        snapshot(t_end_s=0.4, n=5),  # a new episode
    ]
    frames = [renderer.frame(s) for s in snaps]
    for frame in frames:
        assert frame.shape == (HEIGHT, WIDTH, 3)
        assert frame.dtype == np.uint8
        assert frame.flags["C_CONTIGUOUS"]
    # Every call returns its own pixels, not a view of the canvas.
    assert not np.shares_memory(frames[0], frames[1])
    assert not np.array_equal(frames[0], frames[2])


def test_frame_is_a_picture(renderer: Renderer) -> None:
    frame = renderer.frame(snapshot())
    colours = np.unique(frame.reshape(-1, 3), axis=0)
    assert len(colours) > 50
    ink = np.any(frame < 200, axis=2).mean()
    assert 0.03 < ink < 0.6


def test_fins_turn_with_the_roll_angle(renderer: Renderer) -> None:
    a = renderer.frame(snapshot(roll_deg=10.0))
    b = renderer.frame(snapshot(roll_deg=10.0 + 360.0))
    c = renderer.frame(snapshot(roll_deg=55.0))
    assert np.array_equal(a, b)  # one turn further looks the same
    assert np.mean(np.any(tail_view(a) != tail_view(c), axis=2)) > 0.01


def test_fins_show_their_deflection(renderer: Renderer) -> None:
    a = renderer.frame(snapshot(fin_deg=0.0))
    b = renderer.frame(snapshot(fin_deg=30.0))
    c = renderer.frame(snapshot(fin_deg=-30.0))
    assert np.mean(np.any(tail_view(a) != tail_view(b), axis=2)) > 0.01
    assert np.mean(np.any(tail_view(b) != tail_view(c), axis=2)) > 0.01


def test_rate_task(renderer: Renderer) -> None:
    rate = renderer.frame(snapshot("rate"))
    again = renderer.frame(snapshot("rate", fin_deg=-25.0))
    angle = renderer.frame(snapshot("angle"))
    assert rate.shape == angle.shape == (HEIGHT, WIDTH, 3)
    assert not np.array_equal(rate, again)
    assert not np.array_equal(rate, angle)


def test_other_size_and_no_finite_data() -> None:
    r = Renderer("rgb_array", fps=30.0, size=(496, 320))
    nan = np.full(3, np.nan)
    snap = EpisodeHistory(nan, nan, nan, nan, nan, nan, nan, nan, nan, "rate", 40.0, "")
    assert r.frame(snap).shape == (320, 496, 3)
    r.close()


def test_human_mode_without_display_warns_once(monkeypatch) -> None:
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.setattr(sys, "platform", "linux")
    r = Renderer("human", fps=1000.0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r.show(snapshot())
        r.show(snapshot(roll_deg=40.0))
        r.close()
    assert len(caught) == 1 and caught[0].category is UserWarning
    assert "no display" in str(caught[0].message) and "rgb_array" in str(caught[0].message)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match=r"human.*rgb_array"):
        Renderer("ansi", fps=10.0)
    with pytest.raises(ValueError, match="fps"):
        Renderer("rgb_array", fps=0.0)
    with pytest.raises(ValueError, match="size"):
        Renderer("rgb_array", fps=10.0, size=(64, 48))
    with pytest.raises(ValueError, match="one length"):
        dataclasses.replace(snapshot(), rate_dps=np.zeros(3))
    with pytest.raises(ValueError, match="task"):
        dataclasses.replace(snapshot(), task="spin")


def test_close_twice_then_draw_again() -> None:
    r = Renderer("rgb_array", fps=10.0)
    r.close()  # before any frame
    assert r.frame(snapshot(n=1)).shape == (HEIGHT, WIDTH, 3)
    r.close()
    r.close()


def test_fin_geometry() -> None:
    """Fin 0 points up at roll 0, the fins turn counter-clockwise with the roll angle,
    and a positive deflection moves the trailing edges clockwise, in proportion to θ."""
    quads = _fin_polygons(0.0, 0.0, 40.0)
    np.testing.assert_allclose(quads[0, 1], [0.0, _FIN_TIP_R], atol=1e-12)
    np.testing.assert_allclose(_fin_polygons(90.0, 0.0, 40.0)[0, 1], [-_FIN_TIP_R, 0.0], atol=1e-12)
    np.testing.assert_allclose(_fin_polygons(90.0, 0.0, 40.0)[3], quads[0], atol=1e-12)
    half = _fin_polygons(0.0, 20.0, 40.0)
    full = _fin_polygons(0.0, 40.0, 40.0)
    assert half[0, 3, 0] > 0.0  # fin 0 points up: its trailing edge moves right (clockwise)
    np.testing.assert_allclose(
        full[:, 2:] - quads[:, 2:], 2.0 * (half[:, 2:] - quads[:, 2:]), atol=1e-12
    )
    np.testing.assert_allclose(_fin_polygons(0.0, 90.0, 40.0), full)  # beyond range: clipped


def test_wrap_deg() -> None:
    wrapped = wrap_deg(np.array([0.0, 180.0, -180.0, 190.0, 725.0]))
    np.testing.assert_allclose(wrapped, [0.0, -180.0, -180.0, -170.0, 5.0])
