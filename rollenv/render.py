"""Pictures of RocketRoll-v0: the rocket seen from its tail beside strip charts.

:class:`Renderer` turns a :class:`EpisodeHistory` (the last few seconds of one
episode) into an RGB frame a person understands at a glance:

* left, the rocket seen from its tail, looking forward along the flight axis:
  the round body, its four cruciform fins rotated by the roll angle and drawn
  deflected, a ring of roll angles around it (0° up, positive
  counter-clockwise) with the setpoint on it (angle task) or arc arrows of roll
  rate and rate setpoint (rate task), and two small arrows inside the body for
  the roll torque of the fins and of the turbulence ``u_d``;
* right, strip charts over the last ``window_s`` seconds: the tracking error
  (angle task), the roll rate, the fin angle with its command and limits, and
  ``u_d``.

Figures are drawn on :class:`matplotlib.figure.Figure` with the Agg canvas,
never through pyplot, so ``render_mode="rgb_array"`` leaves the process-wide
matplotlib backend alone.  The figure and its artists are made once and only
their data change afterwards, which keeps a frame at a few tens of
milliseconds.  ``render_mode="human"`` shows the same frame in a pyplot window
when a display and an interactive matplotlib backend exist; otherwise it warns
once (a ``UserWarning``) that nothing is shown, and draws offscreen.

A fin deflected by θ > 0 rolls the rocket the positive way (counter-clockwise
in this view); seen from the tail its trailing edge moves the other way,
because the fin turns the air clockwise and the air pushes back.  The arrow
inside the body shows the resulting roll torque, so the reader need not work
that out.
"""

from __future__ import annotations

import logging
import math
import os
import sys
import time
from typing import Any, Final

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.font_manager import FontProperties
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Polygon, Wedge
from matplotlib.ticker import MaxNLocator
from numpy.typing import NDArray

from rollenv.core import wrap_deg
from rollenv.history import EpisodeHistory

__all__ = ["RENDER_MODES", "Renderer"]

logger = logging.getLogger("rollenv")

FloatArray = NDArray[np.float64]

#: The render modes :class:`Renderer` accepts.
RENDER_MODES: Final = ("human", "rgb_array")


# Tail-view geometry, in body radii.
_BODY_R: Final = 1.0
_FIN_TIP_R: Final = 2.05
_RING_R: Final = 2.3
_RATE_R: Final = 2.55
_RATE_SET_R: Final = 2.8
_VIEW_R: Final = 3.0
_DPI: Final = 100.0  # figure dots per inch: 1 inch of figure = 100 px
_FIN_OFFSET: Final = 0.55  # tangential trailing-edge offset at full deflection, root
_FIN_TAPER: Final = 0.7  # tip offset / root offset (a tapered fin)
_RATE_ARC_DEG: Final = 150.0  # arc of the rate arrows at the rate axis limit
_TORQUE_ARC_DEG: Final = 110.0  # arc of the torque arrows at full fin range
_NUMBER_WIDTH: Final = 7  # characters of a number in the readout
_READOUT_COLUMNS: Final = (6, 27)  # where its two columns of numbers start, characters

# Colours.
_FIN_LIGHT: Final = (0.80, 0.86, 0.94)
_FIN_DARK: Final = (0.05, 0.20, 0.50)
_C_ROLL: Final = "#1f3b73"
_C_SET: Final = "#e07b00"
_C_FIN: Final = "#1f77b4"
_C_CMD: Final = "#7f7f7f"
_C_UD: Final = "#8e44ad"
_C_LIMIT: Final = "#c0392b"
_C_RATE: Final = "#2a7f3f"


def _nice_ceil(x: float) -> float:
    """The smallest 1, 2 or 5 × 10^k that is ≥ ``x`` (``x`` > 0)."""
    exponent = math.floor(math.log10(x))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        value = mantissa * 10.0**exponent
        if value >= x * (1 - 1e-12):
            return value
    return 10.0 ** (exponent + 1)  # pragma: no cover - the loop always returns


class _SymmetricLimit:
    """A symmetric axis limit ±L with hysteresis, so a video does not jitter.

    L grows to a round value as soon as the data need it and shrinks only when
    the data have used less than a quarter of it for the whole window.
    """

    def __init__(self, minimum: float) -> None:
        self.minimum = minimum
        self.value = minimum

    def reset(self) -> None:
        self.value = self.minimum

    def update(self, needed: float) -> float:
        if not math.isfinite(needed):
            return self.value
        if needed > self.value:
            self.value = _nice_ceil(needed * 1.1)
        elif needed < 0.25 * self.value and self.value > self.minimum:
            self.value = max(self.minimum, _nice_ceil(max(needed, 1e-9) * 1.5))
        return self.value


def _max_abs(*arrays: FloatArray) -> float:
    """The largest finite magnitude in the arrays, 0 when there is none."""
    values = np.concatenate([np.abs(a[np.isfinite(a)]) for a in arrays])
    return float(values.max()) if values.size else 0.0


def _fin_polygons(roll_deg: float, fin_deg: float, fin_range_deg: float) -> FloatArray:
    """Outlines of the four fins seen from the tail, shape (4, 4, 2).

    Each fin is hinged along a radius; its leading edge (hidden behind it)
    lies on the radius and its trailing edge is offset tangentially by
    ``_FIN_OFFSET·θ/range`` at the root, tapering towards the tip.  A
    positive θ moves the trailing edge clockwise (see the module docstring).
    """
    psi = np.deg2rad(90.0 + roll_deg + 90.0 * np.arange(4))
    radial = np.stack([np.cos(psi), np.sin(psi)], axis=1)
    tangential = np.stack([-np.sin(psi), np.cos(psi)], axis=1)  # counter-clockwise
    offset = -_FIN_OFFSET * float(np.clip(fin_deg / fin_range_deg, -1.0, 1.0))
    corners = [
        _BODY_R * radial,
        _FIN_TIP_R * radial,
        _FIN_TIP_R * radial + _FIN_TAPER * offset * tangential,
        _BODY_R * radial + offset * tangential,
    ]
    return np.stack(corners, axis=1)


def _arc_arrow(
    radius: float, start_deg: float, sweep_deg: float, head: float
) -> tuple[FloatArray, FloatArray]:
    """An arc from ``start_deg`` sweeping ``sweep_deg`` (counter-clockwise > 0).

    Returns the arc as a polyline (n, 2) and its arrow head as a triangle
    (3, 2); angles in the plot's polar convention (0° to the right).
    """
    angles = np.deg2rad(start_deg + sweep_deg * np.linspace(0.0, 1.0, 40))
    arc = radius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    end = angles[-1]
    radial = np.array([math.cos(end), math.sin(end)])
    forward = math.copysign(1.0, sweep_deg) * np.array([-math.sin(end), math.cos(end)])
    tip = arc[-1] + head * forward
    head_xy = np.stack([tip, arc[-1] + 0.5 * head * radial, arc[-1] - 0.5 * head * radial])
    return arc, head_xy


class _Scene:
    """The figure of one task and its artists, made once and then updated.

    Everything that changes from frame to frame is an *animated* artist: the
    static rest (axes, ticks, labels, the ring) is drawn once into a cached
    background, and a frame restores that background and draws only the
    animated artists on it (blitting).  A change of an axis limit marks the
    background stale, and the next frame redraws it in full.
    """

    def __init__(
        self, task: str, size: tuple[int, int], window_s: float, title: str = "RocketRoll-v0"
    ) -> None:
        width, height = size
        self.task = task
        self.title = title
        self.window_s = window_s
        self.figure = Figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
        self.figure.set_facecolor("white")
        self.canvas = FigureCanvasAgg(self.figure)
        self.font = float(np.clip(9.0 * min(width / 720.0, height / 480.0), 5.0, 18.0))
        self.last_time_s = -math.inf
        self.rate_limit = _SymmetricLimit(20.0)
        self.ud_limit = _SymmetricLimit(5.0)
        self.error_limit = _SymmetricLimit(10.0)
        self.limits: dict[str, tuple[float, float]] = {}
        self.dynamic: list[Artist] = []
        self.background: Any = None
        self.stale = True
        self._build_left(width, height)
        self._build_strips(width, height)
        for artist in self.dynamic:
            artist.set_animated(True)

    # -- construction ------------------------------------------------------------------------

    def _build_left(self, width: float, height: float) -> None:
        """The tail view and its text, in a column on the left."""
        font = self.font
        line_px = 1.7 * font  # one line of text at 100 dpi, px
        top_band = 2.0 * line_px + 10.0
        bottom_band = 5.0 * line_px + 8.0
        side = min(0.55 * width, height - top_band - bottom_band)
        x0 = 6.0
        y0 = bottom_band + 0.5 * (height - top_band - bottom_band - side)
        self.left_px = x0 + side
        ax = self.figure.add_axes(
            (x0 / width, y0 / height, side / width, side / height), frameon=False
        )
        self.tail = ax
        x_text = (x0 + 6.0) / width
        self.figure.text(
            x_text,
            1.0 - 6.0 / height,
            f"{self.title} · seen from the tail",
            fontsize=font * 1.15,
            weight="bold",
            va="top",
        )
        y_clock = 1.0 - (8.0 + line_px) / height
        self.clock = self.figure.text(x_text, y_clock, "", fontsize=font, va="top")
        self.figure.text(
            (x0 + side) / width, y_clock, f"task: {self.task}", fontsize=font, va="top", ha="right"
        )
        # The readout: fixed words in the background and, per frame, only the two columns
        # of numbers drawn over them, aligned in a monospace font.
        mono: dict[str, Any] = {
            "fontsize": font,
            "va": "top",
            "family": "monospace",
            "linespacing": 1.25,
        }
        y_readout = (bottom_band - 4.0) / height
        self.readout_words = self.figure.text(x_text, y_readout, "", color="0.3", **mono)
        advance_px = _monospace_advance_px(self.canvas, font)
        self.readout_numbers = [
            self.figure.text(x_text + column * advance_px / width, y_readout, "", **mono)
            for column in _READOUT_COLUMNS
        ]
        self.corner = self.figure.text(
            x_text, 4.0 / height, "", fontsize=font * 0.8, color="0.45", va="bottom"
        )

        ax.set_xlim(-_VIEW_R, _VIEW_R)
        ax.set_ylim(-_VIEW_R, _VIEW_R)
        ax.set_aspect("equal")
        ax.set_xticks([])
        ax.set_yticks([])
        # The static ring of roll angles: 0° up, positive counter-clockwise.
        ax.add_patch(Circle((0.0, 0.0), _RING_R, fill=False, lw=1.0, ec="0.6"))
        ticks = np.deg2rad(90.0 + np.arange(0.0, 360.0, 30.0))
        inner = _RING_R - np.where(np.arange(12) % 3 == 0, 0.16, 0.09)
        segments = np.stack(
            [
                np.stack([inner * np.cos(ticks), inner * np.sin(ticks)], axis=1),
                np.stack([_RING_R * np.cos(ticks), _RING_R * np.sin(ticks)], axis=1),
            ],
            axis=1,
        )
        ax.add_collection(LineCollection(list(segments), colors="0.6", linewidths=1.0))
        for angle, text in ((0, "0°"), (90, "+90°"), (180, "180°"), (270, "−90°")):
            psi = math.radians(90.0 + angle)
            r = _RING_R - 0.36
            ax.text(r * math.cos(psi), r * math.sin(psi), text, fontsize=font * 0.85,
                    color="0.5", ha="center", va="center")  # fmt: skip
        ax.add_patch(Circle((0.0, 0.0), _BODY_R, fc="0.94", ec="0.3", lw=1.5, zorder=2))
        ax.add_patch(Circle((0.0, 0.0), 0.1, fc="0.6", ec="none", zorder=2))
        ax.text(-0.22, -0.62, "fin", color=_C_FIN, fontsize=font * 0.8, ha="center", zorder=3)
        ax.text(0.25, -0.62, "u_d", color=_C_UD, fontsize=font * 0.8, ha="center", zorder=3)
        ax.text(0.0, -0.83, "torque", color="0.5", fontsize=font * 0.7, ha="center", zorder=3)
        key = (
            (("▼ roll", _C_ROLL), ("▼ setpoint", _C_SET))
            if self.task == "angle"
            else (("━ roll rate", _C_RATE), ("╍ setpoint", _C_SET))
        )
        for k, (text, colour) in enumerate(key):
            ax.text(0.0, 0.03 + 0.06 * (1 - k), text, color=colour, fontsize=font * 0.85,
                    ha="left", va="bottom", transform=ax.transAxes)  # fmt: skip

        # Animated artists, in the order they are drawn.
        def polygon(n: int, colour: Any, **kwargs: Any) -> Polygon:
            patch = Polygon(np.zeros((n, 2)), closed=True, color=colour, **kwargs)
            ax.add_patch(patch)
            self.dynamic.append(patch)
            return patch

        def line(**kwargs: Any) -> Line2D:
            (artist,) = ax.plot([], [], **kwargs)
            self.dynamic.append(artist)
            return artist

        if self.task == "angle":
            self.error_wedge = Wedge(
                (0.0, 0.0), _RING_R + 0.12, 0.0, 0.0, width=0.24, color=_C_SET, alpha=0.35, lw=0
            )
            ax.add_patch(self.error_wedge)
            self.dynamic.append(self.error_wedge)
            self.set_line = line(ls="--", lw=1.6, color=_C_SET)
            self.set_marker = polygon(3, _C_SET)
        else:
            self.rate_arc = line(lw=3.0, color=_C_RATE, solid_capstyle="butt")
            self.rate_head = polygon(3, _C_RATE)
            self.rate_set_arc = line(lw=1.8, ls="--", color=_C_SET)
            self.rate_set_head = polygon(3, _C_SET)
        self.roll_marker = polygon(3, _C_ROLL)
        self.fins = [polygon(4, _FIN_LIGHT, lw=0.0) for _ in range(4)]
        self.trailing_edges = [
            line(lw=2.4, color=_FIN_DARK, solid_capstyle="round") for _ in range(4)
        ]
        self.hinges = [line(lw=1.2, color="0.15") for _ in range(4)]
        self.fin0_dot = line(marker="o", ms=6.0, ls="none", color=_C_ROLL)
        self.fin_torque_arc = line(lw=2.6, color=_C_FIN)
        self.fin_torque_head = polygon(3, _C_FIN)
        self.ud_torque_arc = line(lw=2.6, color=_C_UD)
        self.ud_torque_head = polygon(3, _C_UD)
        self.dynamic += [self.clock, *self.readout_numbers]

    def _build_strips(self, width: float, height: float) -> None:
        """The strip charts, stacked in a column on the right, time relative to now."""
        font = self.font
        names = ("error", "rate", "fin", "ud") if self.task == "angle" else ("rate", "fin", "ud")
        left = self.left_px + 5.0 * font + 16.0
        right = width - 10.0
        bottom = 3.6 * font
        top = height - 8.0
        gap = 6.0
        strip = (top - bottom - gap * (len(names) - 1)) / len(names)
        self.axes: dict[str, Axes] = {}
        for k, name in enumerate(names):
            y = top - (k + 1) * strip - k * gap
            ax = self.figure.add_axes(
                (left / width, y / height, (right - left) / width, strip / height),
                sharex=self.axes.get(names[0]),
            )
            ax.tick_params(labelsize=font * 0.85, length=3, pad=2)
            ax.yaxis.set_major_locator(MaxNLocator(nbins=4, symmetric=True, prune="both"))
            ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 5, 10]))
            ax.grid(True, lw=0.4, color="0.88")
            ax.axhline(0.0, lw=0.6, color="0.6")
            ax.yaxis.set_label_coords(-4.6 * font / (right - left), 0.5)
            if k < len(names) - 1:
                ax.tick_params(labelbottom=False)
            else:
                ax.set_xlabel("time relative to now (s)", fontsize=font, labelpad=1)
            self.axes[name] = ax

        def line(name: str, **kwargs: Any) -> Line2D:
            (artist,) = self.axes[name].plot([], [], **kwargs)
            self.dynamic.append(artist)
            return artist

        legend: dict[str, Any] = {
            "loc": "upper left",
            "fontsize": font * 0.75,
            "ncol": 2,
            "frameon": False,
        }
        if self.task == "angle":
            self.error_line = line("error", lw=1.3, color=_C_ROLL)
            self.axes["error"].set_ylabel("setpoint − roll (°)", fontsize=font)
        self.rate_line = line("rate", lw=1.3, color=_C_RATE, label="rate")
        self.axes["rate"].set_ylabel("roll rate (°/s)", fontsize=font)
        if self.task == "rate":
            self.rate_set_line = line(
                "rate", lw=1.3, ls="--", color=_C_SET, drawstyle="steps-post", label="setpoint"
            )
            self.axes["rate"].legend(**legend)
        fin_ax = self.axes["fin"]
        self.fin_line = line("fin", lw=1.3, color=_C_FIN, label="fin")
        self.cmd_line = line(
            "fin", lw=0.9, ls="--", color=_C_CMD, drawstyle="steps-post", label="command"
        )
        self.fin_hi = fin_ax.axhline(math.nan, lw=0.8, ls=":", color=_C_LIMIT)
        self.fin_lo = fin_ax.axhline(math.nan, lw=0.8, ls=":", color=_C_LIMIT)
        fin_ax.set_ylabel("fin angle (°)", fontsize=font)
        fin_ax.legend(handles=[self.fin_line, self.cmd_line], **legend)
        self.ud_line = line("ud", lw=1.0, color=_C_UD, drawstyle="steps-post")
        self.axes["ud"].set_ylabel("u_d (° of fin)", fontsize=font)

    # -- update --------------------------------------------------------------------------------

    def _set_limits(self, name: str, low: float, high: float) -> None:
        """Set an axis's limits (``"x"`` for the shared time axis); a change redraws all."""
        if self.limits.get(name) == (low, high):
            return
        self.limits[name] = (low, high)
        self.stale = True
        if name == "x":
            self.axes["ud"].set_xlim(low, high)
        else:
            self.axes[name].set_ylim(low, high)

    def update(self, snap: EpisodeHistory) -> None:
        """Move every artist to the state ``snap`` shows."""
        now = float(snap.time_s[-1])
        if now < self.last_time_s:  # a new episode: let the axes start over
            for limit in (self.rate_limit, self.ud_limit, self.error_limit):
                limit.reset()
        self.last_time_s = now
        self._update_strips(snap)
        self._update_tail(snap)
        self._update_text(snap)

    def _update_strips(self, snap: EpisodeHistory) -> None:
        t = snap.time_s - snap.time_s[-1]
        width = max(self.window_s, -float(t[0])) if math.isfinite(t[0]) else self.window_s
        self._set_limits("x", -width, 0.0)

        rate_needed = _max_abs(snap.rate_dps)
        if snap.task == "rate":
            rate_needed = max(rate_needed, _max_abs(snap.setpoint))
            self.rate_set_line.set_data(t, snap.setpoint)
        limit = self.rate_limit.update(rate_needed)
        self._set_limits("rate", -limit, limit)
        self.rate_line.set_data(t, snap.rate_dps)

        if snap.task == "angle":
            error = wrap_deg(snap.setpoint - snap.angle_deg)
            limit = self.error_limit.update(_max_abs(error))
            self._set_limits("error", -limit, limit)
            self.error_line.set_data(t, error)

        fin_range = snap.fin_range_deg
        if self.limits.get("fin") != (-1.15 * fin_range, 1.15 * fin_range):
            self.fin_hi.set_ydata([fin_range, fin_range])
            self.fin_lo.set_ydata([-fin_range, -fin_range])
        self._set_limits("fin", -1.15 * fin_range, 1.15 * fin_range)
        self.fin_line.set_data(t, snap.fin_deg)
        self.cmd_line.set_data(t, snap.command_deg)

        limit = self.ud_limit.update(_max_abs(snap.u_d_deg))
        self._set_limits("ud", -limit, limit)
        self.ud_line.set_data(t, snap.u_d_deg)

    def _update_tail(self, snap: EpisodeHistory) -> None:
        roll = _finite(float(snap.angle_deg[-1]))
        fin = _finite(float(snap.fin_deg[-1]))
        fin_range = snap.fin_range_deg
        level = min(abs(fin) / fin_range, 1.0)
        r, g, b = (a + (z - a) * level for a, z in zip(_FIN_LIGHT, _FIN_DARK, strict=True))
        edge = _C_LIMIT if abs(fin) >= 0.995 * fin_range else _FIN_DARK
        polygons = _fin_polygons(roll, fin, fin_range)
        for k in range(4):
            quad = polygons[k]
            self.fins[k].set_xy(quad)
            self.fins[k].set_facecolor((r, g, b))
            self.hinges[k].set_data(quad[:2, 0], quad[:2, 1])
            self.trailing_edges[k].set_data(quad[2:, 0], quad[2:, 1])
            self.trailing_edges[k].set_color(edge)
        tip = 1.05 * polygons[0, 1]
        self.fin0_dot.set_data([tip[0]], [tip[1]])
        self.roll_marker.set_xy(_ring_marker(roll, _RING_R + 0.02, 0.22))
        # Roll torque of the fin and of u_d: arrows from the top, positive counter-clockwise.
        u_d = _finite(float(snap.u_d_deg[-1]))
        for value, radius, arc, head in (
            (fin, 0.78, self.fin_torque_arc, self.fin_torque_head),
            (u_d, 0.5, self.ud_torque_arc, self.ud_torque_head),
        ):
            sweep = _TORQUE_ARC_DEG * float(np.clip(value / fin_range, -1.0, 1.0))
            _set_arrow(arc, head, radius, sweep, head_size=0.16)

        setpoint = float(snap.setpoint[-1])
        if snap.task == "angle":
            psi = math.radians(90.0 + setpoint)
            radii = np.array([_BODY_R * 1.05, _RING_R + 0.3])
            self.set_line.set_data(radii * math.cos(psi), radii * math.sin(psi))
            self.set_marker.set_xy(_ring_marker(setpoint, _RING_R + 0.3, 0.26))
            error = float(wrap_deg(setpoint - roll))
            visible = math.isfinite(error) and abs(error) > 0.2
            self.error_wedge.set_visible(visible)
            if visible:
                low, high = sorted((90.0 + roll, 90.0 + roll + error))
                self.error_wedge.set_theta1(low)
                self.error_wedge.set_theta2(high)
        else:
            scale = _RATE_ARC_DEG / self.rate_limit.value
            rate = float(snap.rate_dps[-1])
            _set_arrow(self.rate_arc, self.rate_head, _RATE_R, _clip_arc(rate * scale), 0.22)
            _set_arrow(
                self.rate_set_arc, self.rate_set_head, _RATE_SET_R, _clip_arc(setpoint * scale), 0.2
            )

    def _update_text(self, snap: EpisodeHistory) -> None:
        self.clock.set_text(f"t = {float(snap.time_s[-1]):.1f} s")
        words, columns = _readout(snap)
        for text, column in zip(self.readout_numbers, columns, strict=True):
            text.set_text(column)
        if words != self.readout_words.get_text() or snap.label != self.corner.get_text():
            self.readout_words.set_text(words)
            self.corner.set_text(snap.label)
            self.stale = True

    def rgb(self) -> NDArray[np.uint8]:
        """Draw the frame and return its pixels, (height, width, 3) uint8, a fresh copy."""
        if self.stale or self.background is None:
            self.canvas.draw()  # the static rest; animated artists are left out
            self.background = self.canvas.copy_from_bbox(self.figure.bbox)
            self.stale = False
        else:
            self.canvas.restore_region(self.background)
        renderer = self.canvas.get_renderer()
        for artist in self.dynamic:
            artist.draw(renderer)
        rgba = np.asarray(self.canvas.buffer_rgba())
        return np.ascontiguousarray(rgba[..., :3])


def _finite(value: float) -> float:
    """``value``, or 0 when it is not finite (a picture needs a number)."""
    return value if math.isfinite(value) else 0.0


def _readout(snap: EpisodeHistory) -> tuple[str, tuple[str, str]]:
    """The readout under the tail view: its words and its two columns of numbers.

    The words keep a blank of ``_NUMBER_WIDTH`` characters where each number
    goes, at the columns ``_READOUT_COLUMNS`` of a monospace font, so they can
    sit in the cached background and only the numbers are drawn per frame.
    """
    roll = float(wrap_deg(snap.angle_deg[-1]))
    setpoint = float(snap.setpoint[-1])
    rate = float(snap.rate_dps[-1])
    fin, command, u_d = (float(x[-1]) for x in (snap.fin_deg, snap.command_deg, snap.u_d_deg))
    blank = " " * _NUMBER_WIDTH
    if snap.task == "angle":
        rows = [
            (f"roll  {blank}°    setpoint {blank}°", roll, float(wrap_deg(setpoint))),
            (f"rate  {blank}°/s  error    {blank}°", rate, float(wrap_deg(setpoint - roll))),
        ]
    else:
        rows = [
            (f"rate  {blank}°/s  setpoint {blank}°/s", rate, setpoint),
            (f"roll  {blank}°    error    {blank}°/s", roll, setpoint - rate),
        ]
    rows.append((f"fin   {blank}°    command  {blank}°", fin, command))
    words = "\n".join([row[0] for row in rows] + [f"u_d   {blank}°    (turbulence as fin angle)"])
    first = "\n".join([_number(row[1]) for row in rows] + [_number(u_d)])
    second = "\n".join(_number(row[2]) for row in rows)
    return words, (first, second)


def _monospace_advance_px(canvas: FigureCanvasAgg, fontsize: float) -> float:
    """The advance of one character of the monospace font at ``fontsize`` pt, px."""
    probe = "0" * 20
    prop = FontProperties(family="monospace", size=fontsize)
    width_px, _, _ = canvas.get_renderer().get_text_width_height_descent(probe, prop, False)
    return float(width_px) / len(probe)


def _number(value: float) -> str:
    """A value as ``_NUMBER_WIDTH`` (7) characters, one decimal, sign (clipped to ±9999.9)."""
    return f"{float(np.clip(value, -9999.9, 9999.9)):+7.1f}"


def _clip_arc(sweep_deg: float) -> float:
    """An arrow's sweep limited to ±(``_RATE_ARC_DEG`` + 30°), °."""
    return float(np.clip(sweep_deg, -_RATE_ARC_DEG - 30.0, _RATE_ARC_DEG + 30.0))


def _set_arrow(
    arc: Line2D, head: Polygon, radius: float, sweep_deg: float, head_size: float
) -> None:
    """Point an arc arrow from the top of the view, ``sweep_deg`` counter-clockwise (> 0)."""
    visible = math.isfinite(sweep_deg) and abs(sweep_deg) >= 1.0
    arc.set_visible(visible)
    head.set_visible(visible)
    if visible:
        line_xy, head_xy = _arc_arrow(radius, 90.0, sweep_deg, head_size)
        arc.set_data(line_xy[:, 0], line_xy[:, 1])
        head.set_xy(head_xy)


def _ring_marker(angle_deg: float, radius: float, size: float) -> FloatArray:
    """A triangle with its tip at ``radius`` pointing to the centre, (3, 2); angle in °."""
    psi = math.radians(90.0 + angle_deg) if math.isfinite(angle_deg) else 0.0
    radial = np.array([math.cos(psi), math.sin(psi)])
    tangential = np.array([-math.sin(psi), math.cos(psi)])
    tip = radius * radial
    base = tip + size * radial
    return np.stack([tip, base + 0.5 * size * tangential, base - 0.5 * size * tangential])


def _warn_once(message: str) -> None:
    """A ``UserWarning`` through Gymnasium's logger (a renderer says it once: it then
    draws offscreen without opening a window again)."""
    from gymnasium import logger as gym_logger

    gym_logger.warn(message)


def _display_available() -> bool:
    """Whether a window could open: a display on Linux/BSD, always on macOS and Windows."""
    if sys.platform.startswith(("win", "darwin")):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _interactive_backends() -> set[str]:
    """Lower-case names of matplotlib's interactive built-in backends."""
    try:
        from matplotlib.backends import BackendFilter, backend_registry
    except ImportError:  # matplotlib < 3.9
        from matplotlib import rcsetup

        return {name.lower() for name in getattr(rcsetup, "interactive_bk", ())}
    return {name.lower() for name in backend_registry.list_builtin(BackendFilter.INTERACTIVE)}


class Renderer:
    """Draws :class:`EpisodeHistory` frames of RocketRoll-v0 for ``rgb_array`` or a window.

    Parameters
    ----------
    render_mode : str
        ``"rgb_array"`` (:meth:`frame` returns pixels) or ``"human"``
        (:meth:`show` draws into a window).
    fps : float
        Frames per second a window is paced to, 1/s (the environment's
        ``metadata["render_fps"]``).
    size : tuple of int, optional
        Frame (width, height) in pixels; (720, 480) by default, multiples of 16
        so video encoders take it unchanged.
    window_s : float, optional
        Shortest time span of the strip charts, s (10 s by default); a longer
        history widens them.
    title : str, optional
        What the frame is of (the environment's id), before "seen from the tail".

    Raises
    ------
    ValueError
        If ``render_mode`` is not one of :data:`RENDER_MODES`, ``fps`` is not
        positive or ``size`` is not two integers, at least (480, 320).

    Notes
    -----
    The figure and its artists are made on the first frame and only their
    data change afterwards (a task change rebuilds them).  ``rgb_array``
    never touches pyplot; ``human`` imports pyplot on the first :meth:`show`
    and uses whatever backend matplotlib resolves: without a display or with
    a non-interactive backend it warns once (``UserWarning``) and draws
    offscreen only.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(0.0, 10.0, 0.1)
    >>> from rollenv.history import EpisodeHistory
    >>> zero = np.zeros_like(t)
    >>> snap = EpisodeHistory(t, 30 + 5 * np.sin(t), 5 * np.cos(t), 10 * np.sin(t),
    ...                       10 * np.sin(t), zero, np.full_like(t, 30.0), zero, zero, "angle")
    >>> renderer = Renderer("rgb_array", fps=10)
    >>> renderer.frame(snap).shape
    (480, 720, 3)
    >>> renderer.close()
    """

    def __init__(
        self,
        render_mode: str,
        fps: float,
        size: tuple[int, int] = (720, 480),
        *,
        window_s: float = 10.0,
        title: str = "RocketRoll-v0",
    ) -> None:
        if render_mode not in RENDER_MODES:
            raise ValueError(
                f"render_mode must be one of {RENDER_MODES} (or None for no rendering), "
                f"got {render_mode!r}"
            )
        if not (math.isfinite(fps) and fps > 0.0):
            raise ValueError(f"fps must be a positive number, got {fps!r}")
        if (
            len(size) != 2
            or not all(isinstance(n, int | np.integer) for n in size)
            or size[0] < 480
            or size[1] < 320
        ):
            raise ValueError(
                f"size must be (width, height) in pixels, at least (480, 320), got {size!r}"
            )
        if not (math.isfinite(window_s) and window_s > 0.0):
            raise ValueError(f"window_s must be a positive number of seconds, got {window_s!r}")
        self.render_mode = render_mode
        self.fps = float(fps)
        self.size = (int(size[0]), int(size[1]))
        self.window_s = float(window_s)
        self.title = str(title)
        self._scene: _Scene | None = None
        self._window: Any = None  # (figure, image) of the pyplot window in human mode
        self._window_state = "unopened"  # "unopened", "open" or "offscreen"
        self._deadline_s = 0.0

    def __repr__(self) -> str:
        return (
            f"Renderer(render_mode={self.render_mode!r}, fps={self.fps}, size={self.size}, "
            f"window_s={self.window_s})"
        )

    def frame(self, snap: EpisodeHistory) -> NDArray[np.uint8]:
        """Draw one frame.

        Parameters
        ----------
        snap : EpisodeHistory
            The episode's recent history to show.

        Returns
        -------
        numpy.ndarray
            RGB pixels, shape (height, width, 3), dtype uint8, C-contiguous, a
            new array on every call; the same shape on every call.
        """
        if self._scene is None or self._scene.task != snap.task:
            self._scene = _Scene(snap.task, self.size, self.window_s, self.title)
        self._scene.update(snap)
        pixels = self._scene.rgb()
        width, height = self.size
        if pixels.shape != (height, width, 3):  # Agg rounding of an odd figure size
            fixed = np.full((height, width, 3), 255, dtype=np.uint8)
            h, w = min(height, pixels.shape[0]), min(width, pixels.shape[1])
            fixed[:h, :w] = pixels[:h, :w]
            pixels = fixed
        return pixels

    def show(self, snap: EpisodeHistory) -> None:
        """Draw one frame and show it in a window, paced to ``fps``.

        Without a usable display (or with a non-interactive matplotlib
        backend) this warns once (``UserWarning``) on the first call and then
        only draws offscreen.  Closing the window stops
        the showing; the episode goes on.

        Parameters
        ----------
        snap : EpisodeHistory
            The episode's recent history to show.
        """
        pixels = self.frame(snap)
        if self._window_state == "unopened":
            self._open_window(pixels)
        if self._window_state != "open":
            return
        import matplotlib.pyplot as plt

        figure, image = self._window
        if not plt.fignum_exists(figure.number):
            self._window_state = "offscreen"
            self._window = None
            logger.info("RocketRoll-v0 window closed; rendering goes on offscreen")
            return
        image.set_data(pixels)
        figure.canvas.draw_idle()
        now = time.perf_counter()
        period = 1.0 / self.fps
        self._deadline_s = max(self._deadline_s + period, now)
        plt.pause(max(self._deadline_s - now, 1e-3))

    def _open_window(self, pixels: NDArray[np.uint8]) -> None:
        """Open the pyplot window, or note (once) that none can open."""
        if not _display_available():
            self._window_state = "offscreen"
            _warn_once(
                'render_mode="human": no display (DISPLAY/WAYLAND_DISPLAY unset), nothing is '
                'shown; use render_mode="rgb_array" for frames'
            )
            return
        import matplotlib
        import matplotlib.pyplot as plt

        backend = str(matplotlib.get_backend()).lower()
        if backend not in _interactive_backends():
            self._window_state = "offscreen"
            _warn_once(
                f'render_mode="human": matplotlib backend {backend!r} cannot open a window, '
                'nothing is shown; use render_mode="rgb_array" for frames or set MPLBACKEND'
            )
            return
        width, height = self.size
        figure = plt.figure(figsize=(width / _DPI, height / _DPI), dpi=_DPI)
        if figure.canvas.manager is not None:
            figure.canvas.manager.set_window_title("RocketRoll-v0")
        ax = figure.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        image = ax.imshow(pixels, interpolation="nearest")
        self._window = (figure, image)
        self._window_state = "open"
        self._deadline_s = time.perf_counter()
        plt.show(block=False)

    def close(self) -> None:
        """Free the figure and close the window; calling it again does nothing."""
        if self._window is not None:
            import matplotlib.pyplot as plt

            plt.close(self._window[0])
            self._window = None
        if self._scene is not None:
            self._scene.figure.clear()
            self._scene = None
        self._window_state = "unopened"
