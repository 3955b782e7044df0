"""The fin's linkage, the sensors' latency and a quadratic damping, identified where the
data can tell them.

The roll model drives the rocket by the servo of eq. 23 and reads it at once.  A
real rig adds a lag between servo and fin, play in the linkage and late sensors
(:class:`identification.model.Linkage`, ``RollConfig.sensor_latency_s``); a
replay without them flatters every feedback controller
(``docs/results/closed-loop-fidelity.md``).  :func:`identify_actuation` looks for
each as an optional term, admitted by a likelihood-ratio test at a stated level
so that a rig inside the model keeps the model:

* **servo lag and backlash**, from a measured fin column (``fin_deg``) against
  the command: least squares of the fin through the servo and a
  :class:`~identification.model.Linkage` (on 1-ms steps), the residual variance
  floored at the fin sensor's resolution; each term tested against the fit
  without it (Gaussian likelihood ratio; a parameter on its boundary at 0, so
  half a χ²(1) tail);
* **sensor latency**, from the roll response: the maximum-likelihood fit with the
  fin delayed by each candidate on the fine grid (:func:`identification.methods.ml.delay_search`),
  tested against no delay the same way.  Below one logging interval a latency
  cannot be resolved, and the answer says so;
* **quadratic damping**, a damping that grows with the roll rate
  (``a(θ)·(1 + q·|v|/v₀)``, ``v₀`` :data:`~identification.model.QUADRATIC_RATE_DPS`),
  from the roll response with the rig found above: the coefficient's profile likelihood
  (:func:`identification.methods.ml.quadratic_search`), tested against ``q = 0`` (two-sided:
  ``q`` may be of either sign), with its 95 % interval, which says how well the
  recording tells it.  It belongs to the rocket, not the rig: the environment does not
  fly it yet.

A likelihood ratio assumes white residuals; a fin's residuals are not, so the
level is a screen, not an exact size (``benchmarks/actuation.py`` measures how
often each term is admitted on truths with and without it).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from identification.compiled import linkage_path
from identification.instruments.reference import fine_steps
from identification.methods.pipeline import IdentifyOptions
from identification.methods.terms import MAX_LATENCY_S, boundary_p
from identification.model import (
    QUADRATIC_RATE_DPS,
    RIG_KEYS,
    RIG_LIMITS,
    TERM_LEVEL,
    Linkage,
    Rig,
    Servo,
)
from identification.recordings.recording import Recording, StatedRig

__all__ = [
    "LEVEL",
    "MAX_LATENCY_S",
    "Actuation",
    "Term",
    "fit_linkage",
    "identify_actuation",
]

#: The level at which each term is admitted (:data:`identification.model.TERM_LEVEL`).
LEVEL = TERM_LEVEL
#: The largest lag and play looked for (a rig's range), s and °.
MOST_LAG, MOST_PLAY = RIG_LIMITS["lag_s"], RIG_LIMITS["backlash_deg"]
#: The fin sensor's resolution when the column does not show one, °.
FIN_RESOLUTION_DEG = 0.01


@dataclass(frozen=True)
class Term:
    """One optional term: its estimate, the likelihood-ratio statistic against the model
    without it, the p-value, whether it is admitted, and what limits it (``note``).

    A term the recording cannot tell (``estimable`` false: the linkage without both fin
    columns) is not tested; its ``note`` says what it needs, and its row shows no test."""

    name: str
    value: float
    unit: str
    statistic: float
    p_value: float
    admitted: bool
    note: str = ""
    #: The estimate, admitted or not, and its 95 % interval, where the test gives one.
    estimate: float | None = None
    interval: tuple[float, float] | None = None
    estimable: bool = True

    def line(self) -> str:
        if not self.estimable:
            return f"{self.name:17s} not estimable: {self.note}"
        said = "admitted" if self.admitted else "not admitted"
        tail = f"; {self.note}" if self.note else ""
        p = "p < 1e-9" if self.p_value < 1e-9 else f"p {self.p_value:.2g}"
        return (
            f"{self.name:17s} {self.value:8.4g} {self.unit:2s}  LR {max(self.statistic, 0.0):9.2f}"
            f"  {p:9s} {said}{tail}"
        )


@dataclass(frozen=True)
class Actuation:
    """What :func:`identify_actuation` found: the rig of the admitted terms (0 where a term
    is not admitted) and every term's test."""

    rig: Rig
    terms: tuple[Term, ...]
    level: float

    def lines(self) -> list[str]:
        head = f"beyond the model (each term admitted at p < {self.level:g}):"
        return [head, *(f"  {t.line()}" for t in self.terms)]

    def settings(self) -> dict[str, float]:
        """The settings that state it (``rocketroll identify``'s and the environment's)."""
        return {setting: getattr(self.rig, f) for f, (setting, _) in RIG_KEYS.items()}


def _resolution(fin: np.ndarray) -> float:
    steps = np.abs(np.diff(fin))
    steps = steps[steps > 1e-9]
    return float(steps.min()) if steps.size else FIN_RESOLUTION_DEG


def fit_linkage(recording: Recording, servo: Servo, level: float = LEVEL) -> tuple[Term, Term]:
    """Servo lag and backlash from the measured fin column against the command.

    Raises ``ValueError`` where the recording has no measured fin or no command.
    """
    if recording.fin_deg is None or recording.fin_cmd_deg is None:
        raise ValueError(f"{recording.name}: needs both fin_cmd_deg and a measured fin_deg")
    dt = float(np.median(np.diff(recording.time_s)))
    per, _ = fine_steps(dt)  # the linkage on the reference integrator's 1-ms steps
    command = np.repeat(np.asarray(recording.fin_cmd_deg, dtype=float)[:-1], per)
    fin = np.asarray(recording.fin_deg, dtype=float)
    floor = max(_resolution(fin), FIN_RESOLUTION_DEG) ** 2 / 12.0
    n = fin.size

    def sse(lag: float, play: float) -> float:
        path = linkage_path(command, float(fin[0]), dt / per, servo, Linkage(lag, play))
        r = path[::per] - fin
        return float(r @ r) + n * floor

    def fitted(free: tuple[bool, bool]) -> tuple[float, float, float]:
        def objective(x: np.ndarray) -> float:
            lag = abs(float(x[0])) if free[0] else 0.0
            play = abs(float(x[1])) if free[1] else 0.0
            return sse(min(lag, MOST_LAG), min(play, MOST_PLAY))

        best: tuple[float, float, float] | None = None
        for start in ((0.02, 0.2), (0.1, 1.0)):
            res = optimize.minimize(
                objective, np.array(start), method="Nelder-Mead",
                options={"xatol": 1e-4, "fatol": 1e-10 * n, "maxiter": 400},
            )  # fmt: skip
            lag = min(abs(float(res.x[0])), MOST_LAG) if free[0] else 0.0
            play = min(abs(float(res.x[1])), MOST_PLAY) if free[1] else 0.0
            if best is None or res.fun < best[2]:
                best = (lag, play, float(res.fun))
        assert best is not None
        return best

    none = sse(0.0, 0.0)
    lag, play, both = fitted((True, True))
    lag_only = fitted((True, False))[2]
    play_only = fitted((False, True))[2]
    terms = []
    for name, value, unit, without in (
        ("servo lag", lag, "s", min(play_only, none)),
        ("backlash", play, "°", min(lag_only, none)),
    ):
        statistic = n * math.log(without / both)
        p = boundary_p(statistic)
        admitted = p < level
        terms.append(
            Term(name, value if admitted else 0.0, unit, statistic, p, admitted,
                 "from the measured fin" if admitted else f"estimate {value:.3g} {unit}")
        )  # fmt: skip
    return terms[0], terms[1]


def identify_actuation(
    recording: Recording,
    options: IdentifyOptions | None = None,
    *,
    model: str = "theta",
    level: float = LEVEL,
    max_latency_s: float = MAX_LATENCY_S,
) -> Actuation:
    """The linkage (from a measured fin column), the sensors' latency and a quadratic
    damping (from the roll response, by maximum likelihood), each admitted at ``level``."""
    from identification.methods.ml import delay_search, quadratic_search
    from identification.methods.pipeline import model_inputs

    opts = IdentifyOptions() if options is None else options
    # What the data show, whatever the user states: the search starts from the model's rig.
    opts = dataclasses.replace(opts, rig=StatedRig(0.0, 0.0, 0.0))
    servo = Servo(rate_limit_dps=opts.servo_rate_dps)
    terms: list[Term] = []
    link = Linkage()
    if recording.fin_deg is not None and recording.fin_cmd_deg is not None:
        lag, play = fit_linkage(recording, servo, level)
        terms += [lag, play]
        link = Linkage(lag.value, play.value)
    else:
        if recording.fin_cmd_deg is None:
            why = "the fin column is the measured fin; the servo's command (fin_cmd) is needed too"
        else:
            why = "the fin column is the servo's command; a measured fin (fin) is needed too"
        for name, unit in (("servo lag", "s"), ("backlash", "°")):
            terms.append(Term(name, 0.0, unit, 0.0, 1.0, False, why, estimable=False))
    inputs = model_inputs(recording, model, opts)
    step = inputs.grid.step_s
    found = delay_search(inputs, model, max_latency_s)
    p = boundary_p(found.statistic)
    latency = found.delay_steps * step
    dt = float(np.median(np.diff(recording.time_s)))
    note = f"resolution {step:g} s"
    if dt > step * 1.5:
        note = f"a latency below the logging interval ({dt:g} s) cannot be resolved"
    admitted = p < level
    terms.append(
        Term("sensor latency", latency if admitted else 0.0, "s", found.statistic, p, admitted,
             note if admitted else f"estimate {latency:.3g} s; {note}")
    )  # fmt: skip
    rig = Rig(
        link.lag_s, link.backlash_deg, min(latency, RIG_LIMITS["latency_s"]) if admitted else 0.0
    )
    found_q = quadratic_search(
        model_inputs(recording, model, dataclasses.replace(opts, rig=StatedRig.of(rig))), model
    )
    p = found_q.p
    q, (low, high) = found_q.coefficient, found_q.interval
    admitted = p < level
    note = (
        f"95 % interval [{low:.2g}, {high:.2g}], × a(θ) at {QUADRATIC_RATE_DPS:g} °/s; "
        "identify --fit-quadratic-damping stores it for the replay"
    )
    terms.append(
        Term("quadratic damping", q if admitted else 0.0, "", found_q.statistic, p, admitted,
             note if admitted else f"estimate {q:.2g}, {note}", q, (low, high))
    )  # fmt: skip
    return Actuation(rig, tuple(terms), level)
