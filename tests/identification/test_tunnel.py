"""Virtual wind tunnel: calibration to the paper, determinism, ground truth, turbulence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from identification.model import PAPER_CONSTANT, PAPER_THETA
from identification.recording import load_recording
from identification.summary import summarize
from identification.tunnel import (
    PAPER_TABLE1,
    Distribution,
    FinSchedule,
    TunnelSpec,
    Turbulence,
    run_tunnel,
    spec_from_command,
)
from rocketroll.cli import main

PAPER_MEAN_ABS_RATE_DPS = 16.4  # paper abstract


def test_cli_seed0_is_valid_and_matches_the_paper_mean_abs_rate(tmp_path, capsys) -> None:
    out = tmp_path / "r.csv"
    assert main(["tunnel", "--seed", "0", "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    rec = load_recording(out)
    assert rec.source == "synthetic" and rec.n_samples == 5731
    summary = summarize(rec)
    # Measured from the encoder, as a user of the file would: within 10 % of 16.4 °/s.
    assert abs(summary.mean_abs_rate_dps / PAPER_MEAN_ABS_RATE_DPS - 1) < 0.10


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_true_mean_abs_rate_is_within_10_percent_for_other_seeds(seed: int) -> None:
    rec = run_tunnel(TunnelSpec(seed=seed, gyro_noise=0.0))
    assert rec.roll_rate_dps is not None
    assert abs(np.mean(np.abs(rec.roll_rate_dps)) / PAPER_MEAN_ABS_RATE_DPS - 1) < 0.10


def test_same_seed_gives_byte_identical_files(tmp_path) -> None:
    paths = [tmp_path / f"{i}.csv" for i in range(3)]
    for path, seed in zip(paths, (5, 5, 6), strict=True):
        assert main(["tunnel", "--seed", str(seed), "--out", str(path)]) == 0
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_metadata_carries_ground_truth_and_the_command() -> None:
    spec = TunnelSpec(seed=7, model="constant", turbulence="laplace", correlation_time=0.5)
    rec = run_tunnel(spec)
    assert rec.truth() == spec.params()
    assert rec.truth() == PAPER_CONSTANT.with_constant_damping(1.314)
    assert rec.seed == 7
    assert rec.metadata["truth.turbulence"] == "laplace"
    assert spec_from_command(rec.metadata["command"]) == spec
    assert run_tunnel(TunnelSpec()).truth() == PAPER_THETA


def test_paper_schedule_is_table1() -> None:
    rec = run_tunnel(TunnelSpec(seed=0))
    t, cmd = rec.time_s, rec.fin_cmd_deg
    assert cmd is not None
    assert t[-1] == pytest.approx(573.0)
    assert np.all(cmd[t < 68.1 - 1e-9] == 0.0)
    for (start, level), (end, _) in zip(
        PAPER_TABLE1, [*PAPER_TABLE1[1:], (573.0, None)], strict=True
    ):
        inside = (t >= start - 1e-9) & (t < end - 1e-9)
        assert np.all(cmd[inside] == level), (start, level)
    assert np.count_nonzero(np.diff(cmd)) == 8


def test_encoder_quantises_to_1024_counts_per_revolution() -> None:
    rec = run_tunnel(TunnelSpec(seed=1))
    assert rec.roll_deg is not None
    counts = rec.roll_deg / (360.0 / 1024)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    ideal = run_tunnel(TunnelSpec(seed=1, encoder_counts=0))
    assert ideal.roll_deg is not None
    assert np.max(np.abs(ideal.roll_deg - rec.roll_deg)) < 360.0 / 1024 + 1e-6
    assert np.max(np.abs(ideal.roll_deg - rec.roll_deg)) > 0.2


def test_sensors_do_not_change_the_turbulence() -> None:
    plain = run_tunnel(TunnelSpec(seed=3))
    full = run_tunnel(TunnelSpec(seed=3, gyro_noise=5.0, measured_fin=True))
    np.testing.assert_array_equal(plain.ud_true_deg, full.ud_true_deg)
    np.testing.assert_array_equal(plain.roll_deg, full.roll_deg)
    assert full.fin_deg is not None and full.roll_rate_dps is not None
    # The measured fin lags the command by the servo (eq. 23), at most 150 °/s.
    assert np.max(np.abs(np.diff(full.fin_deg))) <= 15.0 + 1e-9
    assert np.any(full.fin_deg != full.fin_cmd_deg)


def test_rate_only_recording() -> None:
    rec = run_tunnel(TunnelSpec(seed=2, no_encoder=True, gyro_noise=1.0))
    assert rec.roll_deg is None and rec.roll_rate_dps is not None
    with pytest.raises(ValueError, match="gyro"):
        TunnelSpec(no_encoder=True)


def test_staircase_schedule() -> None:
    rng = np.random.default_rng(0)
    sched = FinSchedule.staircase(rng, steps=15, range_deg=30.0, dwell_s=(10.0, 20.0))
    levels = np.array(sched.levels_deg)
    assert levels.size == 15 and np.all(np.abs(levels) <= 30.0)
    assert np.all(np.abs(np.diff(np.concatenate([[0.0], levels]))) >= 5.0)
    dwell = np.diff([*sched.change_times_s, sched.end_s])
    assert np.all((dwell >= 10.0 - 0.05) & (dwell <= 20.0 + 0.05))
    rec = run_tunnel(TunnelSpec(seed=4, schedule="staircase", steps=5))
    assert rec.fin_cmd_deg is not None
    assert np.count_nonzero(np.diff(rec.fin_cmd_deg)) == 5


@pytest.mark.parametrize("distribution", ["gaussian", "laplace", "student-t"])
def test_turbulence_marginal_is_exact(distribution: Distribution) -> None:
    turb = Turbulence(distribution=distribution, sd_deg=8.4, mean_deg=1.0, correlation_time_s=0.0)
    x = turb.sample(40_000, 0.1, np.random.default_rng(0))
    target = {
        "gaussian": stats.norm(1.0, 8.4),
        "laplace": stats.laplace(1.0, 8.4 / np.sqrt(2)),
        "student-t": stats.t(4.0, 1.0, 8.4 * np.sqrt(2 / 4)),
    }[distribution]
    # Independent values (τ = 0), so the KS test's assumptions hold.
    assert stats.kstest(x, target.cdf).pvalue > 0.01
    assert np.std(x) == pytest.approx(8.4, rel=0.05)


def test_turbulence_correlation_time() -> None:
    turb = Turbulence(correlation_time_s=0.3)
    x = turb.sample(200_000, 0.1, np.random.default_rng(1))
    lag1 = np.corrcoef(x[:-1], x[1:])[0, 1]
    assert lag1 == pytest.approx(np.exp(-0.1 / 0.3), abs=0.01)
    laplace = Turbulence(distribution="laplace", correlation_time_s=0.3)
    y = laplace.sample(200_000, 0.1, np.random.default_rng(1))
    # Through the copula the correlation is close to, not exactly, exp(-Δt/τ).
    assert np.corrcoef(y[:-1], y[1:])[0, 1] == pytest.approx(np.exp(-0.1 / 0.3), abs=0.05)
    assert stats.kurtosis(y) > 2.0  # heavy tails kept (Laplace excess kurtosis is 3)


def test_bad_tunnel_arguments_exit_2_and_write_nothing(tmp_path, capsys) -> None:
    out = tmp_path / "r.csv"
    assert main(["tunnel", "--no-encoder", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "gyro" in err
    assert not out.exists()
