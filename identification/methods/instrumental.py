"""Instrumental variables: a fit that a loop feeding the turbulence back to the fin does not bias.

Under a flight computer's rate loop the fin follows the measured roll rate, so it carries
the turbulence that moved the rate: a method that reads the fin as independent of the
turbulence (the paper's, output error) is biased, and direct maximum likelihood is
consistent only through the right noise model and a delay in the loop.  The system
identification engineer's answer is an *instrument*: a signal that moves the fin and that
the turbulence does not move -- the excitation on top of the loop (a dither, a schedule),
which the stated loop gives back from the log::

    e_k = fin_cmd_k + K·rate(t_k − delay)        (the loop: fin_cmd = clip(e − K·rate))

The model (the constant one, eq. 29 with ``u_d``) integrated over a window of
:data:`WINDOW_S` from each sample ``t_k`` -- the paper's integral form::

    v(t_k + T) − v(t_k) = −a·∫v + a·α·∫θ + a·α·θ̄·T + a·α·∫u_d

is fitted by two-stage least squares, ``∫v`` and ``∫θ`` instrumented by the excitation's
integral over the window and its values at the window's start and the :data:`LAGS`
samples before (statsmodels' ``IV2SLS``, written out to take the Newey-West covariance
of the project's other regressions,
:func:`identification.methods.statistics.two_stage_least_squares`): consistent whatever the
turbulence's spectrum, because ``e`` is independent of it.  Windows that read a
saturated command are left out (there ``e`` is not known: the command says only that the
loop asked for more than the stops).  Without a stated loop the fin itself is the
instrument (an open-loop test: a fin the turbulence does not move), which makes the fit
consistent where least squares on the same equation is not (the turbulence's error is
correlated in time, and ``∫v`` with it).

The window trades precision against robustness to a fin that acts later than its model
(a servo lag, a late sensor): over 16 logs each of ``benchmarks/instrumental.py``
(``--window`` 0.2, 0.5 and 1 s) the median |error| of α was 13, 18 and 25 % under a
delayed loop with a dither, and 83, 34 and 28 % with the fin 50 ms behind an unmodelled
servo lag.  A delay term (``−a·α·τ·Δθ``, instrumented by the
excitation's change) cut the lag's error to 24 % at 0.5 s but raised the loop's to 25 %,
and is not used.

The intervals of α and θ̄ are Fieller's (ratios: bounded only where the denominator is
significantly not 0), that of ``a`` the Wald interval of its coefficient (its low end
at 0 at most).  The first stage's F statistic says whether the instruments move the
regressors enough (at least :data:`WEAK_F`, Staiger and Stock's rule); below it the
fit is reported and judged unreliable with that reason.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

from identification.estimation.likelihood import hessian_interval
from identification.methods import Context, ModelFit, resimulation_metrics, trace_settings
from identification.methods.diagnosis import OWN_EXCITATION, logged_fin
from identification.methods.pipeline import Measurements, recover_disturbance, smoothing_for
from identification.methods.statistics import (
    newey_west_covariance,
    newey_west_lags,
    two_stage_least_squares,
)
from identification.methods.steps import IdentificationError, measured_velocity
from identification.model import RollParams
from rocketroll_common.arrays import FloatArray

__all__ = ["InstrumentalFit", "fieller_interval", "instrumental", "instrumental_method"]

#: How many past values of the excitation instrument each window (its value at the window's
#: start too, where no noise of that sample's reading is in it), beside its integral.
LAGS = 4
#: The window the model is integrated over (s, to whole samples; the paper's integral form).
WINDOW_S = 0.5
#: First-stage F below which the instruments are weak (Staiger and Stock's rule of thumb).
WEAK_F = 10.0
#: Fewest samples left to fit.
MIN_ROWS = 30
#: The intervals' level.
LEVEL = 0.95


@dataclass(frozen=True, eq=False)
class InstrumentalFit:
    """Result of :func:`instrumental`.

    Attributes
    ----------
    params : RollParams
        The constant model's α, θ̄, a.
    std_errors : dict
        Delta-method standard errors of ``alpha``, ``theta_bar``, ``a_per_s``.
    intervals : dict
        Their 95 % intervals (Fieller's for α and θ̄, the Wald interval of ``E`` mapped for
        ``a``), in the form of the likelihood methods' ``intervals``.
    instruments : dict
        What instrumented the fit: ``source`` (``loop excitation`` or ``fin``), the samples
        used and left out at the stops, and the first stage's F per regressor.
    """

    params: RollParams
    std_errors: dict[str, float]
    intervals: dict[str, dict[str, Any]]
    instruments: dict[str, Any]


def fieller_interval(
    num: float, den: float, var_num: float, var_den: float, cov: float, level: float = LEVEL
) -> tuple[float, float] | None:
    """Fieller's interval for the ratio ``num/den`` of two estimates with that covariance:
    the ``ρ`` where ``num − ρ·den`` is not significantly 0.  ``None`` where the set is not
    a bounded interval (``den`` not significantly different from 0)."""
    z2 = float(stats.norm.ppf(0.5 + 0.5 * level)) ** 2
    qa = den * den - z2 * var_den
    if qa <= 0.0:
        return None
    qb = -2.0 * (num * den - z2 * cov)
    qc = num * num - z2 * var_num
    disc = qb * qb - 4.0 * qa * qc
    if disc < 0.0:  # cannot happen with a positive semi-definite covariance
        return None
    root = math.sqrt(disc)
    return (-qb - root) / (2.0 * qa), (-qb + root) / (2.0 * qa)


def _interval(
    estimate: float, bounds: tuple[float, float] | None, se: float, method: str
) -> dict[str, Any]:
    """An interval in the likelihood methods' form; where unbounded, ``estimate ± z·se``
    (the Wald ends, labelled ``open``: the data do not bound it)."""
    if bounds is not None and all(math.isfinite(b) for b in bounds):
        low, high, end = bounds[0], bounds[1], "likelihood"
    else:
        z = float(stats.norm.ppf(0.5 + 0.5 * LEVEL))
        half = z * se if math.isfinite(se) else abs(estimate)
        low, high, end = estimate - half, estimate + half, "open"
    return {
        "method": method,
        "estimate": estimate,
        "low": float(low),
        "high": float(high),
        "low_end": end,
        "high_end": end,
        "level": LEVEL,
        "determined": end == "likelihood",
    }


def instrumental(inputs: Measurements) -> InstrumentalFit:
    """Fit the constant model by instrumental variables (module docstring).

    Parameters
    ----------
    inputs : Measurements
        The recording as the methods read it (its fin model: the servo, the sensors'
        latency); the recording's ``loop.*`` lines, where it has them, state the loop, which
        saturates at its stops, else at the fins' range.

    Raises
    ------
    IdentificationError
        Where too few samples are left, the instruments do not move the fin at all, or the
        fit gives no damped rocket.
    """
    rec = inputs.recording
    name = rec.name
    rate, rate_source = measured_velocity(rec, 0)
    per = inputs.grid.per_sample
    theta = np.asarray(inputs.theta_fine, dtype=float)
    n, dt = rate.size, rec.dt_s
    # Integrals from the first sample: the rate by trapezoids on the samples, the fin by
    # trapezoids on the fine grid (its servo path), and each interval's mean fin.
    fine = theta[: (n - 1) * per + 1]
    pieces = 0.5 * (fine[:-1] + fine[1:]).reshape(n - 1, per).mean(axis=1)  # per interval
    fin_integral = np.concatenate([[0.0], np.cumsum(pieces) * dt])
    rate_integral = np.concatenate([[0.0], np.cumsum(0.5 * (rate[:-1] + rate[1:])) * dt])
    loop = rec.loop
    if loop is not None:
        stops = loop.stops_within(rec.fin_range())
        excitation, saturated = loop.excitation(rec.time_s, logged_fin(rec), rate, stops)
        excitation, saturated = excitation[: n - 1], saturated[: n - 1]
        # The excitation at the sample itself holds no noise of that sample's reading only
        # where the loop read the rate a whole interval or more before.
        current = loop.delay_s >= dt * (1.0 - 1e-6)
        source = "the excitation on top of the stated loop"
    else:
        excitation, saturated, current = pieces, np.zeros(n - 1, dtype=bool), True
        source = "the fin (no loop stated: read as independent of the turbulence)"
    # Held over each interval (the command is), integrated like the fin.
    excitation_integral = np.concatenate([[0.0], np.cumsum(excitation) * dt])
    span = max(1, round(WINDOW_S / dt))
    first = 0 if current else 1
    lags = range(first, LAGS + 1)
    rows = np.arange(LAGS, n - span)
    touched = np.zeros(rows.size, dtype=bool)  # a saturated sample among those the row reads
    for j in range(-LAGS, span):
        touched |= saturated[rows + j]
    rows = rows[~touched]
    if rows.size < MIN_ROWS:
        raise IdentificationError(
            f"{name}: instrumental variables: {rows.size} windows whose excitation is known "
            f"(the command off the stops over {LAGS + span} samples), {MIN_ROWS} needed"
        )
    own, fin_sd = float(np.std(excitation[rows])), float(np.std(pieces[rows]))
    if own < OWN_EXCITATION * fin_sd:
        raise IdentificationError(
            f"{name}: instrumental variables: the excitation on top of the loop is "
            f"{own:.2g}° RMS against the fin's {fin_sd:.2g}° (under "
            f"{100 * OWN_EXCITATION:g} %: what is left is the loop's reading, not an "
            "excitation): nothing moves the fin that the turbulence does not; add an "
            "excitation on the fin command (a dither or PRBS on top of the loop), or use "
            "--method ml (direct, through the loop's delay)"
        )
    window = span * dt
    ends = rows + span
    y = rate[ends] - rate[rows]
    x = np.column_stack(
        [
            rate_integral[ends] - rate_integral[rows],
            fin_integral[ends] - fin_integral[rows],
            np.full(rows.size, window),
        ]
    )
    z = np.column_stack(
        [excitation_integral[ends] - excitation_integral[rows]]
        + [excitation[rows - j] for j in lags]
        + [np.full(rows.size, window)]
    )
    fstats = _first_stage(x, z, exogenous=[2] if loop is not None else [1, 2])
    try:
        beta, resid, projected = two_stage_least_squares(x, y, z)
        # The windows overlap: their errors are correlated over a window at least.
        cov = newey_west_covariance(projected, resid, newey_west_lags(resid, at_least=span))
    except np.linalg.LinAlgError:
        raise IdentificationError(
            f"{name}: instrumental variables: the instruments do not tell the rate from the "
            "fin (a singular first stage)"
        ) from None
    cov = cov * rows.size / (rows.size - 3)
    b0, b1, b2 = (float(b) for b in beta)
    a = -b0
    if not (a > 0.0 and b1 != 0.0):
        raise IdentificationError(
            f"{name}: instrumental variables give no damped rocket (a = {a:.3g} 1/s): the "
            f"rocket is not told from the loop (first-stage F {_shown(fstats)})"
        )
    alpha, theta_bar = b1 / a, b2 / b1
    # Delta method: the gradients of (α, θ̄, a) in (b0, b1, b2) = (−a, a·α, a·α·θ̄).
    grad = np.array([[b1 / b0**2, -1.0 / b0, 0.0], [0.0, -b2 / b1**2, 1.0 / b1], [-1.0, 0.0, 0.0]])
    var = np.diag(grad @ cov @ grad.T)
    se = {
        k: float(math.sqrt(v)) if v > 0 else math.nan
        for k, v in zip(("alpha", "theta_bar", "a_per_s"), var, strict=True)
    }
    se_a = math.sqrt(max(float(cov[0, 0]), 0.0))  # a = −b0: linear in the coefficients
    a_interval = {**hessian_interval(a, se_a, LEVEL), "method": "wald"}
    if a_interval["low"] <= 0.0:  # a damped rocket: the range ends at 0
        a_interval.update(low=0.0, low_end="range", determined=False)
    intervals = {
        "alpha": _interval(
            alpha,
            fieller_interval(b1, a, float(cov[1, 1]), float(cov[0, 0]), -float(cov[0, 1])),
            se["alpha"],
            "fieller",
        ),
        "theta_bar": _interval(
            theta_bar,
            fieller_interval(b2, b1, float(cov[2, 2]), float(cov[1, 1]), float(cov[1, 2])),
            se["theta_bar"],
            "fieller",
        ),
        "a_per_s": a_interval,
    }
    instruments = {
        "source": "loop excitation" if loop is not None else "fin",
        "described": source,
        "lags": list(lags),
        "window_s": window,
        "windows": int(rows.size),
        "rate": rate_source,
        "excitation_sd_deg": own,
        "left_out_at_stops": int(np.count_nonzero(touched)),
        "first_stage_f": fstats,
        "weak": any(f < WEAK_F for f in fstats.values()),
    }
    if loop is not None:
        instruments["loop"] = {
            "gain": loop.gain,
            "delay_s": loop.delay_s,
            "stops_deg": stops,
        }
    return InstrumentalFit(RollParams(alpha, theta_bar, a), se, intervals, instruments)


def _first_stage(x: FloatArray, z: FloatArray, exogenous: Sequence[int]) -> dict[str, float]:
    """Each endogenous regressor's first-stage F: its regression on the instruments against
    one on the exogenous regressors alone (conventional, not robust to the error's
    correlation: a screen)."""
    names = ("rate", "fin", "constant")
    out = {}
    for j in range(x.shape[1]):
        if j in exogenous:
            continue
        target = x[:, j]
        full = np.linalg.lstsq(z, target, rcond=None)[0]
        rss_full = float(np.sum((target - z @ full) ** 2))
        base = x[:, list(exogenous)]
        restricted = np.linalg.lstsq(base, target, rcond=None)[0]
        rss_base = float(np.sum((target - base @ restricted) ** 2))
        q = z.shape[1] - len(exogenous)
        dof = z.shape[0] - z.shape[1]
        out[names[j]] = (
            float((rss_base - rss_full) / q / (rss_full / dof)) if rss_full > 0 else math.inf
        )
    return out


def _shown(fstats: dict[str, float]) -> str:
    return ", ".join(f"{k} {v:.3g}" for k, v in fstats.items())


def instrumental_method(context: Context, models: Sequence[str]) -> list[ModelFit]:
    """Instrumental variables as an identification method (``method="instrumental"``): the
    constant model only; ``u_d`` recovered by the paper's step 8 under its parameters, as
    for output error (from the velocity smoothed over a shorter window where the rocket is
    fast against the options' smoothing, ``metrics["smoothing_window_s"]``)."""
    inputs = context.measurements
    fits = []
    for model in models:
        if model != "constant":
            raise IdentificationError(
                f"{context.recording.name}: instrumental variables fit the constant model "
                f"only, not {model!r}"
            )
        found = instrumental(inputs)
        # u_d from the velocity smoothed over a window short against the rocket's time
        # constant, as for output error (the fit itself reads the raw rate).
        window = smoothing_for(found.params, inputs, context.options)
        used = inputs if window is None else context.smoothed_over(window)
        dist, resim = recover_disturbance(used, found.params, model, context.options)
        metrics = {
            "sources": {"velocity": found.instruments["rate"], "fin_angle": inputs.theta_source},
            **resimulation_metrics(resim),
            "std_errors": found.std_errors,
            "intervals": found.intervals,
            "instruments": found.instruments,
            **({} if window is None else {"smoothing_window_s": window}),
        }
        fits.append(
            ModelFit("instrumental", model, found.params, dist, metrics, trace_settings(dist))
        )
    return fits
