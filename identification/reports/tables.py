"""Text tables of identification results (what ``rocketroll identify`` prints)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from identification import paper
from identification.methods import ModelFit
from identification.methods.adequacy import FIN_ERROR_MATERIAL
from identification.methods.pipeline import Identification
from rocketroll_common.tables import Column, text_table

__all__ = [
    "adequacy_table",
    "flight_table",
    "interval_table",
    "methods_table",
    "parameter_table",
    "scaling_line",
]


def parameter_table(result: Identification) -> str:
    """The text ``rocketroll identify`` prints: parameters, fits, disturbance."""
    rec = result.recording
    truth = result.truth()
    reference = {key: paper.value(key) for key in paper.PARAMETERS}
    labels = {
        "alpha": "α (°/s)/°          eq. 16",
        "beta_dps": "β °/s              eq. 16",
        "theta_bar_deg": "θ̄ °               eq. 30",
        "steady_state_r2": "steady-state R²    eq. 16",
        "a_per_s": "a 1/s (constant)   eq. 26",
        "b_per_s2": "b = aα             eq. 30",
        "alpha_bar_per_deg_s": "ᾱ 1/(s·°)          eq. 48",
        "beta_bar_per_s": "β̄ 1/s              eq. 48",
        "damping_vs_fin_r2": "a(θ) R²            eq. 48",
    }
    kind = "synthetic: virtual wind tunnel" if rec.source == "synthetic" else rec.source
    lines = [
        f"{rec.name} ({kind}): {rec.n_samples} samples every {rec.dt_s:g} s, "
        f"{result.segments.n_steps} fin steps",
        f"  angle: {result.angle_source}; velocity: {result.velocity_source}",
        f"  fin angle: {result.theta_source}",
        "",
    ]
    rows = []
    for key, value in result.parameters().items():
        true = "" if truth is None or key not in truth else f"{truth[key]:.4g}"
        if truth is not None and key in ("a_per_s", "b_per_s2") and true:
            true += "*"
        rows.append([labels[key], f"{value:.4g}", true, f"{reference[key]:.4g}"])
    columns = (
        Column("parameter", 26, "<", display=True),
        Column("identified", 12),
        Column("truth" if truth else "", 12),
        Column("paper", 10),
    )
    lines += text_table(columns, rows)
    if truth is not None and truth["alpha_bar_per_deg_s"] != 0.0:
        lines.append("  * θ-dependent truth: a(θ) averaged over the step fin levels")
    dvf = result.damping_vs_fin
    if dvf.outlier is not None:
        lines.append(
            f"  a(θ): step {dvf.outlier + 1} left out as an outlier (Bonferroni p = "
            f"{dvf.outlier_p:.3g})"
        )
    if dvf.excluded:
        steps = ", ".join(str(i + 1) for i in dvf.excluded)
        lines.append(f"  a(θ): step(s) {steps} left out, a_i <= 0 is not a damping")
    lines += ["", *_steps_table(result)]
    lines += ["", *_resimulation_table(result)]
    st = result.statistics
    lines += ["", *_disturbance_table(result)]
    lines.append(f"two-sample KS between them: p = {st.ks_p:.3g}")
    if rec.ud_true_deg is not None:
        q05, q95 = np.percentile(rec.ud_true_deg, [5, 95])
        lines.append(f"true u_d (synthetic): 90 % interval [{q05:.2f}, {q95:.2f}]")
    if result.noise is not None:
        n = result.noise
        lines += ["", f"noise study (§3.3): {n.runs} runs per level, seed {n.seed}"]
        lines += text_table(
            (Column("η %", 8, "<"), Column("u_d MAE °", 10), Column("P90 °", 9)),
            (
                [f"{eta:g}", f"{mae:.3f}", f"{p90:.3f}"]
                for eta, mae, p90 in zip(n.levels_pct, n.mae_deg, n.p90_deg, strict=True)
            ),
        )
    return "\n".join(lines)


def _steps_table(result: Identification) -> list[str]:
    """Per fin step: its start, level, steady rate, delay and damping (steps 2-5)."""
    seg, outlier = result.segments, result.damping_vs_fin.outlier
    columns = (
        Column("step", 4),
        Column("start s", 9),
        Column("fin °", 8),
        Column("v_ss °/s", 11),
        Column("t0 s", 7),
        Column("a_i 1/s", 10),
        Column("", 0, "<"),
    )
    rows = (
        [
            f"{i + 1}",
            f"{seg.time_s[i]:.1f}",
            f"{seg.step_levels_deg[i]:.2f}",
            f"{result.piecewise.slopes_dps[i]:.2f}",
            f"{result.bilinear.t0_s[i]:.2f}",
            f"{result.damping.a_steps_per_s[i]:.3f}",
            "  outlier" if outlier == i else "",
        ]
        for i in range(seg.n_steps)
    )
    return text_table(columns, rows)


def _resimulation_table(result: Identification) -> list[str]:
    """Each model's re-simulation errors (§3.5)."""
    columns = (
        Column("re-simulation (§3.5)", 22, "<"),
        Column("rate MAE / SD °/s", 22, "<"),
        Column("angle MAE / SD °", 0, "<"),
    )
    rows = (
        [
            f"{name} damping",
            f"{r.rate_mae_dps:9.3f} / {r.rate_sd_dps:.3f}",
            f"{r.angle_mae_deg:7.3f} / {r.angle_sd_deg:.3f}",
        ]
        for name, r in result.resimulations.items()
    )
    return text_table(columns, rows)


def _disturbance_table(result: Identification) -> list[str]:
    """Both models' ``u_d``: its 90 % interval and normality (§3.4)."""
    st = result.statistics
    columns = (
        Column("disturbance u_d (§3.4)", 23, "<"),
        Column("90 % interval °", 16, "<"),
        Column("Lilliefors p", 15),
        Column("normal", 0, "<", gap="   "),
    )
    rows = (
        [
            f"u_d,{name}",
            f"[{trace.q05_deg:6.2f}, {trace.q95_deg:6.2f}]",
            f"{trace.lilliefors_p:.3g}",
            "yes" if trace.normal else "no",
        ]
        for name, trace in (("theta", st.theta), ("constant", st.constant))
    )
    return text_table(columns, rows)


def methods_table(fits: Mapping[str, Mapping[str, ModelFit]]) -> str:
    """Every method's parameters per model, side by side, with its re-simulation errors.

    ``fits`` is ``{method: {model: ModelFit}}`` (:func:`identification.methods.fit`).
    """
    rows = [
        [
            method,
            model,
            f"{f.params.alpha:.4f}",
            f"{f.params.theta_bar_deg:.3f}",
            f"{f.params.beta_bar_per_s:.4f}",
            f"{f.params.alpha_bar_per_deg_s:.4f}",
            _blank(f.metrics.get("resim_rate_mae_dps"), ".3f"),
            _blank(f.metrics.get("resim_angle_mae_deg"), ".3f"),
        ]
        for method, by_model in fits.items()
        for model, f in by_model.items()
    ]
    return "\n".join(text_table(_METHOD_COLUMNS, rows) + _beyond_lines(fits))


#: The method and the model that begin each row of the methods' tables.
_FIT = (Column("method", 14, "<"), Column("model", 10, "<"))
_METHOD_COLUMNS = (
    *_FIT,
    Column("α (°/s)/°", 11),
    Column("θ̄ °", 9),
    Column("β̄ or a 1/s", 13),
    Column("ᾱ 1/(s·°)", 12),
    Column("rate MAE °/s", 14),
    Column("angle MAE °", 13),
)
_ADEQUACY_COLUMNS = (
    *_FIT,
    Column("rate R²", 9),
    Column("ahead R²", 10),
    Column("fin→u_d", 9),
    Column("|u_d|/range", 13),
    Column("α SE %", 8),
    Column("verdict", gap="  "),
)


def _beyond_lines(fits: Mapping[str, Mapping[str, ModelFit]]) -> list[str]:
    """Below the parameters: a sensors' latency a method found, and each searched quadratic
    damping, kept in the fit or not."""
    lines = []
    late_by: dict[float, tuple[dict[str, Any], list[str]]] = {}
    for method, by_model in fits.items():
        for f in by_model.values():
            late = f.metrics.get("sensor_latency") or {}
            if late.get("admitted"):
                found = late_by.setdefault(float(late["estimate_s"]), (late, []))[1]
                if method not in found:
                    found.append(method)
    for seconds, (late, methods) in late_by.items():
        lines.append(
            f"  the roll sensors read {1000 * seconds:.0f} ms late (the likelihood's search: "
            f"LR {late['statistic']:.1f}, p = {late['p']:.2g}; searched to "
            f"{late['searched_s'][1]:g} s): {' and '.join(methods)} fitted on the fin delayed "
            f"by it. The other methods read it where stated: --sensor-latency {seconds:g}"
        )
    for method, by_model in fits.items():
        for model, f in by_model.items():
            term = f.metrics.get("quadratic_damping")
            if not term:
                continue
            low, high = term["interval"]
            kept = (
                "kept in the fit" if term["admitted"] else f"not admitted at p < {term['level']:g}"
            )
            lines.append(
                f"  {method} {model}: quadratic damping q = {term['estimate']:.3g} "
                f"(95 % [{low:.2g}, {high:.2g}], × a(θ) at {term['rate_dps']:g} °/s; "
                f"LR {term['statistic']:.1f}, p = {term['p']:.2g}): {kept}"
            )
    return lines


def adequacy_table(fits: Mapping[str, Mapping[str, ModelFit]]) -> str:
    """Each fit's adequacy (:mod:`identification.methods.adequacy`): the model without ``u_d``
    against the raw rate, its prediction a time constant ahead, the share of ``u_d``
    the fin explains, ``|u_d|`` against the fins' range, α's standard error, and the
    verdict with its reasons below the table.  Fits without figures are left out."""
    rows, reasons = [], []
    why: dict[str, list[str]] = {}  # each finding on the log, with the fits that make it
    for method, by_model in fits.items():
        for model, f in by_model.items():
            a = f.metrics.get("adequacy")
            if not a:
                continue
            for finding in (a.get("diagnosis") or {}).get("findings", ()):
                why.setdefault(finding["text"], []).append(f"{method} {model}")
            se = None if a["alpha_rel_se"] is None else 100 * a["alpha_rel_se"]
            rows.append(
                [
                    method,
                    model,
                    _blank(a["rate_r2"], ".3f"),
                    _blank(a["ahead_r2"], ".3f"),
                    _fin_share_cell(a),
                    _blank(a["ud_range_fraction"], ".2f"),
                    _blank(se, ".1f"),
                    a["verdict"],
                ]
            )
            reasons += [f"  {method} {model}: {reason}" for reason in a["reasons"]]
            reasons += [f"  {method} {model}: suspected: {s}" for s in a.get("suspected") or ()]
    for text, where in why.items():
        by = "" if len(where) == len(rows) else f" ({', '.join(where)})"
        reasons.append(f"  why{by}: {text}")
    return "\n".join(text_table(_ADEQUACY_COLUMNS, rows) + reasons)


_INTERVAL_COLUMNS = (
    *_FIT,
    Column("parameter", 20, "<"),
    Column("estimate", 11, gap=" "),
    Column("95 % low", 11, gap=" "),
    Column("95 % high", 11, gap=" "),
    Column("from", 8, "<", gap="  "),
    Column("the log determines it"),
)
#: What each end of an interval says, in a few words (identification.estimation.likelihood).
_END_WORDS = {"range": "the range ends first", "open": "not bounded"}


def _determined(interval: Mapping[str, Any]) -> str:
    """ "yes", or which side the log leaves open and why; where the likelihood has more than
    one optimum the data do not reject, each one's value too."""
    optima = interval.get("optima") or []
    basins = (
        f"{len(optima)} optima the data cannot tell apart, at "
        + ", ".join(f"{v:.3g}" for v in optima)
        if len(optima) > 1
        else ""
    )
    if interval.get("determined"):
        return f"yes ({basins})" if basins else "yes"
    sides = [
        f"{side}: {_END_WORDS.get(interval[f'{side}_end'], interval[f'{side}_end'])}"
        for side in ("low", "high")
        if interval[f"{side}_end"] != "likelihood"
    ]
    return "no (" + "; ".join(sides + ([basins] if basins else [])) + ")"


def _with_error(value: float, metrics: Mapping[str, Any], name: str) -> str:
    """``value ± SE`` where the Hessian gives an SE, else ``value [low, high]`` (its profile
    interval, the sides the log leaves open said)."""
    se = (metrics.get("std_errors") or {}).get(name, math.nan)
    if math.isfinite(se):
        return f"{value:.4f} ± {se:.4f}"
    interval = (metrics.get("intervals") or {}).get(name)
    if not interval:
        return f"{value:.4f} (no interval)"
    shown = f"{value:.4f} [{interval['low']:.4g}, {interval['high']:.4g}]"
    return shown if interval["determined"] else f"{shown} {_determined(interval)}"


def interval_table(fits: Mapping[str, Mapping[str, ModelFit]]) -> str:
    """Each fit's 95 % intervals (the ml and flight methods': the Hessian's where it is
    positive definite, the profile likelihood's where not or where asked) and whether the
    log determines each parameter; empty where no fit has intervals."""
    rows = []
    for method, by_model in fits.items():
        for model, f in by_model.items():
            for name, interval in (f.metrics.get("intervals") or {}).items():
                rows.append(
                    [
                        method,
                        model,
                        name,
                        f"{interval['estimate']:.5g}",
                        f"{interval['low']:.5g}",
                        f"{interval['high']:.5g}",
                        interval["method"],
                        _determined(interval),
                    ]
                )
    return "\n".join(text_table(_INTERVAL_COLUMNS, rows)) if rows else ""


def scaling_line(metrics: Mapping[str, Any]) -> str:
    """A flight fit's airspeed scaling: the exponents (measured, with their standard errors
    and eq. 4-8's test, or held) and the rocket carried to the tunnel's airspeed, in one
    line."""
    errors = metrics.get("std_errors") or {}
    n, m = metrics.get("torque_exponent", 2.0), metrics.get("damping_exponent", 1.0)
    if not metrics.get("scaling_measured"):
        return f"scaling held: fin torque ∝ ρV^{n:g}, damping ∝ ρV^{m:g}"
    nan = float("nan")
    n_se, m_se = errors.get("torque_exponent", nan), errors.get("damping_exponent", nan)
    text = (
        f"scaling measured: fin torque ∝ ρV^n, n {n:.3f} ± {n_se:.3f}; "
        f"damping ∝ ρV^m, m {m:.3f} ± {m_se:.3f}"
    )
    test = metrics.get("eq_4_8_test")
    if test:
        said = "rejected" if test["rejected"] else "not rejected"
        text += (
            f"; eq. 4-8 (n 2, m 1) {said} (likelihood ratio {test['statistic']:.3g}, "
            f"p {test['p_value']:.3g})"
        )
    tunnel = metrics.get("at_tunnel_airspeed")
    if tunnel:
        text += (
            f"; carried to {tunnel['v_ref_mps']:.2f} m/s by it: α {tunnel['alpha']:.4f}, "
            f"β̄ {tunnel['beta_bar_per_s']:.4f} 1/s"
        )
    return text


def flight_table(fits: Mapping[str, Mapping[str, ModelFit]]) -> str:
    """A flight's identification (``rocketroll identify``): per model the coefficients at
    the reference airspeed, the scaling (:func:`scaling_line`), the held-out check and what
    the model's limits left out; then the methods' table."""
    lines = []
    for by_model in fits.values():
        for model, f in by_model.items():
            m = f.metrics
            verdict = (m.get("adequacy") or {}).get("verdict")
            judged = f" [{verdict}]" if verdict else ""
            lines.append(
                f"{f.method} {model}{judged}: at V_ref {m['v_ref_mps']:.2f} m/s, ρ_ref "
                f"{m['rho_ref_kgm3']:.4f} kg/m³ (in flight: {m['density']}): "
                f"α₀ {_with_error(f.params.alpha, m, 'alpha')}, "
                f"β̄₀ {_with_error(f.params.beta_bar_per_s, m, 'beta_bar_per_s')} 1/s; "
                f"C_P-like β̄₀/(ρV) {m['damping_per_rho_v']:.5g} m²/kg, "
                f"C_δ-like β̄₀α₀/q {m['torque_per_q']:.5g} (°/s²)/(°·Pa); "
                f"re-simulated rate MAE {m['resim_rate_mae_pct']:.2f} % of mean |rate|"
            )
            lines.append(f"  {scaling_line(m)}")
            held = (m.get("adequacy") or {}).get("held_out") or {}
            if "rate_r2" in held:
                full = held.get("full_fit_rate_r2")
                lines.append(
                    f"  held out: fitted to {held['from_s']:.2f} s, the model without u_d "
                    f"predicts the rest to rate R² {held['rate_r2']:.3f}"
                    + (f" (the whole flight's fit: {full:.3f})" if full is not None else "")
                )
            elif "skipped" in held:
                lines.append(f"  held out: not checked: {held['skipped']}")
            if m.get("descent_excluded_s"):
                lines.append(
                    f"  left out {m['descent_excluded_s']:.2f} s after apogee (falling, the "
                    "rocket no longer flies into the flow its fins were identified in)"
                )
            if m.get("supersonic_excluded_s"):
                first, last = m["fitted_s"]
                lines.append(
                    f"  left out {m['supersonic_excluded_s']:.2f} s above Mach 0.8 (the roll "
                    f"model is subsonic): fitted {first:.2f}-{last:.2f} s "
                    "(--include-supersonic fits them too)"
                )
            if m.get("fitted_with"):
                lines.append(
                    f"  fitted together with {len(m['fitted_with'])} other flight(s): "
                    + ", ".join(m["fitted_with"])
                )
    return (
        "flight identification (fin torque ∝ ρV^n, damping a ∝ ρV^m: α ∝ V^(n-m))\n"
        + "\n".join(lines)
        + "\n\n"
        + (methods_table(fits))
    )


def _fin_share_cell(adequacy: Mapping[str, Any]) -> str:
    """The share of ``u_d`` a line in the fin explains, or ``noise`` where ``u_d`` is too
    small beside the fin for any share of it to matter: its SD under
    :data:`~identification.methods.adequacy.FIN_ERROR_MATERIAL` of the fin's, where the share is
    the R² of a regression on rounding noise and differs from machine to machine."""
    share, ratio = adequacy.get("fin_share"), adequacy.get("fin_error_ratio")
    if share is None:
        return ""
    if ratio is not None and share > 0 and ratio / math.sqrt(share) < FIN_ERROR_MATERIAL:
        return "noise"
    return format(share, ".2f")


def _blank(value: float | None, fmt: str) -> str:
    """``value`` formatted, or nothing for a figure a fit does not have."""
    return "" if value is None else format(value, fmt)
