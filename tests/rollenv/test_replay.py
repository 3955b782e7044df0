"""Replay fidelity: the environment reproduces the identification's re-simulation.

Step 9 of the identification (:func:`identification.methods.steps.resimulate`)
simulates a recording open loop with its identified ``u_d``, starting from the
measured velocity and angle of the first sample, with the fin angle of step 5
(the commanded angle through the servo of eq. 23 on the 0.01-s grid).  The
environment, fed the same ``u_d``, parameters, initial state and fin
commands, must follow that trajectory to rounding, and so reach the same
angle error against the recording.

Tolerance: ``rtol = atol = 1e-9`` (° and °/s).  Measured on the bundled
recordings the largest differences are about 3e-12 °/s and 1e-10 ° (over
570 s, angles of a few thousand degrees).  The actions are float64: a float32
action (the space's dtype) rounds the command by up to 2.4e-6° and moves the
replay by up to ~7e-7 °/s and ~1e-4 °, far inside the identification's own
error (0.1°) but not to rounding.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from disturbances.bank import TraceBank
from disturbances.default import open_default
from identification.instruments.bundled import load_bundled
from identification.methods.pipeline import Identification, IdentifyOptions, identify
from identification.recordings.recording import Recording
from rollenv.env import RocketRollEnv

RTOL = ATOL = 1e-9
FAST = IdentifyOptions(noise_runs=0)
#: Two train recordings (the paper's schedule, a random staircase) and a test one.
NAMES = ("tunnel-paper-seed0", "tunnel-staircase-seed10", "tunnel-paper-seed5")

_IDENTIFIED: dict[str, tuple[Recording, Identification]] = {}


def identified(name: str) -> tuple[Recording, Identification]:
    """The bundled recording and its identification, once per process."""
    if name not in _IDENTIFIED:
        recording = load_bundled(name)
        _IDENTIFIED[name] = (recording, identify(recording, FAST))
    return _IDENTIFIED[name]


def pinned_identification(name: str, model: str) -> tuple[np.ndarray, Any]:
    """The bundled recording's ``u_d`` and parameters for ``model`` (run by ``call_pinned``)."""
    dist = identify(load_bundled(name), FAST).disturbances[model]
    return np.asarray(dist.u_d_deg), dist.params


def replay(env, recording, result, *, trace=0):
    """Drive ``env`` with the recording's commands from its first sample; rate and angle."""
    n = recording.n_samples
    _, info = env.reset(
        options={
            "trace": trace,
            "start": 0,
            "rate_dps": float(result.velocity_dps[0]),
            "angle_deg": float(result.angle_deg[0]),
            "fin_deg": float(recording.fin_cmd_deg[0]),
        }
    )
    rate = np.empty(n)
    angle = np.empty(n)
    rate[0], angle[0] = info["roll_rate_dps"], info["roll_deg"]
    truncated = False
    for k in range(n - 1):
        assert not truncated
        action = np.array([recording.fin_cmd_deg[k] / 40.0])  # float64, see the module doc
        _, _, terminated, truncated, info = env.step(action)
        assert not terminated
        rate[k + 1], angle[k + 1] = info["roll_rate_dps"], info["roll_deg"]
    assert truncated  # the whole recording is one episode
    return rate, angle


def check_matches_resimulation(rate, angle, result, model):
    resim = result.resimulations[model]
    np.testing.assert_allclose(rate, resim.rate_dps, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(angle, resim.angle_deg, rtol=RTOL, atol=ATOL)
    # ... and so the same error against the recording as the identification reports.
    angle_mae = float(np.mean(np.abs(angle - result.angle_deg)))
    rate_mae = float(np.mean(np.abs(rate - result.velocity_dps)))
    assert angle_mae <= resim.angle_mae_deg * (1 + 1e-9)
    assert angle_mae == pytest.approx(resim.angle_mae_deg, rel=1e-9)
    assert rate_mae == pytest.approx(resim.rate_mae_dps, rel=1e-9)


@pytest.mark.parametrize("name", NAMES[:2])
def test_resimulation_compares_against_the_recordings_samples(name):
    # What step 9 compares with: the smoothed measured velocity and the encoder angle,
    # at the recording's uniform 0.1-s samples; u_d holds one value per sample interval.
    recording, result = identified(name)
    assert recording.fin_deg is None  # commanded fin through the servo, as in the env
    assert np.allclose(np.diff(recording.time_s), 0.1, rtol=0, atol=1e-9)
    assert recording.time_s[0] == 0.0
    assert result.grid.per_sample == 10
    assert result.grid.step_s == pytest.approx(0.01, rel=1e-12)
    assert recording.roll_deg is not None
    np.testing.assert_array_equal(result.angle_deg, recording.roll_deg)
    for model in ("theta", "constant"):
        resim = result.resimulations[model]
        dist = result.disturbances[model]
        assert dist.u_d_deg.size == recording.n_samples - 1
        assert dist.interval_s == 0.1
        np.testing.assert_allclose(dist.start_s, recording.time_s[:-1], atol=1e-9)
        assert resim.rate_dps.size == resim.angle_deg.size == recording.n_samples
        assert resim.angle_mae_deg == pytest.approx(
            np.mean(np.abs(resim.angle_deg - result.angle_deg)), rel=1e-12
        )
        assert resim.rate_mae_dps == pytest.approx(
            np.mean(np.abs(resim.rate_dps - result.velocity_dps)), rel=1e-12
        )


@pytest.mark.parametrize("model", ["theta", "constant"])
@pytest.mark.parametrize("name", NAMES[:2])
def test_replay_reproduces_the_resimulation(name, model):
    recording, result = identified(name)
    dist = result.disturbances[model]
    assert dist.params == result.model(model)
    assert dist.params.is_constant_damping == (model == "constant")
    bank = TraceBank.from_arrays([dist.u_d_deg], dt_s=0.1, params=dist.params)
    env = RocketRollEnv(
        bank=bank,
        model=model,
        sensors=False,
        setpoint="zero",
        episode_s=(recording.n_samples - 1) / 10,
    )
    rate, angle = replay(env, recording, result)
    check_matches_resimulation(rate, angle, result, model)


def test_replay_of_the_other_model_does_not_match():
    # The check above can fail: the θ model's u_d replayed with the constant model's
    # parameters drifts far from the θ re-simulation.
    recording, result = identified(NAMES[0])
    bank = TraceBank.from_arrays(
        [result.disturbances["theta"].u_d_deg], dt_s=0.1, params=result.constant_model
    )
    env = RocketRollEnv(
        bank=bank, sensors=False, setpoint="zero", episode_s=(recording.n_samples - 1) / 10
    )
    _, angle = replay(env, recording, result)
    assert np.max(np.abs(angle - result.resimulations["theta"].angle_deg)) > 1.0


def test_replay_from_an_offset_continues_the_resimulation():
    # reset(options={"trace", "start", state}) at sample s of the trace, with the
    # re-simulation's state there, continues the re-simulation.
    recording, result = identified(NAMES[1])
    dist = result.disturbances["theta"]
    resim = result.resimulations["theta"]
    assert recording.fin_cmd_deg is not None
    bank = TraceBank.from_arrays([dist.u_d_deg], dt_s=0.1, params=dist.params)
    env = RocketRollEnv(bank=bank, sensors=False, setpoint="zero", episode_s=60.0)
    s = 1234
    _, info = env.reset(
        options={
            "trace": 0,
            "start": s,
            "rate_dps": float(resim.rate_dps[s]),
            "angle_deg": float(resim.angle_deg[s]),
            "fin_deg": float(result.theta_fine[s * result.grid.per_sample]),
        }
    )
    assert info["start_s"] == pytest.approx(s * 0.1)
    assert info["u_d_deg"] == dist.u_d_deg[s]
    for k in range(600):
        _, _, _, truncated, info = env.step(np.array([recording.fin_cmd_deg[s + k] / 40.0]))
        assert info["u_d_deg"] == dist.u_d_deg[s + k]
        assert info["fin_deg"] == pytest.approx(
            result.theta_fine[(s + k + 1) * result.grid.per_sample], abs=1e-9
        )
        assert info["roll_rate_dps"] == pytest.approx(resim.rate_dps[s + k + 1], rel=RTOL, abs=ATOL)
        assert info["roll_deg"] == pytest.approx(resim.angle_deg[s + k + 1], rel=RTOL, abs=ATOL)
    assert truncated


@pytest.mark.parametrize(
    ("name", "model", "split"),
    [(NAMES[0], "theta", "train"), (NAMES[1], "constant", "train"), (NAMES[2], "theta", "test")],
)
def test_replay_through_the_default_database(default_db, name, model, split):
    from rocketroll_common.numerics import call_pinned

    recording, result = identified(name)
    dist = result.disturbances[model]
    # The database is built under the pinned numerics, so the u_d and parameters it is
    # compared with are recomputed so too: unpinned, a processor with AVX-512 differs from
    # them in the last bits.
    pinned_u_d, pinned_params = call_pinned(pinned_identification, name, model)
    with open_default(progress=False) as db:
        (info,) = db.traces(recording=name, method="paper", model=model, kind="identified")
        assert info.split == split
        stored = db.trace(info.uid)
        # The database's trace is this identification's u_d (its noise study aside).
        np.testing.assert_array_equal(stored.u_d_deg, pinned_u_d)
        assert stored.params == pinned_params
        np.testing.assert_allclose(dist.u_d_deg, pinned_u_d, rtol=0, atol=1e-9)
        assert stored.dt_s == 0.1
        one = TraceBank.from_db(db, split, model=model, recording=name)
    assert [t.uid for t in one.traces] == [info.uid]

    # Through a bank of that one trace ...
    env = RocketRollEnv(
        bank=one, sensors=False, setpoint="zero", episode_s=(recording.n_samples - 1) / 10
    )
    rate, angle = replay(env, recording, result)
    check_matches_resimulation(rate, angle, result, model)
    # ... and through the environment's own bank of the split (the paper's traces, not the
    # default ml posterior draws), picked by uid.
    env = RocketRollEnv(
        split=split,
        model=model,
        method="paper",
        disturbance="replay",
        sensors=False,
        setpoint="zero",
        episode_s=(recording.n_samples - 1) / 10,
    )
    assert len(env.bank) > 1
    rate, angle = replay(env, recording, result, trace=info.uid)
    check_matches_resimulation(rate, angle, result, model)
