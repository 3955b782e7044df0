"""Observer-based roll control: the turbulence estimated on the fly and cancelled.

The paper treats the turbulence as an equivalent fin angle ``u_d`` (eq. 36:
``θ + θ̄ + u_d`` drives the roll), which makes it a *matched* disturbance:
whatever of it can be predicted, the fins can cancel.  This module does that
with the identification's own state-space model (:mod:`identification.methods.ml`),
run forward in real time:

* :class:`TurbulenceModel` -- the autoregressive model of ``u_d`` on the control
  grid, fitted to the train split's traces (pooled least squares, order by
  AIC as in :mod:`identification.methods.ml`), and a slow random-walk *offset* that
  carries what is constant in an episode: the rocket's own θ̄ against the
  nominal one, and any other steady mismatch.
* :class:`RollObserver` -- a Kalman filter on ``[v, ψ, u_d[k], ...,
  u_d[k-p+1], b]``: roll rate, angle relative to the setpoint, the AR lags
  and the offset.  Its time update is the ML model's
  (:func:`identification.compiled.interval_maps` over the fin path the servo takes
  to the command, :func:`identification.methods.rollspace.roll_transition`,
  :func:`identification.estimation.statespace.predict`), its measurement update the
  ML's for the gyro (:func:`identification.estimation.statespace.update`, the
  multiplicative noise of eq. 52 as ``g²·(v̂² + P_vv)``); the encoder as a
  quantised measurement: the prior of the angle truncated to the count read
  (:meth:`RollObserver._encoder`).  A setpoint step shows as a reading the
  prior puts no mass on; the angle's variance is then widened so the reading
  re-anchors it (the step is unknown, the rest of the state is not).
* :class:`ObserverController` -- LQR state feedback on the observer's
  estimate (:func:`scipy.linalg.solve_discrete_are`), designed on the same
  model linearised at trim with the fin as a state, so the cost weighs the
  fin's move per step.  The gain on the turbulence states is the
  disturbance-observer feedforward (about ``-1`` on ``û_d``: cancellation);
  the offset state gives the integral action of an LQI without an integrator
  that can wind up.
* *On the rig*: the design reads the rig the environment flies
  (:class:`~identification.model.Rig`: the median of the design split's, or
  the ``servo_lag_s``, ``backlash_deg``, ``sensor_latency_s`` settings).  The
  filter runs the servo's linkage forward from its own commands and keeps its
  state at the time the late sensors read (:meth:`RollObserver.present`
  carries it to now); a lag makes the fin's drive a design state; with play the
  command is sent half the play beyond the fin's goal
  (:meth:`ObserverController.through_play`).  On the ideal rig all of it is
  off and the design is the model's, number for number.

Deployable: it reads the observation and its own configuration only.
"""

from agents.observer.controller import (
    DEFAULT_WEIGHTS,
    FLIGHT_WEIGHTS,
    ObserverController,
    designed_on,
    make_observer,
    scheduling,
)
from agents.observer.estimator import RollObserver, TurbulenceModel
from agents.observer.features import ObserverFeatures

__all__ = [
    "DEFAULT_WEIGHTS",
    "FLIGHT_WEIGHTS",
    "ObserverController",
    "ObserverFeatures",
    "RollObserver",
    "TurbulenceModel",
    "designed_on",
    "make_observer",
    "scheduling",
]
