"""The core's array layouts, declared once: each column's name and index.

The compiled kernel reads columns by index, everyone else by name; both use
these enumerations (numba treats their members as compile-time constants), so
a layout and its users cannot drift apart.  ``tests/rollenv/test_layout.py``
checks that they agree.

* :class:`State` -- columns of :attr:`RollBatch.state <rollenv.core.RollBatch.state>`,
  the true state of each env;
* :class:`Obs` -- entries of the observation (what a flight computer reads);
* :class:`Param` -- columns of :attr:`RollBatch.params`, the rocket of each env
  (the fields of :class:`identification.model.RollParams`, in order);
* :class:`Scale` -- columns of the per-step multipliers of the rocket's
  parameters (a rocket that changes during an episode, e.g. with airspeed);
* :class:`Cursor` -- columns of :attr:`RollBatch.cursor`: where each env is
  in its episode and in its ``u_d`` and multiplier sequences;
* :class:`Link` -- columns of :attr:`RollBatch.link <rollenv.core.RollBatch.link>`,
  each env's rig (the fin's linkage and the sensors' latency);
* :class:`Cfg` -- the scalars of :meth:`RollConfig.kernel_settings
  <rollenv.config.RollConfig.kernel_settings>`.
"""

from __future__ import annotations

from collections.abc import Mapping
from enum import IntEnum
from types import MappingProxyType

import numpy as np

from identification.model import RollParams
from rocketroll_common.arrays import FloatArray

__all__ = [
    "OBSERVATION_NAMES",
    "PARAM_FIELDS",
    "Cfg",
    "Cursor",
    "Link",
    "Obs",
    "Param",
    "Scale",
    "State",
    "params_of_row",
    "row_of_params",
]


class State(IntEnum):
    """Columns of the true state."""

    RATE = 0  #: roll rate v, °/s
    ANGLE = 1  #: roll angle φ, ° (unwrapped)
    FIN = 2  #: the servo's actual fin angle θ, °
    COMMAND = 3  #: the last fin command, °
    GYRO_ANGLE = 4  #: the flight computer's angle: the gyro's readings integrated, °
    SERVO = 5  #: the rate-limited servo ahead of the fin (a lagging or loose linkage), °
    DRIVE = 6  #: the fin's drive: the servo through the linkage's lag, before its play, °


class Obs(IntEnum):
    """Entries of the observation."""

    ERROR = 0  #: tracking error: ° (angle task, wrapped to ±180°) or °/s (rate task)
    RATE = 1  #: measured roll rate, °/s (gyro)
    FIN = 2  #: fin angle, °
    COMMAND = 3  #: last fin command, °


#: The observation's entries by name, in order (``normalize.json`` records them).
OBSERVATION_NAMES: tuple[str, ...] = tuple(
    {
        Obs.ERROR: "tracking_error",
        Obs.RATE: "roll_rate_dps",
        Obs.FIN: "fin_deg",
        Obs.COMMAND: "fin_cmd_deg",
    }[member]
    for member in Obs
)


class Param(IntEnum):
    """Columns of the rocket's parameters (eq. 36/49)."""

    ALPHA = 0  #: gain α, (°/s)/°
    THETA_BAR = 1  #: asymmetry θ̄, °
    BETA_BAR = 2  #: damping offset β̄ (or the constant a), 1/s
    ALPHA_BAR = 3  #: damping slope ᾱ, 1/(s·°)
    QUADRATIC = 4  #: the damping's growth with the roll rate q (a fraction of a(θ) at 30 °/s)


#: The :class:`~identification.model.RollParams` field of each :class:`Param` column.
PARAM_FIELDS: Mapping[Param, str] = MappingProxyType(
    {
        Param.ALPHA: "alpha",
        Param.THETA_BAR: "theta_bar_deg",
        Param.BETA_BAR: "beta_bar_per_s",
        Param.ALPHA_BAR: "alpha_bar_per_deg_s",
        Param.QUADRATIC: "quadratic_damping",
    }
)


def row_of_params(params: RollParams) -> FloatArray:
    """``params`` as one row of :class:`Param` columns."""
    return np.array([getattr(params, PARAM_FIELDS[p]) for p in Param])


def params_of_row(row: FloatArray) -> RollParams:
    """The :class:`~identification.model.RollParams` of one row of :class:`Param` columns."""
    return RollParams(**{PARAM_FIELDS[p]: float(row[p]) for p in Param})


class Scale(IntEnum):
    """Columns of the per-step multipliers of the rocket's parameters.

    At control step ``k`` the kernel uses ``α·gain[k]`` and the damping
    ``a(θ)·damping[k]`` (``β̄`` and ``ᾱ`` both scaled); θ̄ stays.  With
    airspeed ``V`` and density ``ρ``, eq. 4-8 give ``b ∝ ρV²`` and ``c ∝ ρV``,
    so ``α = b/c`` grows like ``V`` and ``a = c/I`` like ``ρV``
    (:func:`rocketroll_physics.scaling.roll_scales`).  All ones is the rocket of the
    database.
    """

    GAIN = 0  #: multiplies α
    DAMPING = 1  #: multiplies a(θ)


class Cursor(IntEnum):
    """Columns of the per-env integers (``RollBatch.step_count`` and friends are views)."""

    STEP = 0  #: control steps taken in this episode
    U_START = 1  #: index in the concatenated u_d samples of the episode's first sample
    SCALE_START = 2  #: row of the multipliers table at step 0
    SCALE_STRIDE = 3  #: rows per step: 0 (the constant rocket) or 1 (a per-step schedule)


class Cfg(IntEnum):
    """The scalars the kernels read (:meth:`rollenv.config.RollConfig.kernel_settings`)."""

    SUBSTEPS = 0  #: substeps per control step
    H = 1  #: substep length, s
    MAX_MOVE = 2  #: the servo's largest move per substep, °
    FIN_RANGE = 3  #: fin range, °
    TASK_RATE = 4  #: 1 for the rate task, 0 for the angle task
    ENCODER_RES = 5  #: one encoder count, ° (0: no quantisation)
    GYRO_ETA = 6  #: η/100 of eq. 52 (0: no gyro noise)
    GYRO_RANGE = 7  #: gyro full scale, °/s
    ERROR_NORM = 8  #: reward normaliser of the error
    RATE_NORM = 9  #: reward normaliser of the roll rate
    RATE_WEIGHT = 10  #: reward weight of the roll rate (0 in the rate task)
    FIN_WEIGHT = 11  #: reward weight of the fin travel
    TRAVEL_NORM = 12  #: the most the servo travels in a control step, °
    U_SCALE = 13  #: factor on u_d (0: no disturbance)
    SETPOINT_PERIOD = 14  #: control steps between setpoint changes
    ERROR_MAX = 15  #: bound of the observed error
    U_PER = 16  #: substeps per u_d sample (set by the bank)
    ANGLE_GYRO = 17  #: 1: the angle is the integrated gyro (flight), 0: the encoder


class Link(IntEnum):
    """Columns of :attr:`RollBatch.link <rollenv.core.RollBatch.link>`: each env's rig
    (:class:`identification.model.Rig`) as the kernel reads it."""

    DECAY = 0  #: exp(-δt/τ) of the fin's drive lagging the servo (0: no lag)
    RAMP = 1  #: τ·(1 - exp(-δt/τ))/δt, the drive's lag behind a servo ramp (0: no lag)
    HALF = 2  #: half the play between drive and fin, ° (0: none)
    LATENCY = 3  #: the roll sensors' delay, substeps (0: none)
