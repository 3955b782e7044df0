"""Fit adequacy tells right models from wrong ones, on truths the tests make.

Wrong on purpose: the gain held 30 % off, constant damping fitted to a rocket whose
damping rises steeply with the fin, and the fin command read through eq. 23's servo
where the real one was ten times slower.  Right: the maximum-likelihood fit of each.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from identification.adequacy import VERDICTS, Adequacy, adequacy
from identification.bundled import bundled_path, load_bundled
from identification.methods import fit
from identification.ml import maximum_likelihood, posterior_given
from identification.model import RollParams
from identification.pipeline import IdentifyOptions, model_inputs
from identification.recording import Recording
from identification.tunnel import TunnelSpec, run_tunnel
from rocketroll.cli import main as rocketroll

PRBS: dict[str, Any] = {
    "schedule": "prbs",
    "log_dt": 0.01,
    "duration": 58.0,
    "pulse": 0.5,
    "lead": 2.0,
}


def _verdict(rec: Recording, model: str, params: RollParams | None = None) -> Adequacy:
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
    right = _verdict(rec, "theta")
    assert right.verdict == "good", right.reasons
    assert right.rate_r2 > 0.5 and right.fin_share < 0.15
    found = maximum_likelihood(rec, "theta")
    wrong = _verdict(rec, "theta", replace(found.params, alpha=1.3 * found.params.alpha))
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
