"""Virtual wind tunnel: calibration to the paper, determinism, ground truth, turbulence."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from identification.instruments.tunnel import (
    PAPER_TABLE1,
    Distribution,
    FinSchedule,
    TunnelSpec,
    Turbulence,
    run_tunnel,
    spec_from_command,
)
from identification.model import PAPER_CONSTANT, PAPER_THETA
from identification.recordings.recording import load_recording
from identification.reports.summary import summarize
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


#: A short, fast-logged run, as a real rig records one.
RIG = {"log_dt": 0.01, "steps": 6, "dwell_min": 2.0, "dwell_max": 4.0, "lead": 2.0}


def _command(schedule: str, **extra: object) -> tuple[np.ndarray, np.ndarray, TunnelSpec]:
    spec = TunnelSpec(seed=7, schedule=schedule, fin_range=30.0, **{**RIG, **extra})  # type: ignore[arg-type]
    rec = run_tunnel(spec)
    assert rec.fin_cmd_deg is not None
    # The recorded command reproduces the run.
    again = run_tunnel(spec_from_command(rec.metadata["command"]))
    np.testing.assert_array_equal(again.columns()["fin_cmd_deg"], rec.fin_cmd_deg)
    return rec.time_s, rec.fin_cmd_deg, spec


def test_ramps_reach_each_level_at_the_ramp_rate_and_hold_it() -> None:
    t, cmd, _ = _command("ramps", ramp=1.0)
    slope = np.abs(np.diff(cmd)) / 0.01
    assert slope.max() <= 60.0 + 1e-6  # at most a ±30° swing in 1 s
    moving = slope > 1e-9
    assert 0.1 < moving.mean() < 0.6  # ramps, then dwells
    assert np.abs(cmd).max() <= 30.0 and cmd[t < 2.0].max() == 0.0


def test_doublets_are_zero_mean_pulse_pairs() -> None:
    _, cmd, _ = _command("doublets", pulse=0.5)
    changes = np.flatnonzero(np.diff(cmd)) + 1
    assert changes.size == 3 * 6  # +A, -A, back to 0, six times
    for k in range(6):
        up, down, back = changes[3 * k : 3 * k + 3]
        assert cmd[up] == -cmd[down] != 0.0 and cmd[back] == 0.0
        assert down - up == back - down == 50  # two pulses of 0.5 s
        assert 15.0 <= abs(cmd[up]) <= 30.0


def test_prbs_switches_between_two_levels_on_its_bit_grid() -> None:
    t, cmd, _ = _command("prbs", pulse=0.2, duration=30.0)
    after = cmd[t >= 2.0]
    assert set(np.unique(after)) == {-30.0, 30.0}
    changes = np.flatnonzero(np.diff(cmd)) + 1
    assert np.all((changes[1:] - changes[0]) % 20 == 0)  # whole bits of 0.2 s
    assert 0.35 < np.mean(after > 0) < 0.65


def test_a_chirp_sweeps_from_its_first_to_its_last_frequency() -> None:
    t, cmd, _ = _command("chirp", duration=40.0, chirp_from=0.1, chirp_to=2.0)
    inside = (t >= 2.0) & (t <= 42.0)
    crossings = t[inside][1:][np.diff(np.sign(cmd[inside])) != 0]
    half_periods = np.diff(crossings)
    assert half_periods[0] > 5 * half_periods[-1]  # faster and faster
    assert 1.6 < 0.5 / half_periods[-3:].mean() < 2.2  # ends near 2 Hz
    assert np.abs(cmd).max() <= 30.0 and np.all(cmd[t > 42.01] == 0.0)


def test_a_schedule_without_a_lead_starts_at_its_first_level() -> None:
    for schedule in ("staircase", "ramps", "doublets", "prbs", "chirp"):
        _, cmd, _ = _command(schedule, lead=0.0, duration=10.0)
        if schedule in ("staircase", "ramps", "prbs"):
            assert cmd[0] != 0.0, schedule  # the first level from the first sample


def test_pulses_and_bits_are_whole_log_steps_so_both_halves_last_alike() -> None:
    # 0.15 s at 0.1-s logging: each half one step (not 0.1 and 0.2 s), from any lead
    for lead in (20.0, 20.05, 0.05):
        _, cmd, _ = _command("doublets", pulse=0.15, log_dt=0.1, lead=lead)
        changes = np.flatnonzero(np.diff(cmd)) + 1
        if lead < 0.1:  # a doublet from the first sample: its +A is the initial level
            changes = np.concatenate([[0], changes])
        assert changes.size == 3 * 6, (lead, changes.size)  # no doublet lost to a collision
        for k in range(6):
            up, down, back = changes[3 * k : 3 * k + 3]
            assert down - up == back - down == 1, (lead, k)
    # 0.25-s bits at 0.1-s logging: whole two-step bits from the lead (no 0.2/0.3 s mix)
    _, cmd, _ = _command("prbs", pulse=0.25, log_dt=0.1, lead=20.05, duration=10.0)
    changes = np.flatnonzero(np.diff(cmd)) + 1
    assert np.all((changes - changes[0]) % 2 == 0) and np.diff(changes).min() == 2


def test_a_chirp_stops_at_a_zero_crossing() -> None:
    from identification.instruments.tunnel import SmoothSchedule

    sweep = SmoothSchedule.sweep(30.0, 0.1, 2.0, 10.0, 1.0)
    assert sweep.chirp is not None
    stop = sweep.chirp[5]
    assert 9.5 < stop <= 10.0
    t = 1.0 + stop + np.array([-1e-6, 0.0, 1e-6])
    assert np.abs(sweep.command(t)).max() < 0.01  # no step where the sweep ends


@pytest.mark.parametrize(
    ("argv", "said"),
    [
        (["--schedule", "chirp", "--chirp-to", "10"], "--chirp-to: above 2.5 Hz"),
        (["--schedule", "prbs", "--pulse", "0.05"], "--pulse: 0.05 s is shorter than the log"),
        (["--schedule", "prbs", "--duration", "86000", "--log-dt", "0.001"], "--log-dt: 86"),
        (["--schedule", "staircase", "--steps", "200", "--dwell-min", "3000", "--dwell-max",
          "3600"], "--steps: the staircase schedule runs"),
        (["--schedule", "prbs", "--duration", "1", "--lead", "0"], "a recording spans 4.9 s to"),
        (["--schedule", "prbs", "--lead", "0", "--duration", "5", "--log-dt", "0.2", "--pulse",
          "0.2"], "in 26 samples; a recording spans 4.9 s to 24 h in at least 50 samples"),
        (["--schedule", "ramps", "--ramp", "30"], "--ramp: 30 s is longer than --dwell-min 20 s"),
        (["--schedule", "ramps", "--steps", "1", "--lead", "0"], "never moves the fins"),
        (["--schedule", "prbs", "--lead", "0", "--pulse", "10", "--duration", "10"],
         "--duration: the prbs schedule never moves the fins"),
        (["--schedule", "prbs", "--duration", "86000", "--log-dt", "0.001", "--pulse", "0.001"],
         "--log-dt: 86020 s every 0.001 s is 86,020,000 samples"),
    ],
)  # fmt: skip
def test_a_schedule_a_recording_cannot_hold_is_refused_in_one_line(
    argv: list[str], said: str, tmp_path, capsys
) -> None:
    out = tmp_path / "r.csv"
    assert main(["tunnel", *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and said in err, err
    assert not out.exists()


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
