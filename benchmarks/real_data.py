"""Every identification method on recordings a user supplies: parameters, adequacy, errors.

For each recording given (format v1, e.g. made by ``rocketroll import-csv`` from a
rig's log; nothing is downloaded), and each sampling rate asked for (``--every N``
keeps every N-th reading: 100 Hz, 50 Hz, 10 Hz of a 100-Hz log), every tunnel method
(``--methods``; default all) fits both damping models through
:func:`identification.methods.fit` with one shared context.  Printed per fit: α, θ̄, a
(or β̄ and ᾱ), α's standard error where the method reports one, the adequacy figures
(:mod:`identification.methods.adequacy`: rate R² of the model without ``u_d``, R² a time
constant ahead, the share of ``u_d`` the fin explains, ``|u_d|`` against the fins'
range) and the verdict with its reasons; a method that cannot fit the recording
says why in one line, and the others run.

A flight (a recording whose airspeed changes: a flight computer's log imported with
``--source flight``, or ``rocketroll record-flight``'s) is fitted by the flight methods instead:
the rocket at the fit's reference airspeed, its measured airspeed scaling (``n``, ``m``
with their standard errors) and the test of eq. 4-8, and the same adequacy figures.

Where a truth is known -- the recording's ``truth.*`` metadata (the virtual tunnel's or
flight recorder's, a flight's carried to the fit's reference by its own scaling), or
``--truth alpha=3.39,a=9.55`` (e.g. an independent fit of the same rig) -- the errors of
α and of the damping are printed beside each fit.

    .venv/bin/python benchmarks/real_data.py rig.csv --every 1 --every 2 --every 10 \\
        --truth alpha=3.39,a=9.55
    .venv/bin/python benchmarks/real_data.py flight.csv --every 1 --every 4
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from _records import emit

from identification.methods import (
    Context,
    ModelFit,
    default_methods,
    fit,
    is_flight_method,
    traits,
    tunnel_methods,
)
from identification.methods.steps import IdentificationError
from identification.model import RollParams
from identification.recordings.recording import Recording, RecordingError, load_recording
from identification.reports.tables import scaling_line
from rocketroll_common.tables import Column, text_table


def thinned(rec: Recording, every: int) -> Recording:
    """``rec`` with every ``every``-th reading kept (the first kept)."""
    if every == 1:
        return rec
    return Recording(
        name=rec.name,
        source=rec.source,
        metadata=rec.metadata,
        **{name: values[::every] for name, values in rec.columns().items()},
    )


def parse_truth(text: str) -> dict[str, float]:
    """``alpha=3.39,a=9.55`` -> ``{"alpha": 3.39, "a": 9.55}`` (``theta_bar`` too)."""
    out: dict[str, float] = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        if key.strip() not in ("alpha", "a", "theta_bar") or not value:
            raise argparse.ArgumentTypeError(
                f"--truth {text!r}: give alpha=, a= and/or theta_bar= (comma-separated)"
            )
        out[key.strip()] = float(value)
    return out


def truth_of(
    rec: Recording, given: dict[str, float] | None, v_ref_mps: float | None = None
) -> dict[str, float]:
    """The truth to score against: ``--truth``, else the recording's ``truth.*`` (a
    virtual flight's at ``v_ref_mps``, the fit's reference)."""
    if given:
        return given
    params = rec.truth()
    if params is None:
        return {}
    if v_ref_mps is not None and "truth.v_ref_mps" in rec.metadata:
        from identification.instruments.flightlog import truth_at

        params = truth_at(rec, v_ref_mps)
    out = {"alpha": params.alpha, "theta_bar": params.theta_bar_deg}
    if params.is_constant_damping:
        out["a"] = params.beta_bar_per_s
    return out


def _errors(params: RollParams, model: str, truth: dict[str, float]) -> str:
    parts = []
    if "alpha" in truth:
        parts.append(f"α {100 * (params.alpha / truth['alpha'] - 1):+6.2f} %")
    if "theta_bar" in truth:
        parts.append(f"θ̄ {params.theta_bar_deg - truth['theta_bar']:+6.2f}°")
    if "a" in truth and model == "constant":
        parts.append(f"a {100 * (params.beta_bar_per_s / truth['a'] - 1):+6.2f} %")
    return "  ".join(parts)


#: One fit per line: the parameters, α's standard error and the adequacy figures.
FIT_COLUMNS = (
    Column("method", 13, "<", "  "),
    Column("model", 9, "<"),
    Column("α", 9),
    Column("α SE", 8),
    Column("θ̄ °", 8),
    Column("a or β̄", 9),
    Column("ᾱ", 9),
    Column("rate R²", 9),
    Column("ahead", 7),
    Column("fin→u_d", 8),
    Column("|u_d|/rng", 10),
    Column("verdict", 0, "<", "  "),
)


def _value(value: float | None, fmt: str) -> str:
    return "" if value is None or not np.isfinite(value) else format(value, fmt)


def _finite(value: float | None) -> bool:
    return value is not None and bool(np.isfinite(value))


def _emit_fit(
    name: str, model: str, found: ModelFit, truth: Mapping[str, float], flight: bool
) -> None:
    """State one fit's figures: α's error (α where no truth is known) and, of the constant
    model, a's; a flight's measured scaling exponents.  Non-finite figures are left out."""
    p, a = found.params, found.metrics["adequacy"]
    se = (found.metrics.get("std_errors") or {}).get("alpha")
    model_name = f"{'θ' if model == 'theta' else model} model"
    note = f"α {p.alpha:.3f}; verdict {a['verdict']}"
    if _finite(se):
        note += f"; α SE {se:.3f}"
    if "theta_bar" in truth:
        note += f"; θ̄ {p.theta_bar_deg - truth['theta_bar']:+.2f}° off the truth's"
    if flight:
        note += f"; at V_ref {found.metrics.get('v_ref_mps'):.1f} m/s"
    if "alpha" in truth:
        figure, value, unit = "α error", 100 * (p.alpha / truth["alpha"] - 1), "%"
    else:
        figure, value, unit = "α", p.alpha, ""
    if _finite(value):
        emit(f"{name}: {figure} ({model_name})", value, unit, note=note)
    a_value = p.beta_bar_per_s
    if model == "constant" and _finite(a_value):
        if "a" in truth:
            a_error = 100 * (a_value / truth["a"] - 1)
            if _finite(a_error):
                emit(
                    f"{name}: a error (constant model)",
                    a_error,
                    "%",
                    note=f"a {a_value:.2f} 1/s against the truth's {truth['a']:g}",
                )
        elif not truth:
            emit(f"{name}: a (constant model)", a_value, "1/s", note=f"verdict {a['verdict']}")
    if flight and found.metrics.get("scaling_measured"):
        errors = found.metrics.get("std_errors") or {}
        test = found.metrics.get("eq_4_8_test")
        said = (
            "" if not test else "; eq. 4-8 " + ("rejected" if test["rejected"] else "not rejected")
        )
        for key, symbol in (("torque_exponent", "n"), ("damping_exponent", "m")):
            exponent = found.metrics.get(key, float("nan"))
            if _finite(exponent):
                emit(
                    f"{name}: {key.replace('_', ' ')} {symbol} ({model_name})",
                    exponent,
                    "",
                    note=f"± {errors.get(key, float('nan')):.3f}{said}",
                )


def torque_regression(rec: Recording, window: Sequence[float]) -> dict[str, float]:
    """An independent fit of a flight's fin torque per dynamic pressure, outside the
    project's roll model: over ``window`` (s), the gyro's rate differentiated (a
    Savitzky-Golay filter over 0.1 s) regressed by ordinary least squares on ``q·δ``,
    ``ρV·p`` and ``q`` (ISA density at the logged altitude), with Newey-West standard
    errors (statsmodels, lags over 0.25 s).  The coefficient of ``q·δ`` is the torque per
    degree and pascal, (°/s²)/(°·Pa): the flight method's ``torque_per_q`` where the torque
    grows as ``q``."""
    import statsmodels.api as sm
    from scipy.signal import savgol_filter

    from identification.recordings.flight import site_elevation
    from rocketroll_physics.atmosphere import isa

    time_s = np.asarray(rec.time_s)
    keep = (time_s >= window[0]) & (time_s <= window[1])
    rate = np.asarray(rec.roll_rate_dps, dtype=float)
    fin = np.asarray(rec.fin_deg if rec.fin_deg is not None else rec.fin_cmd_deg, dtype=float)
    speed = np.asarray(rec.airspeed_mps, dtype=float)
    height = (
        np.asarray(rec.altitude_m, dtype=float) + site_elevation(rec)
        if rec.altitude_m is not None
        else np.zeros_like(speed)
    )
    rho = np.asarray(isa(height).density_kgm3, dtype=float)
    q = 0.5 * rho * speed**2
    span = max(5, round(0.1 / rec.dt_s) | 1)
    accel = savgol_filter(rate, span, 2, deriv=1, delta=rec.dt_s)
    design = np.column_stack([q * fin, rho * speed * rate, q])[keep]
    lags = max(1, round(0.25 / rec.dt_s))
    found = sm.OLS(accel[keep], design).fit(cov_type="HAC", cov_kwds={"maxlags": lags})
    return {
        "torque_per_q": float(found.params[0]),
        "se": float(found.bse[0]),
        "r2": float(found.rsquared),
        "n": int(keep.sum()),
    }


def _torque_lines(rec: Recording, found: ModelFit) -> list[str]:
    """The flight fit's fin torque per dynamic pressure (its interval) against the
    independent regression's (:func:`torque_regression`) on the window it fitted, and
    against a virtual flight's truth at the fit's reference, where the recording has one."""
    interval = (found.metrics.get("intervals") or {}).get("torque_per_q")
    if not interval or rec.roll_rate_dps is None:
        return []
    ols = torque_regression(rec, found.metrics["fitted_s"])
    low, high = ols["torque_per_q"] - 1.96 * ols["se"], ols["torque_per_q"] + 1.96 * ols["se"]
    covers = interval["low"] <= low and high <= interval["high"]
    line = (
        f"fin torque per q: {interval['estimate']:.4g} [{interval['low']:.4g}, "
        f"{interval['high']:.4g}] ({interval['method']}); independent least squares on the "
        f"same window {ols['torque_per_q']:.4g} ± {ols['se']:.2g} (R² {ols['r2']:.3f}, "
        f"{ols['n']} samples): the fit's interval {'covers' if covers else 'does not cover'} "
        "its 95 % interval"
    )
    if rec.truth() is not None and "truth.v_ref_mps" in rec.metadata:
        from identification.instruments.flightlog import truth_at
        from identification.methods.flightfit import c_coefficients

        reference = (found.metrics["v_ref_mps"], found.metrics["rho_ref_kgm3"])
        true = c_coefficients(truth_at(rec, *reference), *reference)["torque_per_q"]

        def holds(lo: float, hi: float) -> str:
            return "holds" if lo <= true <= hi else "misses"

        line += (
            f"; the truth {true:.4g}: the fit's interval {holds(interval['low'], interval['high'])}"
            f" it, the least squares' {holds(low, high)} it"
        )
    return [line]


def report(
    rec: Recording, methods: Sequence[str], given: dict[str, float] | None, where: str = ""
) -> None:
    """Print every method's fits of ``rec`` (a flight's by the flight methods); state each
    fit's figures as ``where``'s (e.g. ``100 Hz``)."""
    print(f"\n{rec!r}")
    if rec.is_flight:
        methods = [m for m in default_methods(rec) if is_flight_method(m)]
    truth = truth_of(rec, given)
    if truth and not rec.is_flight:
        print("  truth: " + ", ".join(f"{k} = {v:g}" for k, v in truth.items()))
    print(text_table(FIT_COLUMNS, [])[0])
    context = Context(rec)
    for method in methods:
        started = time.perf_counter()
        try:
            fits = fit(context, method, traits(method).models)
        except (IdentificationError, ValueError) as exc:  # this method cannot: say why
            print(f"  {method:13}cannot fit it: {exc}")
            continue
        seconds = time.perf_counter() - started
        for model, found in fits.items():
            p, a = found.params, found.metrics["adequacy"]
            se = (found.metrics.get("std_errors") or {}).get("alpha")
            cells = [
                method,
                model,
                f"{p.alpha:.4f}",
                _value(se, ".4f"),
                f"{p.theta_bar_deg:.3f}",
                f"{p.beta_bar_per_s:.4f}",
                f"{p.alpha_bar_per_deg_s:.4f}",
                _value(a["rate_r2"], ".3f"),
                _value(a["ahead_r2"], ".3f"),
                _value(a["fin_share"], ".2f"),
                _value(a["ud_range_fraction"], ".2f"),
                a["verdict"],
            ]
            print(text_table(FIT_COLUMNS, [cells])[1])
            reference = found.metrics.get("v_ref_mps")
            if rec.is_flight:
                print(f"  {'':22}at V_ref {reference:.1f} m/s; {scaling_line(found.metrics)}")
                truth = truth_of(rec, given, reference)
            if truth:
                print(f"  {'':22}error: {_errors(p, model, truth)}")
            for reason in a["reasons"]:
                print(f"  {'':22}{reason}")
            for finding in (a.get("diagnosis") or {}).get("findings", ()):
                print(f"  {'':22}why: {finding['text']}")
            if rec.is_flight:
                for line in _torque_lines(rec, found):
                    print(f"  {'':22}{line}")
            _emit_fit(f"{where}, {method}" if where else method, model, found, truth, rec.is_flight)
        print(f"  {'':22}({seconds:.2f} s for both models)")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="benchmarks/real_data.py", description=__doc__.split("\n\n")[0]
    )
    parser.add_argument("recording", nargs="+", type=Path, help="recording files (format v1)")
    parser.add_argument(
        "--every",
        type=int,
        action="append",
        help="keep every N-th reading (repeatable; default 1: as recorded)",
    )
    parser.add_argument(
        "--methods",
        default=",".join(tunnel_methods()),
        help="comma-separated methods (default: %(default)s)",
    )
    parser.add_argument("--truth", type=parse_truth, help="alpha=..,a=..,theta_bar=..")
    args = parser.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    unknown = [m for m in methods if m not in tunnel_methods()]
    if unknown:
        parser.error(
            f"--methods: {unknown[0]!r} is not a tunnel method ({', '.join(tunnel_methods())})"
        )
    for every in args.every or [1]:
        if every < 1:
            parser.error(f"--every {every}: must be 1 or more")
    for path in args.recording:
        try:
            rec = load_recording(path)
        except (OSError, RecordingError) as exc:
            print(f"benchmarks/real_data.py: {path}: {exc}", file=sys.stderr)
            return 2
        for every in args.every or [1]:
            try:
                sampled = thinned(rec, every)
            except RecordingError as exc:
                print(f"benchmarks/real_data.py: {path} --every {every}: {exc}", file=sys.stderr)
                return 2
            rate = f"{1 / sampled.dt_s:g} Hz"
            where = f"{path}, {rate}" if len(args.recording) > 1 else rate
            report(sampled, methods, args.truth, where)
    return 0


if __name__ == "__main__":
    sys.exit(main())
