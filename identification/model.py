"""The one roll model: eq. 36/49 of the paper with the servo of eq. 23.

Everything that moves the rocket in this project -- the virtual wind tunnel,
the re-simulation of identified models and the Gymnasium environment -- calls
the functions in this module, so the physics exists exactly once.

Model (paper eq. 36 with eq. 48/49)::

    dv/dt = -a(θ) · (v - α·(θ + θ̄ + u_d))
    a(θ)  = ᾱ·|θ + θ̄| + β̄            (constant damping, eq. 29: ᾱ = 0, β̄ = a)
    dφ/dt = v

with roll rate ``v`` in °/s, roll angle ``φ`` in °, fin angle ``θ`` in °, the
turbulence ``u_d`` as an equivalent fin angle in °, the steady-state gain ``α``
in (°/s)/°, the asymmetry ``θ̄ = β/α`` in ° and the damping ``a`` in 1/s.

Servo (eq. 23): a fin moves ``|Δθ| · 0.4/60`` seconds for a step ``Δθ``, i.e.
at a rate limit of 150 °/s, and is limited to the ±40° range of the experiment.

Integration is exact, not Euler.  Over a piece of length ``h`` the fin moves
linearly from ``θ0`` to ``θ1`` and ``u_d`` is held.  A servo substep is two
such pieces: the ramp at the rate limit, then the hold once the fin reaches
its command, so a ramp that ends inside a substep is followed exactly.  With
``a`` evaluated at the mean fin angle of the piece the ODE is linear with
constant coefficients and a ramp input, whose closed-form solution is
(``z = -a·h``, ``s = α·(θ1 - θ0)/h``)::

    v1 = e^z·v0 + (1 - e^z)·g0 + s·a·h²·φ2(z)
    φ1 = φ0 + g0·h + s·h²/2 + (v0 - g0)·h·φ1(z) - s·h²·φ2(z)

where ``g0 = α·(θ0 + θ̄ + u_d)`` and ``φ1(z) = (e^z - 1)/z``,
``φ2(z) = (e^z - 1 - z)/z²`` are the usual exponential-integrator functions.
This is exact for constant damping; with θ-dependent damping the only
approximation is ``a`` frozen at the piece's mean fin angle while the fin
ramps (second order in ``h``), which ``tests/identification/test_model.py``
bounds against ``scipy.integrate.solve_ivp``.

Because ``a`` depends on the fin angle and not on ``v``, a whole trajectory is
a linear recurrence ``v[k+1] = E[k]·v[k] + c[k]`` whose coefficients are
computed for all substeps at once; :func:`simulate` exploits this.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from identification import paper

FloatArray = NDArray[np.float64]

#: The roll rate at which a quadratic damping coefficient ``q`` is the fraction of ``a(θ)``
#: added (``a(θ)·q·v·|v|/QUADRATIC_RATE_DPS``), °/s: the virtual tunnel's truth, the
#: maximum-likelihood search (:func:`identification.methods.ml.quadratic_search`) and the
#: environment's kernel read it.
QUADRATIC_RATE_DPS = 30.0
#: The least the quadratic damping's factor ``1 + q·|v|/QUADRATIC_RATE_DPS`` may fall to (a
#: negative ``q`` at a rate beyond its data would otherwise leave the rocket undamped):
#: the environment's kernel and :func:`simulate` hold it there.
QUADRATIC_FLOOR = 0.1
#: The level at which a term beyond the paper's model (a servo's lag and play, a latency,
#: the quadratic damping) is admitted by its likelihood-ratio test.
TERM_LEVEL = 0.01

__all__ = [
    "MODELS",
    "MODEL_NAMES",
    "PAPER_CONSTANT",
    "PAPER_THETA",
    "QUADRATIC_FLOOR",
    "QUADRATIC_RATE_DPS",
    "RIG_KEYS",
    "RIG_LIMITS",
    "TERM_LEVEL",
    "TIME_TOL",
    "DampingModel",
    "Disturbance",
    "Linkage",
    "Rig",
    "RollParams",
    "Servo",
    "SimResult",
    "check_model",
    "damping",
    "interval_index",
    "linear_recurrence",
    "linkage_step",
    "model_of",
    "piece_coefficients",
    "quadratic_growth",
    "quadratic_steady_rate",
    "roll_coefficients",
    "roll_step",
    "servo_path",
    "servo_step",
    "simulate",
]


@dataclass(frozen=True)
class RollParams:
    """Intrinsic roll parameters of the rocket (paper eq. 16-17, 29-30, 48).

    Attributes
    ----------
    alpha : float
        Steady-state gain α, (°/s) of roll rate per ° of fin angle (eq. 16).
    theta_bar_deg : float
        Asymmetry θ̄ = β/α as an equivalent fin angle, ° (eq. 30).
    beta_bar_per_s : float
        Damping offset β̄, 1/s (eq. 48).  With ``alpha_bar_per_deg_s = 0`` this
        is the constant damping ``a`` of eq. 29.
    alpha_bar_per_deg_s : float
        Slope ᾱ of the damping versus ``|θ + θ̄|``, 1/(s·°) (eq. 48).
        Zero gives the constant-damping model.
    quadratic_damping : float
        The damping's growth with the roll rate beyond the paper's model: the fraction
        ``q`` of ``a(θ)`` added at :data:`QUADRATIC_RATE_DPS`, the damping being
        ``a(θ)·(1 + q·|v|/QUADRATIC_RATE_DPS)`` (0: the paper's linear roll, eq. 23).
        Identified by :func:`identification.methods.ml.quadratic_search` where the data admit it.
    """

    alpha: float
    theta_bar_deg: float
    beta_bar_per_s: float
    alpha_bar_per_deg_s: float = 0.0
    quadratic_damping: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "alpha",
            "theta_bar_deg",
            "beta_bar_per_s",
            "alpha_bar_per_deg_s",
            "quadratic_damping",
        ):
            value = getattr(self, name)
            if not np.isfinite(value):
                raise ValueError(f"RollParams.{name} must be finite, got {value!r}")
        if self.alpha == 0.0:
            raise ValueError("RollParams.alpha must be non-zero (the fins must act on roll)")

    @classmethod
    def from_steady_state(
        cls, alpha: float, beta: float, beta_bar: float, alpha_bar: float = 0.0
    ) -> RollParams:
        """Build from the paper's steady-state fit ``v_ss = α·θ + β`` (eq. 16).

        Parameters
        ----------
        alpha : float
            α, (°/s)/°.
        beta : float
            β, °/s; the asymmetry is θ̄ = β/α (eq. 30).
        beta_bar : float
            β̄ (or the constant ``a``), 1/s.
        alpha_bar : float, optional
            ᾱ, 1/(s·°).
        """
        if alpha == 0.0:
            raise ValueError("alpha must be non-zero (the fins must act on roll)")
        return cls(
            alpha=alpha,
            theta_bar_deg=beta / alpha,
            beta_bar_per_s=beta_bar,
            alpha_bar_per_deg_s=alpha_bar,
        )

    @property
    def beta_dps(self) -> float:
        """β = α·θ̄, the steady roll rate at zero fin angle, °/s (eq. 16)."""
        return self.alpha * self.theta_bar_deg

    @property
    def is_constant_damping(self) -> bool:
        """True for the constant-damping model of eq. 29 (ᾱ = 0)."""
        return self.alpha_bar_per_deg_s == 0.0

    def damping(self, theta_deg: ArrayLike) -> FloatArray:
        """Damping a(θ), 1/s (eq. 48).  See :func:`damping`."""
        return damping(self, theta_deg)

    def steady_rate(self, theta_deg: ArrayLike, u_d_deg: ArrayLike = 0.0) -> FloatArray:
        """Steady roll rate α·(θ + θ̄ + u_d), °/s, for a held fin angle (eq. 16, 36); with a
        quadratic damping the root ``v`` of ``v·(1 + q·|v|/v₀) = α·(θ + θ̄ + u_d)``."""
        theta = np.asarray(theta_deg, dtype=float)
        linear = self.alpha * (theta + self.theta_bar_deg + np.asarray(u_d_deg, dtype=float))
        return quadratic_steady_rate(linear, self.quadratic_damping)

    def scaled(self, gain: float, damping: float) -> RollParams:
        """The rocket at another airspeed and density: ``α`` times ``gain``, ``ᾱ`` and ``β̄``
        times ``damping``, θ̄ unchanged (eq. 4-8; :func:`rocketroll_physics.scaling.roll_scales`)."""
        return RollParams(
            self.alpha * gain,
            self.theta_bar_deg,
            self.beta_bar_per_s * damping,
            self.alpha_bar_per_deg_s * damping,
            self.quadratic_damping,
        )

    def with_constant_damping(self, a_per_s: float) -> RollParams:
        """The same α and θ̄ with constant damping ``a`` (eq. 29)."""
        return RollParams(self.alpha, self.theta_bar_deg, a_per_s, 0.0, self.quadratic_damping)


def quadratic_growth(speed_dps: ArrayLike, quadratic: float) -> FloatArray:
    """The factor ``1 + q·|v|/QUADRATIC_RATE_DPS`` on a rocket's damping (its gain divided
    by it) at roll speed ``speed_dps`` (``|v|``, °/s), held at or above
    :data:`QUADRATIC_FLOOR`; the environment's kernel computes the same per substep."""
    speed = np.asarray(speed_dps, dtype=float)
    return np.maximum(1.0 + quadratic * speed / QUADRATIC_RATE_DPS, QUADRATIC_FLOOR)


def quadratic_steady_rate(linear_dps: ArrayLike, quadratic: ArrayLike) -> FloatArray:
    """The steady roll rate of a rocket whose linear steady rate is ``linear_dps`` (°/s)
    and whose damping grows by ``quadratic`` of itself at :data:`QUADRATIC_RATE_DPS`
    (either may be an array): the root of ``v·(1 + q·|v|/v₀) = linear`` of the same sign,
    ``linear`` itself at ``q = 0`` (to the bit).  A negative ``q`` has the root only while
    ``4·|q|·|linear| < v₀``, beyond which the damping would vanish: the rate is then held
    at ``v₀/(2·|q|)``."""
    linear = np.asarray(linear_dps, dtype=float)
    k = np.asarray(quadratic, dtype=float) / QUADRATIC_RATE_DPS
    # beyond the largest steady rate of a negative q, 1/(4·|k|), the largest: v₀/(2·|q|)
    size = np.minimum(np.abs(linear), np.where(k < 0.0, 0.25 / np.maximum(-k, 1e-300), np.inf))
    disc = np.maximum(1.0 + 4.0 * k * size, 0.0)
    return np.asarray(np.sign(linear) * (2.0 * size / (1.0 + np.sqrt(disc))))


#: The paper's θ-dependent rocket: α, β from eq. 17 and ᾱ, β̄ from eq. 48 (eq. 49).
PAPER_THETA = RollParams.from_steady_state(
    alpha=paper.value("alpha"),
    beta=paper.value("beta_dps"),
    beta_bar=paper.value("beta_bar_per_s"),
    alpha_bar=paper.value("alpha_bar_per_deg_s"),
)
#: The paper's constant-damping rocket: a = 1.314 1/s from eq. 46.
PAPER_CONSTANT = RollParams.from_steady_state(
    alpha=paper.value("alpha"), beta=paper.value("beta_dps"), beta_bar=paper.value("a_per_s")
)


@dataclass(frozen=True)
class DampingModel:
    """One of the paper's damping models, under the name the whole system uses.

    Attributes
    ----------
    name : str
        ``constant`` or ``theta``: identification results, database rows,
        environment options and command lines all say it this way.
    equation : str
        Where the paper writes it.
    description : str
        One line for help texts.
    constant : bool
        The damping does not depend on the fin angle (ᾱ = 0).
    """

    name: str
    equation: str
    description: str
    constant: bool

    def holds(self, params: RollParams) -> bool:
        """Whether ``params`` are of this model (ᾱ = 0 for the constant one)."""
        return params.is_constant_damping if self.constant else True


#: The damping models, defined once: constant ``a`` (eq. 29, eq. 46) and
#: ``a(θ) = ᾱ·|θ + θ̄| + β̄`` (eq. 48-49).  The order is the order of results.
MODELS: Mapping[str, DampingModel] = MappingProxyType(
    {
        "constant": DampingModel("constant", "eq. 29", "constant damping a (eq. 29)", True),
        "theta": DampingModel(
            "theta", "eq. 49", "fin-angle-dependent damping a(θ) = ᾱ·|θ + θ̄| + β̄ (eq. 49)", False
        ),
    }
)
#: Their names, in order.
MODEL_NAMES: tuple[str, ...] = tuple(MODELS)


def check_model(name: object) -> str:
    """``name`` if it is a damping model of :data:`MODELS`; else a ``ValueError``."""
    if name not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODEL_NAMES)}, not {name!r}")
    return str(name)


def model_of(params: RollParams) -> str:
    """The model whose form ``params`` have: ``constant`` if ᾱ = 0, else ``theta``."""
    return "constant" if params.is_constant_damping else "theta"


@dataclass(frozen=True)
class Servo:
    """Fin servo: rate limit (eq. 23) and mechanical range.

    Attributes
    ----------
    rate_limit_dps : float
        Maximum fin slew rate, °/s.  Eq. 23: 0.4 s per 60° gives 150 °/s.
    range_deg : float
        Fin deflection limit, °; commands are saturated to ±range.
        The experiment used ±40°.
    """

    rate_limit_dps: float = 60.0 / 0.4
    range_deg: float = 40.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate_limit_dps) and self.rate_limit_dps > 0):
            raise ValueError(f"Servo.rate_limit_dps must be > 0, got {self.rate_limit_dps!r}")
        if not (np.isfinite(self.range_deg) and self.range_deg > 0):
            raise ValueError(f"Servo.range_deg must be > 0, got {self.range_deg!r}")

    def lag_s(self, step_deg: ArrayLike) -> FloatArray:
        """Time for a fin step of ``step_deg`` degrees, s (eq. 23)."""
        return np.abs(np.asarray(step_deg, float)) / self.rate_limit_dps


def damping(params: RollParams, theta_deg: ArrayLike) -> FloatArray:
    """Fin-angle-dependent damping ``a(θ) = ᾱ·|θ + θ̄| + β̄`` (paper eq. 48).

    Parameters
    ----------
    params : RollParams
        Model parameters.
    theta_deg : array_like
        Actual fin angle θ, °, any shape.

    Returns
    -------
    ndarray
        a(θ) in 1/s, same shape as ``theta_deg``.
    """
    theta = np.asarray(theta_deg, dtype=float)
    return params.alpha_bar_per_deg_s * np.abs(theta + params.theta_bar_deg) + params.beta_bar_per_s


def servo_step(
    theta_deg: ArrayLike, command_deg: ArrayLike, dt_s: float, servo: Servo
) -> FloatArray:
    """Advance the fin angle toward the command by one step (eq. 23).

    The command is saturated to ``±servo.range_deg`` and the fin moves towards
    it at no more than ``servo.rate_limit_dps``.  The result is the exact fin
    angle at the end of the step for a command held over it.

    Parameters
    ----------
    theta_deg, command_deg : array_like
        Current fin angle and commanded fin angle, °, broadcastable.
    dt_s : float
        Step length, s.
    servo : Servo
        Rate and range limits.

    Returns
    -------
    ndarray
        Fin angle after ``dt_s``, °.
    """
    theta = np.asarray(theta_deg, dtype=float)
    target = np.clip(np.asarray(command_deg, dtype=float), -servo.range_deg, servo.range_deg)
    max_move = servo.rate_limit_dps * dt_s
    return theta + np.clip(target - theta, -max_move, max_move)


def servo_path(command_deg: ArrayLike, theta0_deg: float, dt_s: float, servo: Servo) -> FloatArray:
    """Fin angle at the boundaries of consecutive steps with held commands.

    Parameters
    ----------
    command_deg : array_like, shape (n,)
        Command held over each step, °.
    theta0_deg : float
        Fin angle at the start, °.
    dt_s : float
        Step length, s.
    servo : Servo
        Rate and range limits.

    Returns
    -------
    ndarray, shape (n + 1,)
        Fin angle at times ``0, dt, ..., n·dt``.
    """
    cmd = np.clip(np.asarray(command_deg, dtype=float), -servo.range_deg, servo.range_deg)
    out = np.empty(cmd.size + 1)
    max_move = servo.rate_limit_dps * dt_s
    theta = float(theta0_deg)
    out[0] = theta
    starts = np.flatnonzero(np.diff(cmd)) + 1 if cmd.size else np.empty(0, dtype=np.intp)
    if cmd.size and starts.size < cmd.size // 32:
        # Few command changes (a schedule, a substep-repeated command): within a
        # run of one command the fin approaches it linearly, so each run is
        # one vectorised expression.
        edges = [0, *starts.tolist(), cmd.size]
        for lo, hi in itertools.pairwise(edges):
            reach = max_move * np.arange(1, hi - lo + 1)
            move = np.clip(cmd[lo] - theta, -reach, reach)
            out[lo + 1 : hi + 1] = theta + move
            theta = float(out[hi])
        return out
    # The rate limit makes this a sequential recurrence; plain floats keep it fast.
    for k, target in enumerate(cmd.tolist()):
        delta = target - theta
        theta += max(-max_move, min(max_move, delta))
        out[k + 1] = theta
    return out


@dataclass(frozen=True)
class Linkage:
    """What lies between the servo of eq. 23 and the fin, beyond the model: a first-order
    lag of the fin's drive behind the servo (``τ·dd/dt = θ_servo − d``) and play between
    drive and fin (the fin stays put until its drive is half the play away).  Both 0 is
    the model's direct linkage.

    Attributes
    ----------
    lag_s : float
        Time constant τ of the lag, s.
    backlash_deg : float
        The play, °.
    """

    lag_s: float = 0.0
    backlash_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("lag_s", "backlash_deg"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"Linkage.{name} must be a finite number >= 0, got {value!r}")

    @property
    def direct(self) -> bool:
        """Whether the fin is the servo (no lag, no play)."""
        return self.lag_s == 0.0 and self.backlash_deg == 0.0

    def coefficients(self, step_s: float) -> tuple[float, float, float]:
        """``(decay, ramp, half)`` of :func:`linkage_step` for steps of ``step_s``."""
        if self.lag_s == 0.0:
            return 0.0, 0.0, 0.5 * self.backlash_deg
        decay = math.exp(-step_s / self.lag_s)
        return (
            decay,
            -self.lag_s * math.expm1(-step_s / self.lag_s) / step_s,
            0.5 * self.backlash_deg,
        )


@dataclass(frozen=True)
class Rig:
    """What a rig adds between the command, the fin and the roll sensors, beyond eq. 23:
    the fin's :class:`Linkage` (a lag and play behind the servo) and the sensors'
    latency.  All 0 is the model's rig.  A recording states it (format 1.2's ``rig.*``
    metadata: :data:`RIG_KEYS`), ``rocketroll identify`` takes it from there or its flags,
    the database keeps it with each identification and the environment replays it.

    Attributes
    ----------
    lag_s, backlash_deg : float
        The linkage's time constant, s, and play, °.
    latency_s : float
        The roll sensors' delay, s.
    """

    lag_s: float = 0.0
    backlash_deg: float = 0.0
    latency_s: float = 0.0

    def __post_init__(self) -> None:
        for name, most in RIG_LIMITS.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and 0.0 <= value <= most):
                raise ValueError(f"Rig.{name} must be in [0, {most:g}], got {value!r}")

    @property
    def linkage(self) -> Linkage:
        """The fin's linkage."""
        return Linkage(self.lag_s, self.backlash_deg)

    @property
    def ideal(self) -> bool:
        """Whether the rig adds nothing to the model."""
        return self.linkage.direct and self.latency_s == 0.0

    @classmethod
    def resolved(cls, given: Mapping[str, Any], metadata: Mapping[str, Any]) -> Rig:
        """The rig of settings ``given`` (:data:`RIG_KEYS`'s setting names; None or missing:
        not given) over a recording's ``metadata`` (its ``rig.*`` lines), 0 where neither
        says."""
        values = {}
        for field_name, (setting_name, key) in RIG_KEYS.items():
            value, said = given.get(setting_name), setting_name
            if value is None:
                value, said = metadata.get(key), f"the recording's {key}"
            try:
                number = 0.0 if value is None else float(value)
            except (TypeError, ValueError):
                raise ValueError(f"{said} must be a number, got {value!r}") from None
            most = RIG_LIMITS[field_name]
            if not (np.isfinite(number) and 0.0 <= number <= most):
                raise ValueError(f"{said} must be in [0, {most:g}], got {value!r}")
            values[field_name] = number
        return cls(**values)

    def describe(self) -> str:
        """E.g. ``servo lag 0.05 s, backlash 0.5°, latency 0.03 s``; ``none``."""
        parts = [
            f"{w} {v:g}{u}"
            for w, v, u in (
                ("servo lag", self.lag_s, " s"),
                ("backlash", self.backlash_deg, "°"),
                ("latency", self.latency_s, " s"),
            )
            if v
        ]
        return ", ".join(parts) or "none"


#: :class:`Rig` field -> the largest value it takes (a physical range: half a second of lag
#: or latency, 5° of play).
RIG_LIMITS: Mapping[str, float] = MappingProxyType(
    {"lag_s": 0.5, "backlash_deg": 5.0, "latency_s": 0.5}
)
#: :class:`Rig` field -> (the setting that gives it: ``rocketroll identify``'s options and
#: the environment's, the recording's metadata key that states it).
RIG_KEYS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "lag_s": ("servo_lag_s", "rig.servo_lag_s"),
        "backlash_deg": ("backlash_deg", "rig.backlash_deg"),
        "latency_s": ("sensor_latency_s", "rig.sensor_latency_s"),
    }
)


def linkage_step(
    servo: float,
    drive: float,
    theta: float,
    command: float,
    max_move: float,
    decay: float,
    ramp: float,
    half: float,
) -> tuple[float, float, float]:
    """One step of the servo and its :class:`Linkage`: the servo ``max_move`` at most
    towards ``command``, the fin's drive after it through the lag (exact for the servo's
    ramp over the step: ``decay = exp(−δt/τ)``, ``ramp = τ·(1 − decay)/δt``, both 0 without
    a lag) and the fin after its drive through the play (``half`` of it).  Returns the
    new ``(servo, drive, fin)``; the environment's kernel calls it compiled
    (:data:`identification.compiled.linkage`)."""
    moved = servo + min(max(command - servo, -max_move), max_move)
    drive = moved - ramp * (moved - servo) + decay * (drive - servo)
    fin = theta
    if drive > theta + half:
        fin = drive - half
    elif drive < theta - half:
        fin = drive + half
    return moved, drive, fin


def select(condition: Any, if_true: Any, if_false: Any) -> Any:
    """``np.where``; the environment's compiled kernel gives numba a scalar ``if`` for it."""
    return np.where(condition, if_true, if_false)


#: Below this ``|z|`` the exponential-integrator functions come from their Taylor
#: series (truncation below 1e-18); above it from ``expm1`` (cancellation below 1e-14).
PHI_TAYLOR_BELOW = 0.05


def phi_taylor(z: Any) -> tuple[Any, Any, Any]:
    """``e^z``, ``φ1(z)`` and ``φ2(z)`` from their Taylor series to ``z^8`` (small ``|z|``)."""
    phi2 = 1.0 / 2 + z * (
        1.0 / 6
        + z
        * (
            1.0 / 24
            + z
            * (
                1.0 / 120
                + z
                * (
                    1.0 / 720
                    + z * (1.0 / 5040 + z * (1.0 / 40320 + z * (1.0 / 362880 + z / 3628800)))
                )
            )
        )
    )
    phi1 = 1.0 + z * phi2  # φ1 = 1 + z·φ2
    return 1.0 + z * phi1, phi1, phi2  # e^z = 1 + z·φ1


def phi_direct(z: Any) -> tuple[Any, Any, Any]:
    """``e^z``, ``φ1(z) = (e^z - 1)/z`` and ``φ2(z) = (e^z - 1 - z)/z²`` from ``expm1`` (z ≠ 0)."""
    em1 = np.expm1(z)
    inv = 1.0 / z
    return 1.0 + em1, em1 * inv, (em1 - z) * inv * inv


def phi_functions(z: Any) -> tuple[Any, Any, Any]:
    """``e^z``, ``φ1(z)`` and ``φ2(z)``, accurate to rounding for every ``z`` (arrays too).

    Taylor series below :data:`PHI_TAYLOR_BELOW`, ``expm1`` above.  The
    environment's compiled kernel replaces this function by a scalar branch
    between the same two functions.
    """
    small = np.abs(z) < PHI_TAYLOR_BELOW
    e_t, phi1_t, phi2_t = phi_taylor(z)
    e_d, phi1_d, phi2_d = phi_direct(select(small, 1.0, z))  # no 0/0 in the unused branch
    return select(small, e_t, e_d), select(small, phi1_t, phi1_d), select(small, phi2_t, phi2_d)


def piece_coefficients(
    alpha: Any,
    theta_bar_deg: Any,
    beta_bar_per_s: Any,
    alpha_bar_per_deg_s: Any,
    theta0_deg: Any,
    theta1_deg: Any,
    u_d_deg: Any,
    h_s: Any,
) -> tuple[Any, Any, Any, Any]:
    """Affine update over one piece with the fin linear from θ0 to θ1 (``h_s`` may be 0).

    The closed form of the module docstring, and the only place it is
    written.  It takes plain numbers or arrays (the parameters spelled out,
    not a :class:`RollParams`) and uses only arithmetic and numpy ufuncs, so
    the same source runs vectorised here and compiled by numba in the
    environment's per-env kernel (:mod:`rollenv.core`).

    Returns ``E, c, A, B`` with ``v1 = E·v0 + c`` and ``φ1 = φ0 + A·v0 + B``.
    """
    a = alpha_bar_per_deg_s * np.abs(0.5 * (theta0_deg + theta1_deg) + theta_bar_deg)
    a = a + beta_bar_per_s  # damping a(θ) at the piece's mean fin angle (eq. 48)
    z = -a * h_s
    e, phi1, phi2 = phi_functions(z)
    g0 = alpha * (theta0_deg + theta_bar_deg + u_d_deg)
    sh = alpha * (theta1_deg - theta0_deg)  # s·h: equilibrium-rate change over the piece, °/s
    c = (1.0 - e) * g0 + sh * a * h_s * phi2
    big_a = h_s * phi1
    big_b = g0 * h_s * (1.0 - phi1) + sh * h_s * (0.5 - phi2)
    return e, c, big_a, big_b


def _piece(
    params: RollParams,
    theta0: FloatArray,
    theta1: FloatArray,
    u_d: FloatArray,
    h: FloatArray,
    gain: FloatArray | float = 1.0,
    damping: FloatArray | float = 1.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """:func:`piece_coefficients` for a :class:`RollParams`, its ``α`` times ``gain`` and
    its ``ᾱ``, ``β̄`` times ``damping`` (the flight's scales, eq. 4-8)."""
    p = params
    return piece_coefficients(
        p.alpha * gain,
        p.theta_bar_deg,
        p.beta_bar_per_s * damping,
        p.alpha_bar_per_deg_s * damping,
        theta0,
        theta1,
        u_d,
        h,
    )


def roll_coefficients(
    params: RollParams,
    theta0_deg: ArrayLike,
    theta1_deg: ArrayLike,
    u_d_deg: ArrayLike,
    h_s: float,
    rate_limit_dps: float | None = None,
    *,
    gain: ArrayLike = 1.0,
    damping: ArrayLike = 1.0,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Coefficients of the exact substep update, linear in the rate.

    Over a substep of length ``h_s`` with the fin going from ``theta0_deg`` to
    ``theta1_deg`` and ``u_d_deg`` held::

        v1 = E·v0 + c
        φ1 = φ0 + A·v0 + B

    See the module docstring for the closed form.  With ``rate_limit_dps``
    (a servo), the fin moves at that rate for ``|θ1 - θ0|/rate`` and then
    holds -- the exact path of a rate-limited servo whose ramp may end inside
    the substep -- and the two pieces are composed.  Without it the fin moves
    linearly over the whole substep (e.g. a sampled, measured fin angle).
    All inputs broadcast; ``h_s`` is a scalar.  ``gain`` and ``damping``
    multiply ``α`` and the damping ``a(θ)`` (both ᾱ and β̄) piece by piece:
    the rocket at another airspeed and density (eq. 4-8,
    :func:`rocketroll_physics.scaling.roll_scales`).  The coefficients are the linear
    roll's: a quadratic damping (:attr:`RollParams.quadratic_damping`) enters through
    ``gain`` and ``damping`` at the rate the caller knows (:func:`simulate`, the
    environment's kernel).

    Returns
    -------
    E, c, A, B : ndarray
        ``E`` (dimensionless) and ``A`` (s) multiply ``v0``; ``c`` in °/s and
        ``B`` in °.
    """
    theta0 = np.asarray(theta0_deg, dtype=float)
    theta1 = np.asarray(theta1_deg, dtype=float)
    u_d = np.asarray(u_d_deg, dtype=float)
    g = np.asarray(gain, dtype=float)
    d = np.asarray(damping, dtype=float)
    if rate_limit_dps is None:
        return _piece(params, theta0, theta1, u_d, np.asarray(h_s, dtype=float), g, d)
    h_ramp = np.minimum(np.abs(theta1 - theta0) / rate_limit_dps, h_s)
    e1, c1, a1, b1 = _piece(params, theta0, theta1, u_d, h_ramp, g, d)
    e2, c2, a2, b2 = _piece(params, theta1, theta1, u_d, h_s - h_ramp, g, d)
    # Compose v -> e1·v + c1 -> e2·(e1·v + c1) + c2, and the angle increments alike.
    return e2 * e1, e2 * c1 + c2, a1 + a2 * e1, b1 + a2 * c1 + b2


def roll_step(
    params: RollParams,
    rate_dps: ArrayLike,
    angle_deg: ArrayLike,
    theta0_deg: ArrayLike,
    theta1_deg: ArrayLike,
    u_d_deg: ArrayLike,
    h_s: float,
    rate_limit_dps: float | None = None,
) -> tuple[FloatArray, FloatArray]:
    """One exact substep of eq. 36/49 for arrays of any (broadcastable) shape.

    Parameters
    ----------
    params : RollParams
        Model parameters.
    rate_dps, angle_deg : array_like
        Roll rate v (°/s) and roll angle φ (°) at the start of the substep.
    theta0_deg, theta1_deg : array_like
        Fin angle at the start and end of the substep, °
        (use :func:`servo_step` to get ``theta1_deg``).
    u_d_deg : array_like
        Disturbance as an equivalent fin angle, held over the substep, °.
    h_s : float
        Substep length, s.
    rate_limit_dps : float, optional
        The servo's rate limit: the fin moves at this rate, then holds
        (exact servo path).  Without it, the fin moves linearly over the
        whole substep.

    Returns
    -------
    rate_dps, angle_deg : ndarray
        Roll rate and angle at the end of the substep.

    Examples
    --------
    >>> from identification.model import PAPER_THETA, roll_step
    >>> v, phi = roll_step(PAPER_THETA, 0.0, 0.0, 10.0, 10.0, 0.0, 100.0)
    >>> round(float(v), 6) == round(float(PAPER_THETA.steady_rate(10.0)), 6)
    True
    """
    e, c, big_a, big_b = roll_coefficients(
        params, theta0_deg, theta1_deg, u_d_deg, h_s, rate_limit_dps
    )
    v0 = np.asarray(rate_dps, dtype=float)
    return e * v0 + c, np.asarray(angle_deg, dtype=float) + big_a * v0 + big_b


@dataclass(frozen=True)
class SimResult:
    """Trajectory of :func:`simulate`, sampled at the input grid.

    Attributes
    ----------
    time_s : ndarray, shape (n + 1,)
        Sample times, s.
    fin_deg : ndarray, shape (n + 1,)
        Actual fin angle θ, °.
    rate_dps : ndarray, shape (n + 1,)
        Roll rate v, °/s.
    angle_deg : ndarray, shape (n + 1,)
        Roll angle φ, °.
    """

    time_s: FloatArray
    fin_deg: FloatArray
    rate_dps: FloatArray
    angle_deg: FloatArray

    def __repr__(self) -> str:
        n = self.time_s.size
        return (
            f"SimResult(n={n}, t=[{self.time_s[0]:g}, {self.time_s[-1]:g}] s, "
            f"mean|v|={np.mean(np.abs(self.rate_dps)):.3g} °/s)"
        )


def simulate(
    params: RollParams,
    dt_s: float,
    fin_deg: ArrayLike,
    u_d_deg: ArrayLike = 0.0,
    *,
    rate0_dps: float | None = None,
    angle0_deg: float = 0.0,
    servo: Servo | None = Servo(),
    theta0_deg: float | None = None,
    substeps: int = 10,
    t0_s: float = 0.0,
    gain: ArrayLike = 1.0,
    damping: ArrayLike = 1.0,
) -> SimResult:
    """Simulate eq. 36/49 over a uniform input grid.

    Parameters
    ----------
    params : RollParams
        Model parameters.
    dt_s : float
        Input grid step, s (0.1 s in the paper).
    fin_deg : array_like, shape (n,) or (n + 1,)
        With a ``servo`` (default): the fin *command* held over each of the
        ``n`` intervals, shape (n,); the servo of eq. 23 turns it into the
        actual fin angle.  With ``servo=None``: the *actual* fin angle at the
        ``n + 1`` grid points, shape (n + 1,), linear in between (e.g. a
        measured fin angle).
    u_d_deg : array_like, shape (n,) or scalar
        Disturbance held over each interval, ° of equivalent fin angle.
    rate0_dps : float, optional
        Initial roll rate, °/s.  Default: the steady rate for the initial
        fin angle and disturbance, ``α·(θ0 + θ̄ + u_d[0])``.
    angle0_deg : float
        Initial roll angle, °.
    servo : Servo or None
        Servo model applied to commands; ``None`` if ``fin_deg`` is actual.
    theta0_deg : float, optional
        Initial fin angle with a servo; default: the first command (saturated).
    substeps : int
        Exact-update substeps per interval (10 gives the paper's δt = 0.01 s
        for Δt = 0.1 s).  The servo is resolved on the substep grid.
    t0_s : float
        Time of the first grid point, s.
    gain, damping : float or array_like, shape (n,) or (n * substeps,)
        Factors on ``α`` and on the damping ``a(θ)`` per interval or per
        substep: the rocket in flight (eq. 4-8,
        :func:`rocketroll_physics.scaling.roll_scales`).  The damping's are
        ≥ 0; a gain < 0 is the flow over the fins reversed (a rocket falling
        tail-first).  Default 1: the rocket as identified.

    Returns
    -------
    SimResult
        Trajectory at the ``n + 1`` grid points.
    """
    if not (np.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive number, got {dt_s!r}")
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps must be a positive integer, got {substeps!r}")
    fin = np.asarray(fin_deg, dtype=float)
    if fin.ndim != 1:
        raise ValueError(f"fin_deg must be one-dimensional, got shape {fin.shape}")
    n = fin.size if servo is not None else fin.size - 1
    if n < 1:
        raise ValueError("fin_deg must describe at least one interval")
    u_d = np.broadcast_to(np.asarray(u_d_deg, dtype=float), (n,))
    if not (np.all(np.isfinite(fin)) and np.all(np.isfinite(u_d))):
        raise ValueError("fin_deg and u_d_deg must be finite")
    h = dt_s / substeps

    # Fin angle at every substep boundary, shape (n*substeps + 1,).
    if servo is not None:
        start = fin[0] if theta0_deg is None else float(theta0_deg)
        start = float(np.clip(start, -servo.range_deg, servo.range_deg))
        theta = servo_path(np.repeat(fin, substeps), start, h, servo)
    else:
        frac = np.arange(n * substeps + 1) / substeps
        theta = np.interp(frac, np.arange(n + 1), fin)
    u_fine = np.repeat(u_d, substeps)
    scales = [
        _per_substep(name, x, n, substeps) for name, x in (("gain", gain), ("damping", damping))
    ]

    rate_limit = None if servo is None else servo.rate_limit_dps
    if rate0_dps is None:  # the steady rate of the rocket at the first substep's gain
        gain0 = float(np.ravel(scales[0])[0])
        v0 = float(quadratic_steady_rate(
            gain0 * params.alpha * (theta[0] + params.theta_bar_deg + u_d[0]),
            params.quadratic_damping,
        ))  # fmt: skip
    else:
        v0 = float(rate0_dps)

    def path(gain: FloatArray, damping: FloatArray) -> tuple[FloatArray, ...]:
        e, c, big_a, big_b = roll_coefficients(
            params, theta[:-1], theta[1:], u_fine, h, rate_limit, gain=gain, damping=damping
        )
        return linear_recurrence(e, c, v0), big_a, big_b

    rate, big_a, big_b = path(scales[0], scales[1])
    if params.quadratic_damping != 0.0:
        rate, big_a, big_b = _rate_damped_path(path, rate, scales, params.quadratic_damping)
    angle = np.empty_like(rate)
    angle[0] = angle0_deg
    np.cumsum(big_a * rate[:-1] + big_b, out=angle[1:])
    angle[1:] += angle0_deg

    grid = slice(None, None, substeps)
    time = t0_s + dt_s * np.arange(n + 1, dtype=float)
    return SimResult(time_s=time, fin_deg=theta[grid], rate_dps=rate[grid], angle_deg=angle[grid])


#: :func:`simulate`'s quadratic damping: the most passes over the path, and the change in
#: the damping's factor below which the path has settled.
_QUADRATIC_PASSES, _QUADRATIC_SETTLED = 500, 1e-12


def _rate_damped_path(
    path: Callable[[FloatArray, FloatArray], tuple[FloatArray, ...]],
    rate: FloatArray,
    scales: list[FloatArray],
    quadratic: float,
) -> tuple[FloatArray, ...]:
    """The roll with each substep's damping ``a(θ)·(1 + q·|v|/QUADRATIC_RATE_DPS)`` at its
    starting rate (held at or above :data:`QUADRATIC_FLOOR`) and the gain divided by the
    same: the linear path's factors from ``rate``, the path again with them, until the
    factors settle (each pass a whole vectorised path; the roll's damping makes it a
    contraction wherever the damping stays positive).  The environment's kernel damps a
    moving substep so and a run of held substeps at the mean of its ends' rates."""
    grow = np.ones(rate.size - 1)
    for _ in range(_QUADRATIC_PASSES):
        new = quadratic_growth(np.abs(rate[:-1]), quadratic)
        settled = float(np.max(np.abs(new - grow))) < _QUADRATIC_SETTLED
        grow = new
        out = path(scales[0] / grow, scales[1] * grow)
        rate = out[0]
        if settled:
            return out
    raise ValueError(
        f"quadratic_damping {quadratic:g}: the roll did not settle in {_QUADRATIC_PASSES} passes"
    )


def _per_substep(name: str, value: ArrayLike, n: int, substeps: int) -> FloatArray:
    """A scale factor of :func:`simulate`: a number, or one per interval or per substep."""
    x = np.asarray(value, dtype=float)
    if x.ndim == 0:
        pass
    elif x.shape == (n,):
        x = np.repeat(x, substeps)
    elif x.shape != (n * substeps,):
        raise ValueError(
            f"{name} must be a number or have shape ({n},) (per interval) or "
            f"({n * substeps},) (per substep), not {x.shape}"
        )
    if not np.all(np.isfinite(x)):
        raise ValueError(f"{name} must be finite")
    if name == "damping" and not np.all(x >= 0):  # a gain < 0: the flow over the fins reversed
        raise ValueError("damping must be >= 0")
    return x


#: Largest |log| of the decay accumulated inside one block of
#: :func:`linear_recurrence`; keeps every scaled term within e^±20.
_BLOCK_LOG_SPAN = 20.0


def linear_recurrence(e: FloatArray, c: FloatArray, x0: float) -> FloatArray:
    """``x[k+1] = e[k]·x[k] + c[k]`` from ``x[0] = x0``; returns all n+1 values.

    Vectorised in blocks: inside a block starting from ``xs`` with the running
    products ``Q[k] = e[0]···e[k]`` (all positive here, ``e = exp(-a·h)``),
    ``x[k+1] = Q[k]·(xs + Σ_{j≤k} c[j]/Q[j])``.  The block length keeps
    ``|log Q|`` below :data:`_BLOCK_LOG_SPAN`, so the scaled terms neither
    overflow nor lose precision; only the block starts are sequential.
    """
    n = e.size
    out = np.empty(n + 1)
    out[0] = x0
    if n == 0:
        return out
    log_e = np.log(e)
    span = float(np.max(np.abs(log_e)))
    length = n if span == 0.0 else int(max(1, min(n, _BLOCK_LOG_SPAN // span)))
    blocks = -(-n // length)
    pad = blocks * length - n
    log_q = np.cumsum(np.pad(log_e, (0, pad)).reshape(blocks, length), axis=1)
    q = np.exp(log_q)
    t = np.cumsum(np.pad(c, (0, pad)).reshape(blocks, length) * np.exp(-log_q), axis=1)
    starts = np.empty(blocks)
    x = float(x0)
    q_end, t_end = q[:, -1].tolist(), t[:, -1].tolist()
    for b in range(blocks):
        starts[b] = x
        x = q_end[b] * (x + t_end[b])
    out[1:] = (q * (starts[:, None] + t)).ravel()[:n]
    return out


#: Tolerance when comparing sample times with step and interval boundaries, s.
TIME_TOL = 1e-9


def interval_index(edges: ArrayLike, time_s: ArrayLike) -> NDArray[np.intp]:
    """Index ``k`` with ``edges[k] <= t < edges[k+1]`` (-1 before the first edge)."""
    found = np.searchsorted(edges, np.asarray(time_s, dtype=float) + TIME_TOL, side="right")
    return np.asarray(found - 1, dtype=np.intp)


@dataclass(frozen=True, eq=False)
class Disturbance:
    """Identified disturbance ``u_d(t)`` for one model (eq. 35-44).

    Attributes
    ----------
    model : str
        ``constant`` (``u_d,constant``, eq. 50) or ``theta`` (``u_d,θ``, eq. 51).
    params : RollParams
        The model it was identified with.
    interval_s : float
        Δt, the length over which ``u_d`` is constant (0.1 s).
    start_s : ndarray, shape (N_total,)
        ``t_{i-1}`` of each interval, s.
    u_d_deg : ndarray, shape (N_total,)
        ``u_d,i``, ° of equivalent fin angle (eq. 44).
    """

    model: str
    params: RollParams
    interval_s: float
    start_s: FloatArray
    u_d_deg: FloatArray

    def at(self, time_s: ArrayLike) -> FloatArray:
        """The piecewise-constant ``u_d(t)`` of eq. 44 (held past the last interval), °."""
        t = np.asarray(time_s, dtype=float)
        k = interval_index(self.start_s, t)
        return np.asarray(self.u_d_deg[np.clip(k, 0, self.u_d_deg.size - 1)], dtype=float)
