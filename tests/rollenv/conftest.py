"""Fixtures and helpers of the RocketRoll environment tests.

Banks of bare arrays (:func:`array_bank`) are built once per process and
shared, so Hypothesis tests can use them without function-scoped fixtures.
``default_db`` (root conftest) builds the session's default database once,
for the tests that draw from the real disturbance traces.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from disturbances.bank import TraceBank
from identification.model import RollParams

#: Distinct θ-model parameters, one per trace of :func:`array_bank` (a(θ) > 0 over the
#: whole box they span, so domain randomisation accepts them).
THETA_PARAMS = (
    RollParams(0.62, 3.6, 2.3, -0.030),
    RollParams(0.70, 4.9, 2.6, -0.022),
    RollParams(0.66, 4.2, 2.0, -0.010),
    RollParams(0.64, 3.9, 2.45, 0.004),
)
#: The same rockets with constant damping.
CONSTANT_PARAMS = tuple(p.with_constant_damping(1.1 + 0.2 * k) for k, p in enumerate(THETA_PARAMS))
#: Trace lengths of :func:`array_bank`, samples of 0.1 s (all longer than a 60-s episode).
LENGTHS = (700, 950, 640, 1200)


@functools.cache
def array_bank(model: str = "theta") -> TraceBank:
    """Four random ``u_d`` traces (Δt = 0.1 s) with distinct parameters."""
    params = THETA_PARAMS if model == "theta" else CONSTANT_PARAMS
    rng = np.random.default_rng(20240611)
    traces = []
    for k, (n, p) in enumerate(zip(LENGTHS, params, strict=True)):
        u = np.cumsum(rng.normal(0.0, 0.3, n)) * 0.2 + rng.normal(0.0, 1.5, n)
        one = TraceBank.from_arrays([u], dt_s=0.1, params=p).traces[0]
        traces.append(dataclasses.replace(one, id=k, uid=f"{one.uid}-{k}"))
    return TraceBank(traces, f"array bank ({model})")


def wrap(angle_deg: float) -> float:
    """An angle difference in [-180°, 180°), computed independently of the package."""
    return (angle_deg + 180.0) % 360.0 - 180.0


@pytest.fixture(scope="session")
def bank() -> TraceBank:
    """:func:`array_bank` of the θ model."""
    return array_bank("theta")
