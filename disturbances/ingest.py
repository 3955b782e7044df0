"""From an identification to database rows (no SQL here).

:func:`identification_rows` turns one
:class:`~identification.pipeline.Identification` into a recording row, one
identification row per method and model, and one ``u_d`` trace per
identification:

* ``paper``: the pipeline's own parameters and traces (steps 6-8) with its
  fit metrics (R², re-simulation errors, the noise study, the per-step table);
* ``output-error``: the peer of :mod:`identification.baselines`, fitted on the
  same measurements; its ``u_d`` is recovered with the same step 8
  (eq. 35-44) under its own parameters, and re-simulated the same way, so the
  two methods' traces and metrics compare like for like.

:func:`surrogate_rows` makes surrogate traces of a trace
(:mod:`disturbances.surrogate`), each checked against its source.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

from disturbances.db import now, package_version
from disturbances.rows import (
    METHODS,
    MODELS,
    SURROGATE_KINDS,
    IdentificationRow,
    RecordingRow,
    TraceRow,
    checksum,
    identified_uid,
    surrogate_uid,
)
from identification.pipeline import Identification
from identification.statistics import trace_statistics
from identification.steps import Disturbance, Resimulation, identify_disturbance, resimulate

__all__ = ["identification_rows", "surrogate_rows", "trace_summary"]


def trace_summary(u_d_deg: np.ndarray) -> dict[str, Any]:
    """Mean, SD, 90 % interval and normality p-value of a trace (§3.4)."""
    st = trace_statistics(u_d_deg)
    return {
        "mean_deg": st.mean_deg,
        "sd_deg": st.sd_deg,
        "q05_deg": st.q05_deg,
        "q95_deg": st.q95_deg,
        "normality_p": st.lilliefors_p,
    }


def _resimulation_metrics(r: Resimulation) -> dict[str, float]:
    return {
        "resim_rate_mae_dps": r.rate_mae_dps,
        "resim_rate_sd_dps": r.rate_sd_dps,
        "resim_angle_mae_deg": r.angle_mae_deg,
        "resim_angle_sd_deg": r.angle_sd_deg,
    }


def _trace_row(recording_hash: str, method: str, dist: Disturbance, created_at: str) -> TraceRow:
    u = np.asarray(dist.u_d_deg, dtype=float)
    return TraceRow(
        uid=identified_uid(recording_hash, method, dist.model),
        recording_hash=recording_hash,
        method=method,
        model=dist.model,
        kind="identified",
        source_uid=None,
        seed=None,
        settings={"interval_s": dist.interval_s, "equations": "35-44"},
        dt_s=dist.interval_s,
        t0_s=float(dist.start_s[0]),
        u_d_deg=u,
        checksum=checksum(u),
        statistics=trace_summary(u),
        validation=None,
        created_at=created_at,
    )


def identification_rows(
    result: Identification, methods: Sequence[str] = METHODS
) -> tuple[RecordingRow, list[IdentificationRow], list[TraceRow]]:
    """Rows for a recording, its identifications by ``methods`` and their traces.

    Parameters
    ----------
    result : Identification
        The paper's pipeline on one recording.
    methods : sequence of str
        ``paper`` (required: it is what the recording was identified with)
        and optionally ``output-error``.
    """
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown method(s) {unknown}; use {', '.join(METHODS)}")
    if "paper" not in methods:
        raise ValueError("methods must include 'paper'")
    stamp = now()
    version = package_version()
    recording = RecordingRow.of(result.recording, added_at=stamp)
    options = {k: v for k, v in dataclasses.asdict(result.options).items() if k != "progress"}
    details = result.to_dict()
    common = {
        "n_steps": result.segments.n_steps,
        "sources": details["sources"],
        "steady_state_r2": result.steady.r_squared,
        "beta_dps": result.steady.beta_dps,
        "piecewise_rms_deg": result.piecewise.rms_deg,
    }
    identifications: list[IdentificationRow] = []
    traces: list[TraceRow] = []
    for model in MODELS:
        metrics: dict[str, Any] = {
            **common,
            **_resimulation_metrics(result.resimulations[model]),
            "steps": details["steps"],
        }
        if model == "constant":
            metrics["damping_fit_rms_dps"] = result.damping.rms_dps
            metrics["noise_study"] = details["noise_study"]
        else:
            metrics["damping_vs_fin_r2"] = result.damping_vs_fin.r_squared
            metrics["damping_vs_fin"] = details["damping_vs_fin"]
        identifications.append(
            IdentificationRow(
                recording.content_hash,
                "paper",
                model,
                result.model(model),
                metrics,
                options,
                version,
                stamp,
            )
        )
        traces.append(
            _trace_row(recording.content_hash, "paper", result.disturbances[model], stamp)
        )
    if "output-error" in methods:
        from identification.baselines import output_error

        for model in MODELS:
            fit = output_error(result.recording, model, options=result.options)
            dist = identify_disturbance(
                fit.params,
                model,
                result.grid,
                result.theta_fine,
                result.velocity_fine,
                interval_s=result.options.ud_interval_s,
            )
            resim = resimulate(
                dist,
                result.recording,
                result.grid,
                result.theta_fine,
                result.velocity_dps,
                result.angle_deg,
            )
            metrics = {
                **common,
                **_resimulation_metrics(resim),
                "rate_rmse_dps": fit.rate_rmse_dps,
                "nfev": fit.nfev,
                "converged": fit.success,
                "optimizer_message": fit.message,
            }
            identifications.append(
                IdentificationRow(
                    recording.content_hash,
                    "output-error",
                    model,
                    fit.params,
                    metrics,
                    options,
                    version,
                    stamp,
                )
            )
            traces.append(_trace_row(recording.content_hash, "output-error", dist, stamp))
    return recording, identifications, traces


def surrogate_rows(
    source: TraceRow, kinds: Sequence[str], count: int, seed: int = 0
) -> list[TraceRow]:
    """``count`` surrogates of each kind in ``kinds`` made from ``source``.

    Surrogate ``k`` has seed ``seed + k``; its generator is seeded with that
    seed and the source's checksum, so the same source and seed always give
    the same surrogate and different sources give independent ones.  Each
    is checked against its source (two-sample KS of the marginals, Welch
    PSD log-distance); the check is stored with it.
    """
    from disturbances.surrogate import check_surrogate, make_surrogate

    if count < 0:
        raise ValueError(f"count must be non-negative, got {count}")
    unknown = [k for k in kinds if k not in SURROGATE_KINDS]
    if unknown:
        raise ValueError(f"unknown surrogate kind(s) {unknown}; use {', '.join(SURROGATE_KINDS)}")
    rows: list[TraceRow] = []
    stamp = now()
    entropy = int(source.checksum[:16], 16)
    for kind in kinds:
        for k in range(count):
            s = seed + k
            rng = np.random.default_rng([s, entropy])
            made = make_surrogate(source.u_d_deg, kind, rng)
            u = np.asarray(made.u_d_deg, dtype=float)
            check = check_surrogate(source.u_d_deg, u, source.dt_s)
            rows.append(
                TraceRow(
                    uid=surrogate_uid(source.uid, kind, s),
                    recording_hash=source.recording_hash,
                    method=source.method,
                    model=source.model,
                    kind=kind,
                    source_uid=source.uid,
                    seed=s,
                    settings=dict(made.settings),
                    dt_s=source.dt_s,
                    t0_s=source.t0_s,
                    u_d_deg=u,
                    checksum=checksum(u),
                    statistics=trace_summary(u),
                    validation=check.to_dict(),
                    created_at=stamp,
                )
            )
    return rows
