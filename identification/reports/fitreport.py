"""Every tunnel method's fit, judged: one figure per method and a ``report.md`` section
(``rocketroll identify REC --report DIR`` with any method).

The paper's report (:mod:`identification.reports.report`) re-creates the paper's figures
from its own pipeline; this one shows, for whichever methods ran, what the
adequacy (:mod:`identification.methods.adequacy`) judges, on one time axis:

1. the measured roll rate (the gyro's raw readings, or the velocity from the
   angle) and each damping model driven by the fin alone, ``u_d = 0``: a model
   that describes the rocket follows the rate's fin-driven part, and the
   turbulence is what is left;
2. the fin angle and each model's ``u_d``: a ``u_d`` that moves with the fin is
   model error, not turbulence; one beyond the fins' range is a disturbance the
   fins could not have made.

``report.md`` holds the parameter and adequacy tables ``rocketroll identify``
prints, each fit's verdict with its reasons, the standard errors and correlations of
its parameters where the method reports them, and links the figures.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from identification.methods import Context, ModelFit
from identification.methods.adequacy import model_only
from identification.reports.tables import adequacy_table, methods_table
from rocketroll_common.plotting import new_figure, png_bytes

__all__ = ["figure_name", "fit_section", "render_fit_report"]

_COLORS = {"constant": "tab:orange", "theta": "tab:green"}
_WIDTH_IN, _DPI = 10.0, 110


def figure_name(method: str) -> str:
    """The file of ``method``'s figure in the report's folder."""
    return f"fit-{method}.png"


def _figure(context: Context, method: str, by_model: Mapping[str, ModelFit]) -> bytes:
    rec = context.recording
    t = np.asarray(rec.time_s, dtype=float)
    fig = new_figure(figsize=(_WIDTH_IN, 6.5), layout="constrained")
    rate_ax, ud_ax = fig.subplots(2, 1, sharex=True)
    source = ""
    for model, found in by_model.items():
        inputs = context.measurements_of(found)
        predicted = model_only(inputs, found.params)
        if not source:
            source = predicted.rate_source
            rate_ax.plot(t, predicted.measured_rate_dps, color="0.6", lw=0.8,
                         label=f"measured ({source})")  # fmt: skip
        verdict = (found.metrics.get("adequacy") or {}).get("verdict", "not assessed")
        rate_ax.plot(t, predicted.rate_dps, color=_COLORS.get(model), lw=1.2,
                     label=f"{model} model, fin only: {verdict}")  # fmt: skip
        u = found.disturbance.at(t[:-1])
        ud_ax.step(t[:-1], u, where="post", color=_COLORS.get(model), lw=0.9,
                   label=f"u_d ({model})")  # fmt: skip
    inputs = context.measurements
    fin = np.asarray(inputs.theta_fine[:: inputs.grid.per_sample], dtype=float)
    ud_ax.plot(t[: fin.size], fin, color="black", lw=1.0, label=f"fin θ ({inputs.theta_source})")
    rate_ax.set_ylabel("roll rate (°/s)")
    rate_ax.set_title("the model driven by the fin alone (u_d = 0) against the measured rate")
    ud_ax.set_ylabel("angle (°)")
    ud_ax.set_xlabel("time (s)")
    ud_ax.set_title("u_d, the turbulence as an equivalent fin angle, beside the fin")
    for ax in (rate_ax, ud_ax):
        lo, hi = ax.get_ylim()
        ax.set_ylim(lo, hi + 0.3 * (hi - lo))  # room for the legend above the data
        ax.legend(loc="upper right", fontsize=8, ncol=2)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{method}: {rec.name} ({rec.source})", fontsize=10)
    return png_bytes(fig, dpi=_DPI)


def fit_section(context: Context, fits: Mapping[str, Mapping[str, ModelFit]]) -> str:
    """The report's markdown section on ``fits`` (``{method: {model: ModelFit}}``)."""
    lines = [
        "## Fit adequacy of each method",
        "",
        "Each method's parameters, and each fit judged by its model *without* `u_d` "
        "(`u_d` absorbs any model error, so a re-simulation with it says nothing about the "
        "model): R² of the rate from the fin alone, R² a time constant ahead, the share of "
        "`u_d` a line in the fin explains, `u_d`'s 99th percentile against the fins' range, "
        "α's standard error, and the verdict (good / weak / unreliable) with its reasons.",
        "",
        "```",
        methods_table(fits),
        "",
        adequacy_table(fits),
        "```",
        "",
    ]
    for method, by_model in fits.items():
        for model, found in by_model.items():
            a = found.metrics.get("adequacy") or {}
            reasons = "; ".join(a.get("reasons") or ()) or "no figure beyond its limits"
            lines.append(f"- **{method} {model}**: {a.get('verdict', 'not assessed')} — {reasons}")
            se = found.metrics.get("std_errors") or {}
            corr = found.metrics.get("correlations") or {}
            if se:
                lines.append(
                    "  standard errors: "
                    + ", ".join(f"{name} ±{value:.3g}" for name, value in se.items())
                    + (
                        "; correlations: "
                        + ", ".join(f"{pair} {value:+.2f}" for pair, value in corr.items())
                        if corr
                        else ""
                    )
                )
        lines += ["", f"![{method}]({figure_name(method)})", ""]
    return "\n".join(lines)


def render_fit_report(
    context: Context,
    fits: Mapping[str, Mapping[str, ModelFit]],
    paper_report: Mapping[str, str | bytes] | None = None,
) -> dict[str, str | bytes]:
    """The fit report's files as ``{file name: content}``, nothing written: a figure per
    method and ``report.md``.

    Parameters
    ----------
    context : Context
        The recording the methods ran on.
    fits : mapping
        ``{method: {model: ModelFit}}`` of tunnel methods (not flights).
    paper_report : mapping, optional
        The paper's report of the same recording
        (:func:`identification.reports.report.render_report`): its ``report.md`` gets the
        section, after its own; else the section has a title of its own.
    """
    if not fits:
        raise ValueError("no fits to report")
    rec = context.recording
    out: dict[str, str | bytes] = dict(paper_report or {})
    out.update(
        {figure_name(method): _figure(context, method, fits_of) for method, fits_of in fits.items()}
    )
    if paper_report is not None:
        head = str(paper_report["report.md"]).rstrip("\n") + "\n\n"
    else:
        head = (
            f"# Identification report: {rec.name}\n\nRecording `{rec.name}` ({rec.source}): "
            f"{rec.n_samples} samples every {rec.dt_s:g} s ({rec.duration_s:g} s).\n\n"
        )
    out["report.md"] = head + fit_section(context, fits) + "\n"
    return out
