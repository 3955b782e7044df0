"""End to end: ``identify(recording)`` on virtual-tunnel data with known ground truth.

Tolerances were set from what the method achieves on these seeds (measured, with the
numbers in the comments), with margin, so that a real regression fails them.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from identification.instruments.bundled import load_bundled
from identification.instruments.tunnel import PAPER_TABLE1, TunnelSpec, run_tunnel
from identification.methods.pipeline import Identification, IdentifyOptions, identify
from identification.methods.steps import IdentificationError
from identification.recordings.importer import import_csv
from identification.recordings.recording import Recording
from rocketroll_common.errors import SettingError

OPTS = IdentifyOptions(noise_runs=0)
PAPER_ALPHA, PAPER_BETA = 0.6590, 2.8856  # eq. 17
PAPER_UD_THETA_90 = (-13.38, 14.28)  # §3.2


@pytest.fixture(scope="module")
def seed0() -> Identification:
    return identify(load_bundled("tunnel-paper-seed0"), OPTS)


def true_alpha(rec: Recording) -> float:
    truth = rec.truth()
    assert truth is not None
    return truth.alpha


def check_sane(result: Identification, truth_alpha: float, rel: float = 0.05) -> None:
    """Finite parameters and disturbances, α near the truth."""
    assert result.steady.alpha == pytest.approx(truth_alpha, rel=rel)
    assert all(np.isfinite(v) for v in result.parameters().values())
    for name in ("constant", "theta"):
        assert np.all(np.isfinite(result.disturbances[name].u_d_deg))
        assert np.isfinite(result.resimulations[name].rate_mae_dps)
        assert np.isfinite(result.resimulations[name].angle_mae_deg)


# --------------------------------------------------------------------------- the paper's run


def test_seed0_steady_state_matches_eq_17(seed0: Identification) -> None:
    assert seed0.steady.r_squared >= 0.99  # the paper: 0.9914; seed 0: 0.9989
    assert seed0.steady.alpha == pytest.approx(PAPER_ALPHA, rel=0.03)  # seed 0: +2.8 %
    assert seed0.steady.beta_dps == pytest.approx(PAPER_BETA, abs=0.5)  # seed 0: 2.58
    assert seed0.steady.theta_bar_deg == pytest.approx(seed0.steady.beta_dps / seed0.steady.alpha)


def test_seed0_finds_the_eight_steps_of_table_1(seed0: Identification) -> None:
    times, levels = zip(*PAPER_TABLE1, strict=True)
    seg = seed0.segments
    assert seg.n_steps == 8
    np.testing.assert_allclose(seg.time_s, times, rtol=0, atol=1e-9)
    np.testing.assert_allclose(seg.step_levels_deg, levels, rtol=0, atol=1e-9)
    assert seg.end_s == pytest.approx(573.0)
    assert seg.fin_source == "fin_cmd_deg"


@pytest.mark.parametrize("model", ["constant", "theta"])
def test_seed0_resimulation_errors_are_within_the_papers(seed0: Identification, model: str) -> None:
    res = seed0.resimulations[model]
    # The paper (§3.5): 0.094 / 0.097 °/s and 0.13 / 0.18°.  Seed 0: 0.03-0.04 °/s, 0.13°.
    assert res.rate_mae_dps <= 0.10
    assert res.angle_mae_deg <= 0.20
    assert res.rate_dps.shape == seed0.recording.time_s.shape


def test_seed0_disturbance_interval_is_the_papers(seed0: Identification) -> None:
    st = seed0.statistics.theta
    # Seed 0: [-12.5, 13.6]° against the paper's [-13.38, 14.28]°.
    assert st.q05_deg == pytest.approx(PAPER_UD_THETA_90[0], abs=2.0)
    assert st.q95_deg == pytest.approx(PAPER_UD_THETA_90[1], abs=2.0)
    u = seed0.disturbances["theta"].u_d_deg
    assert u.size == 5730  # 573 s in 0.1 s intervals
    assert (st.q05_deg, st.q95_deg) == pytest.approx(tuple(np.percentile(u, [5, 95])))


def test_seed0_to_dict_is_json_and_carries_parameters_and_truth(seed0: Identification) -> None:
    d = seed0.to_dict()
    text = json.dumps(d, allow_nan=False)
    back = json.loads(text)
    assert back["parameters"] == pytest.approx(seed0.parameters())
    truth = seed0.truth()
    assert truth is not None and back["truth"] == pytest.approx(truth)
    assert back["truth"]["alpha"] == PAPER_ALPHA
    assert len(back["steps"]) == 8
    assert back["steps"][2]["fin_deg"] == pytest.approx(26.67)
    assert back["noise_study"] is None
    assert set(back["resimulation"]) == {"constant", "theta"}
    assert back["recording"]["seed"] == 0


def test_to_dict_with_a_noise_study_is_json() -> None:
    rec = load_bundled("tunnel-paper-seed1")
    result = identify(rec, IdentifyOptions(noise_runs=2, noise_levels_pct=(1.0, 10.0)))
    assert result.noise is not None
    d = json.loads(json.dumps(result.to_dict(), allow_nan=False))
    assert d["noise_study"]["runs"] == 2
    assert d["noise_study"]["levels_pct"] == [1.0, 10.0]


# --------------------------------------------------------------------------- ground truth

RECOVERY_SEEDS = range(6)


@pytest.fixture(scope="module")
def recovery() -> list[tuple[float, float]]:
    """(relative α error, θ̄ error in °) for each seed of the paper's run."""
    out = []
    for seed in RECOVERY_SEEDS:
        rec = run_tunnel(TunnelSpec(seed=seed))
        truth = rec.truth()
        assert truth is not None
        result = identify(rec, OPTS)
        out.append(
            (
                result.steady.alpha / truth.alpha - 1.0,
                result.steady.theta_bar_deg - truth.theta_bar_deg,
            )
        )
    return out


def test_alpha_and_theta_bar_are_recovered_over_seeds(recovery: list[tuple[float, float]]) -> None:
    # Measured on seeds 0-5: |α error| 0.7-2.8 % (mean 1.9 %, signed mean 0.0 %),
    # |θ̄ error| 0.17-0.69°.  The scatter is the turbulence averaged over each ~63 s step.
    alpha_err = np.array([a for a, _ in recovery])
    theta_bar_err = np.array([t for _, t in recovery])
    assert np.mean(np.abs(alpha_err)) < 0.03
    assert np.all(np.abs(alpha_err) < 0.04)
    assert abs(np.mean(alpha_err)) < 0.015  # no systematic bias
    assert np.all(np.abs(theta_bar_err) < 1.0)


def test_student_t_turbulence_is_flagged_non_normal() -> None:
    # Measured: Student-t(3) flagged in 8 of 8 seeds, Gaussian in 1 of 8 (seed 5, p = 0.049).
    heavy = [
        identify(run_tunnel(TunnelSpec(seed=s, turbulence="student-t", dof=3)), OPTS)
        for s in range(8)
    ]
    gauss = [identify(run_tunnel(TunnelSpec(seed=s)), OPTS) for s in range(8)]
    assert sum(r.statistics.theta.normal is False for r in heavy) >= 6
    assert sum(r.statistics.theta.normal is False for r in gauss) <= 2


# --------------------------------------------------------------------------- sensor sets


def test_rate_gyro_only() -> None:
    rec = run_tunnel(TunnelSpec(seed=1, no_encoder=True, gyro_noise=1.0))
    assert rec.roll_deg is None and rec.truth() is not None
    result = identify(rec, OPTS)
    assert result.velocity_source.startswith("rate gyro")
    assert "integrated" in result.angle_source
    assert result.segments.n_steps == 8
    check_sane(result, true_alpha(rec))  # measured: -2.7 %


def test_measured_fin_only() -> None:
    rec = run_tunnel(TunnelSpec(seed=2, measured_fin=True))
    fin_only = dataclasses.replace(rec, fin_cmd_deg=None)
    assert fin_only.fin_cmd_deg is None and fin_only.fin_deg is not None
    result = identify(fin_only, OPTS)
    assert result.segments.fin_source == "fin_deg"
    assert result.theta_source.startswith("measured fin angle")
    # The servo leaves the old level after T_i: the last sample before the ramp is T_i.
    np.testing.assert_allclose(result.segments.time_s, [t for t, _ in PAPER_TABLE1], atol=1e-9)
    check_sane(result, true_alpha(rec))  # measured: +2.8 %


def test_100_hz_logging() -> None:
    rec = run_tunnel(TunnelSpec(seed=1, log_dt=0.01))
    result = identify(rec, OPTS)
    assert result.grid.per_sample == 1 and result.grid.step_s == pytest.approx(0.01)
    assert result.segments.n_steps == 8
    np.testing.assert_allclose(result.segments.time_s, [t for t, _ in PAPER_TABLE1], atol=1e-9)
    check_sane(result, true_alpha(rec))  # measured: -2.1 %


def test_radians_converted_by_the_importer(tmp_path: Path) -> None:
    rec = run_tunnel(TunnelSpec(seed=3, gyro_noise=1.0))
    assert rec.fin_cmd_deg is not None and rec.roll_deg is not None
    assert rec.roll_rate_dps is not None
    table = np.column_stack(
        [rec.time_s, *(np.radians(c) for c in (rec.fin_cmd_deg, rec.roll_deg, rec.roll_rate_dps))]
    )
    path = tmp_path / "log_rad.csv"
    np.savetxt(path, table, fmt="%.17g", delimiter=",", header="t,cmd,roll,rate", comments="")
    imported = import_csv(path, ["time", "fin_cmd", "roll", "roll_rate"], units="rad")
    assert imported.metadata["import.units"] == "rad"
    assert imported.roll_deg is not None
    np.testing.assert_allclose(imported.roll_deg, rec.roll_deg, rtol=1e-13, atol=1e-11)
    result = identify(imported, OPTS)
    reference = identify(rec, OPTS)
    np.testing.assert_allclose(result.segments.time_s, reference.segments.time_s)
    assert result.steady.alpha == pytest.approx(reference.steady.alpha, rel=1e-9)
    assert result.damping.a_per_s == pytest.approx(reference.damping.a_per_s, rel=1e-7)
    np.testing.assert_allclose(
        result.disturbances["theta"].u_d_deg, reference.disturbances["theta"].u_d_deg, atol=1e-6
    )
    assert imported.truth() is None and result.truth() is None
    check_sane(result, true_alpha(rec))  # measured: +0.7 %


def fin_changes(rec: Recording) -> tuple[np.ndarray, np.ndarray]:
    """Times and levels of the commanded steps, read off the recording."""
    assert rec.fin_cmd_deg is not None
    idx = np.flatnonzero(np.diff(rec.fin_cmd_deg)) + 1
    return rec.time_s[idx], rec.fin_cmd_deg[idx]


@pytest.mark.parametrize(
    ("steps", "seed", "rel"),
    [
        # Three 20-60 s dwells: α rests on three points, each a steady slope that carries
        # the turbulence averaged over one dwell; measured errors over seeds 0-11 span
        # -11 % ... +16 % (seed 0: +16 %, seed 1: -11 %, seed 2: -2.3 %).
        (3, 0, 0.20),
        (3, 1, 0.20),
        (3, 2, 0.05),
        # Twelve steps: |α error| <= 2.9 % over seeds 0-11.
        (12, 0, 0.05),
        (12, 1, 0.05),
    ],
)
def test_staircase_schedules(steps: int, seed: int, rel: float) -> None:
    rec = run_tunnel(TunnelSpec(seed=seed, schedule="staircase", steps=steps))
    times, levels = fin_changes(rec)
    assert times.size == steps
    assert np.unique(np.round(np.diff(np.append(times, rec.time_s[-1])), 6)).size == steps
    result = identify(rec, OPTS)
    assert result.segments.n_steps == steps
    np.testing.assert_allclose(result.segments.time_s, times, atol=1e-9)
    np.testing.assert_allclose(result.segments.step_levels_deg, levels, atol=1e-9)
    assert len(result.to_dict()["steps"]) == steps
    check_sane(result, true_alpha(rec), rel=rel)


def test_a_negative_damping_fit_is_reported_not_simulated() -> None:
    rec = run_tunnel(
        TunnelSpec(seed=8, schedule="staircase", steps=3, dwell_min=60.0, dwell_max=120.0)
    )
    # A turbulent burst puts step 3's breakpoint (0.01 s) inside the servo ramp and
    # its a_3 < 0: the step is left out of a(θ) and both models stay stable.
    result = identify(rec, OPTS)
    assert result.damping.a_steps_per_s[2] < 0
    assert result.damping_vs_fin.excluded == (2,)
    assert result.to_dict()["damping_vs_fin"]["excluded_steps"] == [3]
    for res in result.resimulations.values():
        assert np.isfinite(res.rate_mae_dps) and np.isfinite(res.angle_mae_deg)


# --------------------------------------------------------------------------- errors


def test_a_single_fin_step_is_refused_with_a_clear_message() -> None:
    n = 600
    cmd = np.where(np.arange(n) < 200, 0.0, 20.0)
    rec = Recording(
        name="one-step",
        source="wind-tunnel",
        time_s=np.asarray(0.1 * np.arange(n), dtype=np.float64),
        fin_cmd_deg=cmd,
        roll_deg=np.cumsum(0.1 * (0.659 * cmd + 2.9)),
    )
    with pytest.raises(IdentificationError, match=r"one-step: found 1 fin step.*at least two"):
        identify(rec, OPTS)


def test_a_recording_without_steps_is_refused() -> None:
    n = 300
    rec = Recording(
        name="flat",
        source="flight",
        time_s=np.asarray(0.1 * np.arange(n), dtype=np.float64),
        fin_cmd_deg=np.where(np.arange(n) < 100, 0.0, 0.5),
        roll_deg=np.zeros(n),
    )
    with pytest.raises(IdentificationError, match="never steps"):
        identify(rec, OPTS)


@pytest.mark.parametrize(
    ("option", "value"),
    [
        ("min_step_deg", 0.0),
        ("max_breakpoint_s", -4.0),
        ("breakpoint_resolution_s", float("nan")),
        ("servo_rate_dps", float("inf")),
        ("fine_step_s", 0.0),
        ("ud_interval_s", -0.1),
        ("outlier_level", 1.0),
        ("outlier_level", 0.0),
        ("smoothing_passes", 1.5),
        ("smoothing_passes", -1),
        ("smoothing_passes", True),
        ("noise_runs", -5),
        ("noise_seed", 0.5),
        ("noise_levels_pct", (1.0, -2.0)),
        ("noise_levels_pct", (float("nan"),)),
    ],
)
def test_bad_options_are_refused_naming_the_option(option: str, value: object) -> None:
    with pytest.raises(SettingError, match=f"^{option}: ") as caught:
        IdentifyOptions(**{option: value})  # type: ignore[arg-type]
    assert caught.value.setting == option


def test_a_breakpoint_range_below_the_search_step_names_the_range() -> None:
    """The step is not a command-line option; the range (``--max-breakpoint``) is, so the
    error names the setting a user can change."""
    with pytest.raises(SettingError, match=r"^max_breakpoint_s: .*search step \(0\.5 s\)"):
        IdentifyOptions(max_breakpoint_s=0.2, breakpoint_resolution_s=0.5)


def test_an_interval_off_the_fine_grid_is_refused() -> None:
    rec = load_bundled("tunnel-paper-seed0")
    with pytest.raises(IdentificationError, match="not a multiple"):
        identify(rec, IdentifyOptions(noise_runs=0, ud_interval_s=0.105))
