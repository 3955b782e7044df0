"""Instrumental variables under a stated rate loop (identification.methods.instrumental), the
loop's ``loop.*`` lines (StatedLoop), and the adequacy that reads a stated loop, on virtual
tunnel logs flown by the reference integrator under its own loop (not the model's code)."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from identification.instruments.reference import Effects
from identification.instruments.tunnel import TunnelSpec, run_tunnel
from identification.methods import Context, fit
from identification.methods.adequacy import model_only, r_squared
from identification.methods.instrumental import fieller_interval, instrumental
from identification.methods.statistics import newey_west_covariance, two_stage_least_squares
from identification.methods.steps import IdentificationError
from identification.recordings.recording import (
    Recording,
    RecordingError,
    StatedLoop,
    load_recording,
    save_recording,
)
from tests.cli import ok, refused

#: An aileron-convention rocket (α < 0) with a positive asymmetry: unlike the paper's.
ROCKET: dict[str, Any] = {"model": "constant", "alpha": -1.3, "beta": -5.2, "beta_bar": 1.8}
#: 25 Hz, 50 s, the loop reading the gyro 40 ms late, a ±5° PRBS dither on its command.
LOOP: dict[str, Any] = {
    "log_dt": 0.04, "lead": 2.0, "duration": 50.0, "gyro_noise": 1.0, "stops": 15.0,
    "loop_gain": -0.6, "loop_delay": 0.04, "schedule": "prbs", "fin_range": 5.0,
    "pulse": 0.5, "turbulence_sd": 6.0,
}  # fmt: skip


def _logged(**changes: Any) -> tuple[Recording, TunnelSpec]:
    """A loop log as the flight computer keeps it: the command, not the fin."""
    spec = TunnelSpec(seed=4, **{**ROCKET, **LOOP, **changes})
    rec = run_tunnel(spec)
    return dataclasses.replace(rec, fin_deg=None), spec


def _truth(spec: TunnelSpec) -> dict[str, float]:
    p = spec.params()
    return {
        "alpha": p.alpha,
        "theta_bar": p.theta_bar_deg + spec.turbulence_mean,
        "a_per_s": p.beta_bar_per_s,
    }


def test_the_loops_excitation_instruments_a_fit_output_error_gets_wrong() -> None:
    rec, spec = _logged()
    assert rec.loop == StatedLoop(-0.6, 0.04, 15.0)
    context = Context(rec)
    found = fit(context, "instrumental", ["constant"])["constant"]
    truth = _truth(spec)
    intervals = found.metrics["intervals"]
    for name, value in truth.items():
        assert intervals[name]["low"] <= value <= intervals[name]["high"], name
        assert intervals[name]["determined"]
    # Informative, not merely wide: each interval within twice the truth's size.
    assert intervals["alpha"]["high"] - intervals["alpha"]["low"] < 2 * abs(truth["alpha"])
    assert intervals["a_per_s"]["high"] - intervals["a_per_s"]["low"] < 2 * truth["a_per_s"]
    instruments = found.metrics["instruments"]
    assert instruments["source"] == "loop excitation"
    assert not instruments["weak"]
    assert instruments["loop"] == {"gain": -0.6, "delay_s": 0.04, "stops_deg": 15.0}
    # The same log read as open loop: output error's gain is far off (the fin carries the
    # turbulence through the loop), which is what the instrument is for.
    oe = fit(context, "output-error", ["constant"])["constant"]
    assert abs(oe.params.alpha / truth["alpha"] - 1.0) > 0.5
    reasons = " ".join(oe.metrics["adequacy"]["reasons"])
    assert "state the loop (--loop-gain, --loop-delay) and use instrumental" in reasons


def test_a_loop_without_excitation_is_refused_with_what_to_add() -> None:
    rec, _ = _logged(schedule="none")
    with pytest.raises(IdentificationError, match="dither or PRBS on top of the loop"):
        fit(Context(rec), "instrumental", ["constant"])


def test_without_a_stated_loop_the_fin_is_the_instrument() -> None:
    spec = TunnelSpec(seed=5, **{**ROCKET, **LOOP, "loop_gain": 0.0, "fin_range": 8.0})
    rec = run_tunnel(spec)
    assert rec.loop is None
    found = instrumental(Context(rec).measurements)
    assert found.instruments["source"] == "fin"
    truth = _truth(spec)
    for name, value in truth.items():
        assert found.intervals[name]["low"] <= value <= found.intervals[name]["high"], name


def test_an_unstated_loop_makes_the_fin_no_instrument_and_the_adequacy_says_so() -> None:
    rec, _ = _logged()
    bare = dataclasses.replace(
        rec, metadata={k: v for k, v in rec.metadata.items() if not k.startswith("loop.")}
    )
    found = fit(Context(bare), "instrumental", ["constant"])["constant"]
    assert found.metrics["instruments"]["source"] == "fin"
    adequacy = found.metrics["adequacy"]
    assert adequacy["verdict"] == "unreliable"
    assert any("so the fin is no instrument" in r for r in adequacy["reasons"])


def test_a_wrong_stated_gain_is_named() -> None:
    rec, _ = _logged()
    check = "the stated loop's gain (-0.78) is not the one the log shows"
    right = fit(Context(rec), "instrumental", ["constant"])["constant"]
    assert not any("the stated loop's gain" in r for r in right.metrics["adequacy"]["reasons"])
    wrong = dataclasses.replace(rec, metadata={**rec.metadata, "loop.gain": "-0.78"})
    off = fit(Context(wrong), "instrumental", ["constant"])["constant"]
    assert off.metrics["adequacy"]["verdict"] == "unreliable"
    assert any(check in r for r in off.metrics["adequacy"]["reasons"])


def test_the_model_only_is_the_closed_loop_driven_by_the_excitation() -> None:
    """Without turbulence and with the true rocket, the model's closed loop (the model's
    code: its sample step, the servo, the loop's law) retraces the reference integrator's
    (another code); with turbulence and the true rocket it explains the rate the dither
    drives, where the open-loop model of a wrong rocket does not."""
    rec, spec = _logged(turbulence_sd=1e-6, gyro_noise=0.01)
    model = model_only(Context(rec).measurements, spec.params())
    assert r_squared(model.rate_dps, model.measured_rate_dps) > 0.9999
    # A gain off by half: the closed loop no longer retraces it.
    wrong = dataclasses.replace(spec.params(), alpha=0.5 * spec.params().alpha)
    off = model_only(Context(rec).measurements, wrong)
    assert r_squared(off.rate_dps, off.measured_rate_dps) < 0.99


def test_a_servo_lag_outside_the_model_stays_within_the_intervals() -> None:
    """A truth outside the model class: the fin 40 ms behind the servo, unmodelled; the
    integral over half a second keeps its bias inside the intervals on this log (over
    many logs: ``benchmarks/instrumental.py``, case ``servo-lag``)."""
    rec, spec = _logged(effects=Effects(servo_lag_s=0.04))
    found = fit(Context(rec), "instrumental", ["constant"])["constant"]
    intervals = found.metrics["intervals"]
    truth = _truth(spec)
    for name in ("alpha", "a_per_s"):
        assert intervals[name]["low"] <= truth[name] <= intervals[name]["high"], name


def test_two_stage_least_squares_matches_statsmodels() -> None:
    gmm = pytest.importorskip("statsmodels.sandbox.regression.gmm")
    rng = np.random.default_rng(0)
    n = 400
    z1, z2, noise = rng.standard_normal((3, n))
    endogenous = z1 + 0.5 * z2 + 0.8 * noise
    x = np.column_stack([endogenous, np.ones(n)])
    y = 2.0 * endogenous + 1.0 + noise
    z = np.column_stack([z1, z2, np.ones(n)])
    beta, resid, projected = two_stage_least_squares(x, y, z)
    cov = newey_west_covariance(projected, resid, 0)
    reference = gmm.IV2SLS(y, x, z).fit()
    np.testing.assert_allclose(beta, reference.params, rtol=1e-10)
    np.testing.assert_allclose(resid, y - x @ reference.params, atol=1e-10)
    # With no lags the Newey-West covariance is White's: statsmodels' HC0 of the second stage.
    fitted = z @ np.linalg.lstsq(z, x, rcond=None)[0]
    bread = np.linalg.inv(fitted.T @ fitted)
    white = bread @ (fitted.T * resid**2) @ fitted @ bread
    np.testing.assert_allclose(cov, white, rtol=1e-10)


@pytest.mark.parametrize(("num", "den"), [(2.0, 1.0), (-3.0, 0.5), (1.0, -2.0)])
def test_fiellers_interval_is_the_set_the_test_does_not_reject(num: float, den: float) -> None:
    var_n, var_d, cov = 0.04, 0.01, 0.005
    interval = fieller_interval(num, den, var_n, var_d, cov)
    assert interval is not None
    low, high = interval
    z = 1.959963984540054
    grid = np.linspace(num / den - 5.0, num / den + 5.0, 200_001)
    kept = grid[(num - grid * den) ** 2 <= z**2 * (var_n - 2 * grid * cov + grid**2 * var_d)]
    assert kept.min() == pytest.approx(low, abs=1e-4)
    assert kept.max() == pytest.approx(high, abs=1e-4)
    # A denominator not told from 0: no bounded interval.
    assert fieller_interval(num, 0.1, var_n, var_d, cov) is None


@pytest.mark.parametrize(
    ("key", "value", "words"),
    [
        ("loop.gain", "0", "other than 0"),
        ("loop.gain", "fast", "must be a number"),
        ("loop.delay_s", "0.7", "[0, 0.5]"),
        ("loop.stops_deg", "0", "(0, 90]"),
    ],
)
def test_a_bad_loop_line_is_refused(key: str, value: str, words: str) -> None:
    rec, _ = _logged(duration=5.0)
    with pytest.raises(RecordingError, match=re_escape(words)):
        dataclasses.replace(rec, metadata={**rec.metadata, key: value})


def re_escape(text: str) -> str:
    import re

    return re.escape(text)


def test_the_command_line_states_a_loop_over_the_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, _ = _logged()
    bare = dataclasses.replace(
        rec, metadata={k: v for k, v in rec.metadata.items() if not k.startswith("loop.")}
    )
    path = tmp_path / "bare.csv"
    save_recording(bare, path)
    before = path.read_bytes()
    out = tmp_path / "fit.json"
    ok(capsys, [
        "identify", str(path), "--method", "instrumental", "--loop-gain", "-0.6",
        "--loop-delay", "0.04", "--fin-range", "15", "--json", str(out),
    ])  # fmt: skip
    data = json.loads(out.read_text())
    instruments = data["methods"]["instrumental"]["constant"]["metrics"]["instruments"]
    assert instruments["source"] == "loop excitation"
    assert instruments["loop"] == {"gain": -0.6, "delay_s": 0.04, "stops_deg": 15.0}
    assert path.read_bytes() == before  # the recording given is not rewritten
    assert load_recording(path).loop is None


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--loop-gain", "0"], "--loop-gain: 0 is no loop"),
        (["--loop-delay", "0.04"], "states no loop (no loop.gain line); give --loop-gain"),
        (["--loop-gain", "0.5", "--loop-delay", "0.9"], "--loop-delay"),
    ],
)
def test_a_bad_loop_flag_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], flags: list[str], words: str
) -> None:
    spec = TunnelSpec(seed=5, **{**ROCKET, **LOOP, "loop_gain": 0.0, "duration": 10.0})
    path = tmp_path / "open.csv"
    save_recording(run_tunnel(spec), path)
    out = tmp_path / "fit.json"
    refused(capsys, ["identify", str(path), "--method", "instrumental", *flags, "--json", str(out)],
            words)  # fmt: skip
    assert not out.exists()


def test_import_csv_stores_the_loop_and_instrumental_reads_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rec, _ = _logged()
    raw = tmp_path / "raw.csv"
    rate, command = np.asarray(rec.roll_rate_dps), np.asarray(rec.fin_cmd_deg)
    raw.write_text("".join(f"{v:.17g},{c:.17g}\n" for v, c in zip(rate, command, strict=True)))
    mine = tmp_path / "mine.csv"
    ok(capsys, [
        "import-csv", str(raw), "--out", str(mine), "--columns", "roll_rate,fin_cmd",
        "--no-header", "--rate", "25", "--fin-range", "15", "--loop-gain", "-0.6",
        "--loop-delay", "0.04",
    ])  # fmt: skip
    imported = load_recording(mine)
    assert imported.loop == StatedLoop(-0.6, 0.04, None)
    found = fit(Context(imported), "instrumental", ["constant"])["constant"]
    assert found.metrics["instruments"]["loop"]["stops_deg"] == 15.0
    np.testing.assert_allclose(
        found.params.alpha,
        fit(Context(rec), "instrumental", ["constant"])["constant"].params.alpha,
        rtol=1e-6,  # the same samples, written to 17 digits
    )


def test_a_fast_rockets_u_d_is_recovered_over_a_shorter_smoothing() -> None:
    """A rig like the public aircraft one (a ≈ 9 1/s at 100 Hz): the paper's 0.3-s smoothing
    would smear its response into a fin-shaped u_d; the u_d is taken over a shorter one
    (on the public rig's log the fin's share of u_d fell from 48 to 5 %)."""
    spec = TunnelSpec(
        seed=2, model="constant", alpha=3.4, beta=0.0, beta_bar=9.0, schedule="prbs",
        fin_range=10.0, pulse=0.3, duration=30.0, lead=1.0, log_dt=0.01, gyro_noise=1.0,
        turbulence_sd=0.5,
    )  # fmt: skip
    found = fit(Context(run_tunnel(spec)), "instrumental", ["constant"])["constant"]
    assert found.metrics["smoothing_window_s"] < 0.3
    assert abs(found.params.alpha / 3.4 - 1.0) < 0.05
    assert abs(found.params.beta_bar_per_s / 9.0 - 1.0) < 0.05
