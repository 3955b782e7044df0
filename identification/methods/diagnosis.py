"""What a log can tell, and why not: the reasons behind a fit, in the terms of the test flown.

The adequacy (:mod:`identification.methods.adequacy`) says whether a fit describes its
recording; an interval (:func:`~identification.estimation.likelihood.profile_interval`)
says what the recording determines.  This module says *why* a log determines little, in
the terms of the test that made it, each finding one line that names what would fix it:

* **the fins at their stops** -- the share of samples within
  :data:`STOP_TOLERANCE` of the fins' range (stated, or the log's largest ``|fin|``): there
  the fin is constant whatever the controller asks, the turbulence acts unopposed and
  the fin's effect cannot be told from a constant torque;
* **feedback** -- the share of the fin's changes the roll rate measured before them
  predicts, beyond the fin's own past (a Granger-style regression over lags up to
  :data:`FEEDBACK_LAGS_S`): a rate controller on the fins.  An open-loop schedule is
  not predicted by the rocket's response; a closed loop's fin is.  Its proportional gain
  ``K`` and delay are read off the best single lag.  On such a log the fin carries the
  turbulence through the loop: output error is not consistent; maximum likelihood with
  the fin read from the log is (the loop has a delay, the turbulence is modelled), and
  with a proportional loop and nothing on top of it only ``a·(1 + α·K)`` is determined;
* **collinearity** -- how much of each of the model's regressors the others explain
  (uncentred R² of the one-step equation's regressors: the fin, the roll rate, a
  constant torque; in flight ``q·δ``, ``ρV·p`` and ``q``), at least
  :data:`COLLINEAR_R2` (a variance inflation of 20) naming the pair;
* **excitation against the turbulence** -- the part of the fin not explained by the
  rate (its own excitation) against the turbulence's SD, under :data:`EXCITATION_RATIO`;
* **independent samples** -- how many independent looks at the rocket the fin gives
  (the samples over the fin's decorrelation length), under :data:`MIN_INDEPENDENT`.

Each figure is in :class:`Diagnosis` (``figures``) and each finding names its kind, so a
benchmark can check that the diagnosis names saturation on flights that saturate and
not on those that do not (``benchmarks/closed_loop_identification.py``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from identification.methods.statistics import decorrelation_stride
from identification.recordings.recording import FinRange, Recording
from rocketroll_common.arrays import FloatArray

__all__ = [
    "COLLINEAR_R2",
    "Diagnosis",
    "Finding",
    "LoopAlone",
    "collinearity",
    "diagnose",
    "feedback",
    "logged_fin",
    "loop_alone",
    "looped",
    "partly_looped",
    "share_at_stops",
]

#: A sample is at a stop within this fraction of the fins' range.
STOP_TOLERANCE = 0.005
#: Share of samples at the stops from which saturation is named.
STOP_SHARE = 0.05
#: Longest lag of the roll rate the fin's feedback regression reads, s.
FEEDBACK_LAGS_S = 0.25
#: Most lags in that regression (spread evenly over the span).
MAX_LAGS = 12
#: Share of the fin's smooth changes (its jumps left out) the past rate predicts, beyond the
#: fin's own past, from which a closed loop is named, with its F-test's p under
#: :data:`FEEDBACK_P` (``benchmarks/closed_loop_identification.py`` counts both sides).
FEEDBACK_SHARE = 0.3
FEEDBACK_P = 1e-6
#: Share from which a loop that moves only part of the fin is named (p under
#: :data:`FEEDBACK_P` too): a controller beside a schedule, a dither or its own noise.
#: Open-loop schedules on the virtual tunnel: 0 (steps, ramps, doublets, PRBS) to 0.011
#: (a chirp, p ≥ 2e-5); a chirp clipped at the stops 0.03-0.12 (p down to 1e-19): the
#: finding is not made where the fin is at its stops :data:`STOP_SHARE` of the time.
PARTLY_SHARE = 0.01
#: The fin's own part (no rate explains it) against its SD from which a loop is excited.
OWN_EXCITATION = 0.1
#: Uncentred R² of a regressor on the others from which they are collinear (VIF 20).
COLLINEAR_R2 = 0.95
#: The fin's own excitation against the turbulence's SD under which it is too small.
EXCITATION_RATIO = 0.25
#: Fewest independent looks at the rocket the fin should give.
MIN_INDEPENDENT = 20


@dataclass(frozen=True)
class Finding:
    """One reason, its ``kind`` (``saturation``, ``feedback``, ``collinearity``,
    ``excitation``, ``samples``) and the line that says it and what would fix it."""

    kind: str
    text: str


@dataclass(frozen=True)
class Diagnosis:
    """The figures behind the findings (JSON-safe) and the findings themselves."""

    figures: dict[str, Any]
    findings: tuple[Finding, ...] = field(default_factory=tuple)

    @property
    def kinds(self) -> tuple[str, ...]:
        return tuple(f.kind for f in self.findings)

    def lines(self) -> list[str]:
        return [f.text for f in self.findings]

    def as_dict(self) -> dict[str, Any]:
        return {
            **self.figures,
            "findings": [{"kind": f.kind, "text": f.text} for f in self.findings],
        }


def loop_law(gain: float, delay_s: float) -> str:
    """A proportional rate loop as a line says it: ``fin ≈ trim − 0.6·rate 40 ms before``
    (``+`` for a negative gain)."""
    sign = "−" if gain >= 0 else "+"
    return f"fin ≈ trim {sign} {abs(gain):.3g}·rate {1000 * delay_s:.0f} ms before"


def logged_fin(recording: Recording) -> FloatArray:
    """The fin as the log holds it and a loop acts on it: the command where there is one,
    else the measured fin (a recording has one or the other)."""
    fin = recording.fin_cmd_deg if recording.fin_cmd_deg is not None else recording.fin_deg
    assert fin is not None
    return np.asarray(fin, dtype=float)


def share_at_stops(fin: FloatArray, fins: FinRange) -> float:
    """The share of samples whose ``|fin|`` is within :data:`STOP_TOLERANCE` of the range."""
    return float(np.mean(np.abs(fin) >= fins.deg * (1.0 - STOP_TOLERANCE)))


def _lags(dt_s: float) -> list[int]:
    """The rate's lags the feedback regression reads, in samples: 0 (a rate read at the
    sample the command is sent) to :data:`FEEDBACK_LAGS_S`."""
    most = max(1, round(FEEDBACK_LAGS_S / dt_s))
    return sorted({int(v) for v in np.linspace(0, most, min(MAX_LAGS, most + 1))})


def _r2_gain(y: FloatArray, base: FloatArray, extra: FloatArray) -> tuple[float, FloatArray]:
    """The share of ``y``'s variance (around the base fit) that ``extra`` explains beyond
    ``base``; and the full fit's residual."""
    full = np.column_stack([base, extra])
    r_base = y - base @ np.linalg.lstsq(base, y, rcond=None)[0]
    r_full = y - full @ np.linalg.lstsq(full, y, rcond=None)[0]
    rss = float(r_base @ r_base)
    return (1.0 - float(r_full @ r_full) / rss if rss > 0 else 0.0), r_full


_NO_LOOP = {"share": math.nan, "p": math.nan, "own_sd_deg": math.nan, "gain": math.nan,
            "delay_s": math.nan}  # fmt: skip


def feedback(
    fin: FloatArray, rate: FloatArray, dt_s: float, free: NDArray[np.bool_]
) -> dict[str, Any]:
    """The fin's dependence on the roll rate measured before it, over the samples ``free``
    of the stops (a Granger-style test): the share of the fin's changes the rate at lags 0
    to :data:`FEEDBACK_LAGS_S` predicts beyond the fin's own past at the same lags
    (``share``: a ramp, a sweep or a servo's travel is the fin's own) and its F-test's
    ``p``; the part of the fin no rate explains (``own_sd_deg``: the excitation on top of a
    loop, or the whole schedule of an open one); and the loop's proportional gain (``gain``,
    °/(°/s): the fin ≈ trim − gain·rate) and delay (s), from the fin's changes on the
    rate's at the best lag, the excitation's jumps left out (beyond four robust SDs)."""
    lags = _lags(dt_s)
    top = max(lags)
    n = fin.size
    t = np.arange(top + 1, n)
    t = t[free[t] & free[t - 1]] if n > top + 1 else t
    if t.size < 20 + 2 * len(lags):
        return dict(_NO_LOOP)
    change = fin[t] - fin[t - 1]
    levels = np.column_stack([np.ones(t.size), *(rate[t - d] for d in lags)])
    own = fin[t] - levels @ np.linalg.lstsq(levels, fin[t], rcond=None)[0]
    # The excitation's jumps (a step, a PRBS bit) are the fin's own and unpredictable: left
    # out, what is left of a loop's fin is the loop's, and of an open schedule's nothing.
    scale = 1.4826 * float(np.median(np.abs(change - np.median(change))))
    smooth = np.abs(change) <= 4.0 * scale
    ts, moves = t[smooth], change[smooth]
    if ts.size < 20 + 2 * len(lags) or float(np.ptp(moves)) == 0.0:
        share, p = 0.0, 1.0
    else:
        base = np.column_stack([np.ones(ts.size), *(fin[ts - 1 - d] for d in lags)])
        past = np.column_stack([rate[ts - d] for d in lags])
        share, resid = _r2_gain(moves, base, past)
        dof = ts.size - base.shape[1] - past.shape[1]
        unexplained = max(float(resid @ resid) / dof, 1e-300)
        rss_base = share * float(resid @ resid) / max(1.0 - share, 1e-12)
        p = float(stats.f.sf(rss_base / past.shape[1] / unexplained, past.shape[1], dof))
    best = (-1.0, math.nan, math.nan)
    for d in lags:
        x = (rate[t - d] - rate[t - d - 1])[smooth]
        y = change[smooth]
        denominator = float(x @ x)
        if denominator <= 0:
            continue
        slope = float(x @ y) / denominator
        r2 = 1.0 - float(np.sum((y - slope * x) ** 2)) / max(float(y @ y), 1e-300)
        if r2 > best[0]:
            best = (r2, -slope, d * dt_s)
    return {
        "share": max(0.0, share),
        "p": p,
        "own_sd_deg": float(np.std(own)),
        "gain": best[1],
        "delay_s": best[2],
    }


def looped(loop: Mapping[str, Any]) -> bool:
    """Whether :func:`feedback`'s figures say a closed loop: the rate predicts at least
    :data:`FEEDBACK_SHARE` of the fin's changes, significantly (p < :data:`FEEDBACK_P`)."""
    share, p = loop["share"], loop["p"]
    return bool(math.isfinite(share) and share >= FEEDBACK_SHARE and p < FEEDBACK_P)


def partly_looped(loop: Mapping[str, Any]) -> bool:
    """Whether :func:`feedback`'s figures say a loop moves part of the fin only: the rate
    predicts at least :data:`PARTLY_SHARE` of its changes, significantly, but less than a
    closed loop's (:func:`looped`)."""
    share, p = loop["share"], loop["p"]
    return bool(math.isfinite(share) and PARTLY_SHARE <= share < FEEDBACK_SHARE and p < FEEDBACK_P)


def _excited(own_sd_deg: float, fin: FloatArray, free: NDArray[np.bool_]) -> bool:
    """Whether the fin's own part (°, no rate explains it) is an excitation on top of a
    loop: at least :data:`OWN_EXCITATION` of the fin's SD over the samples ``free`` of the
    stops (of nothing where none is)."""
    fin_sd = float(np.std(fin[free])) if np.any(free) else 0.0
    return bool(own_sd_deg >= OWN_EXCITATION * fin_sd)


@dataclass(frozen=True)
class LoopAlone:
    """A rate loop that alone moves the fin and answers the rate within the log's sample:
    its ``gain`` (°/(°/s)) and ``delay_s``, as stated (``stated``) or read off the log
    (:func:`feedback`: 0, the delay under a sample, on the log's grid).

    There the fin between two samples answers the turbulence of that same interval, which
    the log sees only at its end: the fin is not an input decided before the turbulence it
    meets, and maximum likelihood with the fin read from the log is not consistent.  The
    rocket's damping and gain are not told apart (nor, with the gain, its asymmetry), and
    with the turbulence the only input not even the closed loop's damping ``a·(1 + α·K)``
    is: the loop's time constant and the turbulence's correlation can trade places."""

    gain: float
    delay_s: float
    stated: bool

    def as_dict(self) -> dict[str, Any]:
        return {"gain": self.gain, "delay_s": self.delay_s, "stated": self.stated}


def loop_alone(
    recording: Recording, rate: FloatArray, dt_s: float, fins: FinRange
) -> LoopAlone | None:
    """The :class:`LoopAlone` of a log whose fin a rate loop moves with nothing on top and
    whose loop answers the measured ``rate`` (°/s, at its samples ``dt_s`` apart) in under a
    sample.

    A stated loop (the recording's ``loop.*`` lines) says its delay, unless the log shows the
    loop two samples late or more (a delay left at its default of 0); nothing is on top where
    the excitation given back through it (:meth:`~identification.recordings.recording.
    StatedLoop.excitation`) moves under :data:`OWN_EXCITATION` of the fin's SD off the
    stops.  Without one, the loop is the one the log shows (:func:`looped`) at lag 0, with
    the fin's own part under that share.  None otherwise."""
    fin = logged_fin(recording)[: np.size(rate)]
    rate = np.asarray(rate, dtype=float)[: fin.size]
    stated = recording.loop
    free = np.abs(fin) < fins.deg * (1.0 - STOP_TOLERANCE)
    loop = feedback(fin, rate, dt_s, free)
    if stated is not None:
        if stated.delay_s >= dt_s or (looped(loop) and loop["delay_s"] >= 2.0 * dt_s):
            return None  # the log shows the loop two samples late or more: not under one
        time = np.asarray(recording.time_s, dtype=float)[: fin.size]
        own, saturated = stated.excitation(time, fin, rate, stated.stops_within(fins))
        free = ~saturated.astype(bool)
        if np.any(free) and _excited(float(np.std(own[free])), fin, free):
            return None  # an excitation on top of the loop tells the rocket from it
        return LoopAlone(stated.gain, stated.delay_s, True)
    if not looped(loop) or loop["delay_s"] != 0.0:
        return None
    if _excited(loop["own_sd_deg"], fin, free):
        return None  # an excitation on top of the loop tells the rocket from it
    return LoopAlone(loop["gain"], 0.0, False)


def collinearity(columns: Mapping[str, FloatArray]) -> dict[str, float]:
    """Each regressor's uncentred R² on the others (1 − 1/VIF): near 1, the data cannot
    tell its coefficient from theirs."""
    names = list(columns)
    x = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    out = {}
    for i, name in enumerate(names):
        y = x[:, i]
        others = np.delete(x, i, axis=1)
        resid = y - others @ np.linalg.lstsq(others, y, rcond=None)[0]
        total = float(y @ y)
        out[name] = 1.0 - float(resid @ resid) / total if total > 0 else 1.0
    return out


def diagnose(
    fin: FloatArray,
    rate: FloatArray,
    dt_s: float,
    fins: FinRange,
    *,
    turbulence_sd_deg: float | None = None,
    regressors: Mapping[str, FloatArray] | None = None,
) -> Diagnosis:
    """The findings on one log: ``fin`` (°) and the measured ``rate`` (°/s) at its samples,
    ``dt_s`` apart; the fins' range; the fitted turbulence's SD (°, equivalent fin angle)
    where known; the model's regressors (default the tunnel model's: the fin, the roll rate,
    a constant torque)."""
    fin = np.asarray(fin, dtype=float)
    rate = np.asarray(rate, dtype=float)
    stops = share_at_stops(fin, fins)
    free = np.abs(fin) < fins.deg * (1.0 - STOP_TOLERANCE)
    loop = feedback(fin, rate, dt_s, free)
    columns = regressors or {
        "the fin": fin,
        "the roll rate": rate,
        "a constant torque (θ̄)": np.ones_like(fin),
    }
    collinear = collinearity(columns)
    stride = decorrelation_stride(fin - fin.mean(), math.exp(-1.0)) if np.ptp(fin) > 0 else fin.size
    independent = fin.size / max(stride, 1)
    closed = looped(loop)
    # The fin's own excitation: all of it in open loop, the part no past rate explains in a loop.
    own = loop["own_sd_deg"] if closed else float(np.std(fin))
    ratio = own / turbulence_sd_deg if turbulence_sd_deg else math.nan
    found: list[Finding] = []
    if stops >= STOP_SHARE:
        consequence = (
            "there the fin is constant whatever the controller asks, the turbulence acts "
            "unopposed and the fin's effect cannot be told from a constant torque; fly with "
            "less loop gain or a smaller excitation, or fit the stretches off the stops "
            "(--from/--to)"
            if closed
            else "the schedule runs to the stops: the gain is then read from the fin's travel "
            "between them, and a stop that gives or sits elsewhere than the range biases it; "
            "keep the schedule inside the range"
        )
        where = (
            f"the fin sits at its largest |fin|, {fins.deg:g}°, {100 * stops:.0f} % of the "
            "time (the fins' range is not stated; if that is not their stops, say so with "
            "--fin-range): "
            if fins.source == FinRange.LARGEST
            else f"the fins sit at their stops ({fins}) {100 * stops:.0f} % of the time: "
        )
        found.append(Finding("saturation", where + consequence))
    if closed:
        instant = loop["delay_s"] == 0.0
        consistent = (
            f"the loop answers the rate within the log's sample (its delay reads as 0 on the "
            f"log's {1000 * dt_s:.3g}-ms grid), so the fin carries the turbulence and the "
            "gyro's noise of the very sample it is logged with, and ml is not consistent "
            "either (direct identification needs the loop's delay to be a sample or more: log "
            "faster than the loop answers, or state the loop with --loop-delay)"
            if instant
            else "ml with the fin read from the log is (the loop has a delay)"
        )
        excited = (
            f"The fin's own excitation on top of the loop ({own:.2g}° RMS) separates the "
            "rocket from the loop; with the loop stated (--loop-gain, --loop-delay, or the "
            "recording's loop.* lines) --method instrumental takes it as the instrument"
            if _excited(own, fin, free)
            else "Nothing moves the fin but the loop: the rocket is told from the loop only "
            "through the loop's delay (without one only a·(1 + α·K) is determined); an "
            "excitation on the fin command (a dither or PRBS) makes it robust"
        )
        found.append(
            Finding(
                "feedback",
                f"the fin follows the measured roll rate (the rate before it predicts "
                f"{100 * loop['share']:.0f} % of the fin's changes; "
                f"{loop_law(loop['gain'], loop['delay_s'])}): a closed "
                "loop. Output error is not consistent on it (the fin carries the turbulence "
                f"through the loop); {consistent}. {excited}",
            )
        )
    elif partly_looped(loop) and stops < STOP_SHARE:  # a clipped schedule mimics a weak loop
        p = "p < 1e-12" if loop["p"] < 1e-12 else f"p = {loop['p']:.2g}"
        found.append(
            Finding(
                "feedback",
                f"the fin partly follows the measured roll rate (the rate before it predicts "
                f"{100 * loop['share']:.0f} % of the fin's changes beyond the fin's own past, "
                f"{p}): a loop acts on the fin beside its own excitation (a schedule, a "
                "dither, the controller's noise). ml with the fin read from the log is "
                "consistent on it; output error and the paper's method are biased by the part "
                "of the fin the loop carries (the turbulence, fed back); the fin's own part is "
                "what tells the rocket",
            )
        )
    pairs = [name for name, r2 in collinear.items() if r2 >= COLLINEAR_R2]
    if pairs:
        detail = ", ".join(f"{name} {collinear[name]:.3f}" for name in pairs)
        found.append(
            Finding(
                "collinearity",
                f"the model's regressors move together (each one's R² on the others: {detail}): "
                f"only what {' and '.join(pairs)} do apart tells their coefficients apart, and "
                "the intervals say how well that was; where they are wide, an excitation of "
                "the fin that the rate does not cause (a dither on top of the loop, steps at "
                "other speeds) separates them",
            )
        )
    if math.isfinite(ratio) and ratio < EXCITATION_RATIO:
        found.append(
            Finding(
                "excitation",
                f"the fin moves {own:.2g}° RMS of its own against the turbulence's "
                f"{turbulence_sd_deg:.2g}°: the turbulence, not the test, drives the roll; "
                "a larger or longer excitation narrows every interval",
            )
        )
    if independent < MIN_INDEPENDENT:
        found.append(
            Finding(
                "samples",
                f"the fin gives about {independent:.0f} independent looks at the rocket "
                f"({fin.size} samples, the fin correlated over {stride * dt_s:.2g} s): a "
                "longer log or a faster excitation (shorter dwells or PRBS bits) gives more",
            )
        )

    def safe(value: float) -> float | None:
        return float(value) if math.isfinite(value) else None

    figures = {
        **fins.as_dict(),
        "share_at_stops": stops,
        "feedback_share": safe(loop["share"]),
        "closed_loop": closed,
        "loop_gain": safe(loop["gain"]),
        "loop_delay_s": safe(loop["delay_s"]),
        "fin_own_sd_deg": safe(own),
        "excitation_ratio": safe(ratio),
        "collinearity_r2": collinear,
        "independent_samples": independent,
    }
    return Diagnosis(figures, tuple(found))
