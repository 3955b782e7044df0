"""Fit adequacy tells right models from wrong ones, on truths the tests make.

Wrong on purpose: the gain held 30 % off, constant damping fitted to a rocket whose
damping rises steeply with the fin, and the fin command read through eq. 23's servo
where the real one was ten times slower.  Right: the maximum-likelihood fit of each.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from identification.instruments.bundled import bundled_path, load_bundled
from identification.instruments.tunnel import TunnelSpec, run_tunnel, spec_from_command
from identification.methods import fit
from identification.methods.adequacy import VERDICTS, Adequacy, adequacy
from identification.methods.baselines import output_error
from identification.methods.ml import MLFit, maximum_likelihood, posterior_given
from identification.methods.pipeline import (
    SMOOTHING_PER_TIME_CONSTANT,
    IdentifyOptions,
    model_inputs,
    recover_disturbance,
    smoothing_for,
)
from identification.methods.steps import smoothing_spread_s
from identification.model import RollParams
from identification.recordings.recording import Recording
from rocketroll.cli import main as rocketroll

PRBS: dict[str, Any] = {
    "schedule": "prbs",
    "log_dt": 0.01,
    "duration": 58.0,
    "pulse": 0.5,
    "lead": 2.0,
}


def _verdict(
    rec: Recording, model: str, params: RollParams | None = None, found: MLFit | None = None
) -> Adequacy:
    """The adequacy of the maximum-likelihood fit ``found`` of ``model`` (fitted here where
    not given), or of ``params`` with that fit's turbulence."""
    if found is None:
        found = maximum_likelihood(rec, model)
    if params is None:
        params, dist, metrics = found.params, found.disturbance(), {"std_errors": found.std_errors}
    else:
        given = posterior_given(
            rec, params, found.ar.tolist(), found.sd_deg, gyro_noise=found.gyro_noise
        )
        dist, metrics = given.disturbance(), {}
    return adequacy(model_inputs(rec, model, None), params, dist, metrics)


@pytest.mark.parametrize("truth", [{}, {"alpha": 0.9, "beta": -3.0, "correlation_time": 0.3}])
def test_a_right_fit_is_good_and_the_gain_30_percent_off_is_not(truth: dict[str, Any]) -> None:
    rec = run_tunnel(TunnelSpec(seed=11, gyro_noise=1.0, **PRBS, **truth))
    found = maximum_likelihood(rec, "theta")  # one fit, judged as it is and 30 % off
    right = _verdict(rec, "theta", found=found)
    assert right.verdict == "good", right.reasons
    assert right.rate_r2 > 0.5 and right.fin_share < 0.15
    wrong = _verdict(rec, "theta", replace(found.params, alpha=1.3 * found.params.alpha), found)
    assert wrong.verdict != "good"
    assert any("the fin explains" in reason for reason in wrong.reasons)


def test_constant_damping_on_a_steeply_theta_dependent_rocket_is_not_good() -> None:
    rec = run_tunnel(TunnelSpec(seed=0, gyro_noise=1.0, alpha_bar=0.06, beta_bar=0.3, **PRBS))
    wrong = _verdict(rec, "constant")
    assert wrong.verdict != "good"
    assert _verdict(rec, "theta").verdict == "good"


def test_a_servo_ten_times_slower_than_eq_23_is_unreliable() -> None:
    rec = run_tunnel(TunnelSpec(seed=0, gyro_noise=1.0, servo_rate=15.0, **PRBS))
    wrong = _verdict(rec, "theta")
    assert wrong.verdict == "unreliable"
    assert wrong.ud_range_fraction > 1.5  # u_d the fins could not have made
    assert any("fins'" in reason for reason in wrong.reasons)


@pytest.mark.parametrize("method", ["paper", "output-error", "ml"])
def test_every_tunnel_method_reports_adequacy_in_its_metrics(method: str) -> None:
    fits = fit(load_bundled("tunnel-paper-seed0"), method, options=IdentifyOptions(noise_runs=0))
    for f in fits.values():
        figures = f.metrics["adequacy"]
        assert figures["verdict"] in VERDICTS
        assert figures["verdict"] == "good", figures["reasons"]  # the paper's rocket, its schedule
        assert 0.9 < figures["rate_r2"] < 1.0
        assert json.dumps(figures, allow_nan=False)


def test_identify_prints_the_adequacy_table_and_writes_it_to_the_json(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "fit.json"
    argv = ["identify", str(bundled_path("tunnel-paper-seed0")), "--method", "output-error"]
    assert rocketroll([*argv, "--json", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "fit adequacy" in printed and "verdict" in printed
    data = json.loads(out.read_text())
    for model in ("constant", "theta"):
        assert data["methods"]["output-error"][model]["metrics"]["adequacy"]["verdict"] == "good"


FAST = "--model constant --alpha 3.4 --beta 0.2 --beta-bar 9.5"  # a 0.1-s time constant


@pytest.mark.parametrize("seed", [1, 3])
def test_output_error_smooths_a_fast_rocket_over_a_window_short_against_its_time_constant(
    seed: int,
) -> None:
    # The paper's smoothing spreads 0.15 s, more than this rocket's time constant: fitted
    # through it, the output-error u_d took up the smeared response in the fin's shape.
    command = (
        f"--seed {seed} --log-dt 0.01 --gyro-noise 1 --turbulence-sd 2 --correlation-time 0.2 "
        f"--schedule ramps --steps 6 --dwell-min 2 --dwell-max 3 --lead 1 --ramp 1 {FAST}"
    )
    rec = run_tunnel(spec_from_command(command))
    options = IdentifyOptions(noise_runs=0)
    found = fit(rec, "output-error", ["constant"], options)["constant"]
    window = found.metrics["smoothing_window_s"]
    assert window < options.smoothing_window_s
    spread = smoothing_spread_s(rec.dt_s, options.smoothing_passes, window)
    assert spread <= SMOOTHING_PER_TIME_CONSTANT / found.params.beta_bar_per_s
    assert found.metrics["adequacy"]["verdict"] == "good", found.metrics["adequacy"]["reasons"]
    assert abs(found.params.alpha / 3.4 - 1) < 0.03
    se = found.metrics["std_errors"]
    assert set(se) == {"alpha", "theta_bar", "a_per_s"} and 0 < se["alpha"] < 0.1
    assert abs(found.params.alpha - 3.4) < 4 * se["alpha"]  # the error within its bars
    assert all(-1 <= r <= 1 for r in found.metrics["correlations"].values())
    # through the paper's smoothing the same rocket's fit is not good
    inputs = model_inputs(rec, "constant", options)
    smeared = output_error(rec, "constant", options=options).params
    dist, _ = recover_disturbance(inputs, smeared, "constant", options)
    assert adequacy(inputs, smeared, dist, {}).verdict != "good"


def test_the_paper_rocket_keeps_the_paper_smoothing() -> None:
    options = IdentifyOptions(noise_runs=0)
    for name in ("tunnel-paper-seed3", "tunnel-staircase-seed10"):
        rec = load_bundled(name)
        for model, found in fit(rec, "output-error", options=options).items():
            assert "smoothing_window_s" not in found.metrics
            assert smoothing_for(found.params, model_inputs(rec, model, options), options) is None


def test_the_fin_share_is_statsmodels_ols_with_newey_west_and_its_wald_test() -> None:
    import math

    import numpy as np
    import statsmodels.api as sm

    from identification.methods.adequacy import _fin_share
    from identification.methods.statistics import decorrelation_stride

    rng = np.random.default_rng(3)
    n = 3000
    fin = np.repeat(rng.uniform(-20, 20, n // 100 + 1), 100)[: n + 1]
    lag = np.convolve(rng.standard_normal(n + 30), np.ones(30) / 30, "valid")[: n + 1]
    u = np.convolve(rng.standard_normal(n + 20), np.ones(20) / 20, "valid")[:n] + 0.01 * fin[:-1]
    share, p = _fin_share(u, fin, 2.0, lag)
    size = np.abs(fin[:-1] + 2.0)
    x = np.column_stack([np.ones(n), fin[:-1], size, np.diff(fin), lag[:-1], lag[:-1] * size])
    maxlags = min(2 * decorrelation_stride(u, math.exp(-1.0)), n // 4)
    fitted = sm.OLS(u, x).fit(cov_type="HAC", cov_kwds={"maxlags": maxlags})
    expected = float(fitted.wald_test(np.eye(6)[1:], scalar=True).pvalue)
    assert share == pytest.approx(fitted.rsquared, rel=1e-9)
    assert p == pytest.approx(expected, rel=1e-9)


def test_the_fins_delay_is_read_off_u_d_in_first_differences() -> None:
    """A ``u_d`` that holds ``-τ·dθ/dt`` over AR(1) turbulence of SD 9° gives τ back; the
    turbulence alone gives none (z near 0)."""
    from scipy.signal import lfilter

    from identification.methods.adequacy import fin_delay

    rng = np.random.default_rng(0)
    n, dt = 6000, 0.1
    turbulence = 9.0 * math.sqrt(1 - 0.85**2) * lfilter([1.0], [1.0, -0.85], rng.standard_normal(n))
    fin = np.repeat(rng.uniform(-20.0, 20.0, n // 50), 50)
    fin = np.concatenate([fin, fin[-1:]])
    u = turbulence - 0.05 * np.diff(fin) / dt
    tau, z = fin_delay(u, fin, dt)
    assert tau == pytest.approx(0.05, rel=0.2) and z > 4.0
    tau, z = fin_delay(turbulence, fin, dt)
    assert abs(z) < 3.0 and abs(tau) < 0.02


def test_a_wandering_intensity_is_told_from_a_stationary_one() -> None:
    from scipy.signal import lfilter

    from identification.methods.adequacy import INTENSITY_RATIO, intensity_ratio

    rng = np.random.default_rng(1)
    n, dt, ar = 6000, 0.1, 0.85
    steady = lfilter([1.0], [1.0, -ar], rng.standard_normal(n))
    assert intensity_ratio(steady, dt, np.array([ar])) < 1.3
    x = lfilter([1.0], [1.0, -math.exp(-dt / 20.0)], rng.standard_normal(n))
    swell = np.exp(0.35 * x / x.std())  # the tunnel's gusty truth: 0.5x to 1.8x over ~20 s
    assert intensity_ratio(steady * swell, dt, np.array([ar])) > INTENSITY_RATIO


def test_adequacy_names_the_effects_a_fit_lacks_on_truths_outside_the_model(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The virtual tunnel's gusty truth and all four effects together (the paper's 10-Hz
    encoder): the wandering intensity is suspected on both, the fin's delay on all four
    (this seed); on the paper's own truth, neither."""
    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from _truths import spec_of

    said = {}
    for truth in ("paper", "gusty", "mismatch-all"):
        rec = run_tunnel(spec_of(truth, 2))
        found = fit(rec, "ml", ["theta"])["theta"]  # the constant model's is not judged
        said[truth] = " ".join(found.metrics["adequacy"]["suspected"])
    assert said["paper"] == ""
    assert "intensity wanders" in said["gusty"] and "fin acts" not in said["gusty"]
    assert "intensity wanders" in said["mismatch-all"]
    assert "a servo lag or a sensor latency" in said["mismatch-all"]
