"""The nominal rocket a deployable controller is designed for, and the open-loop trim floor."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from agents.base import Design, FlightView
from disturbances.bank import TraceBank
from identification.model import RIG_LIMITS, Rig, RollParams

__all__ = ["NominalModel", "TrimController", "make_trim"]


@dataclass(frozen=True)
class NominalModel:
    """One first-order roll model standing for all rockets of a database split.

    ``dv/dt = -a·(v - α·(θ + θ̄ + u_d))`` (eq. 29/36), linearised about the
    trim fin angle ``θ = -θ̄``: there the θ-dependent damping of eq. 49,
    ``a(θ) = ᾱ·|θ + θ̄| + β̄``, is ``β̄``, so ``a = β̄`` (for the constant
    model ``ᾱ = 0`` and ``β̄`` is ``a`` itself).

    Attributes
    ----------
    a_per_s : float
        Damping at trim, 1/s.
    alpha : float
        Gain α, (°/s) per °; negative where a positive fin rolls the rocket negative (an
        aileron convention), never 0.
    theta_bar_deg : float
        Asymmetry θ̄, ° (trim fin angle ``-θ̄``).
    source : str
        Where the numbers come from.
    alpha_bar_per_deg_s : float
        Slope ᾱ of the damping (eq. 48), for controllers that model ``a(θ)``
        away from trim (:mod:`agents.observer`); 0 is constant damping.
    rig : Rig
        The servo's linkage and the roll sensors' latency the design expects
        (:class:`~identification.model.Rig`; the model's ideal rig by default).
    """

    a_per_s: float
    alpha: float
    theta_bar_deg: float
    source: str = "given"
    alpha_bar_per_deg_s: float = 0.0
    rig: Rig = field(default_factory=Rig)

    def __post_init__(self) -> None:
        if not np.isfinite(self.a_per_s) or self.a_per_s <= 0:
            raise ValueError(f"NominalModel.a_per_s must be positive, got {self.a_per_s!r}")
        if not np.isfinite(self.alpha) or self.alpha == 0:  # negative: an aileron convention
            raise ValueError(f"NominalModel.alpha must be a non-zero number, got {self.alpha!r}")
        for name in ("theta_bar_deg", "alpha_bar_per_deg_s"):
            if not np.isfinite(getattr(self, name)):
                raise ValueError(f"NominalModel.{name} must be finite, got {getattr(self, name)}")

    @property
    def params(self) -> RollParams:
        """The rocket as :class:`~identification.model.RollParams` (eq. 49: ``β̄ = a``)."""
        return RollParams(self.alpha, self.theta_bar_deg, self.a_per_s, self.alpha_bar_per_deg_s)

    @classmethod
    def from_bank(cls, bank: TraceBank) -> NominalModel:
        """The median identified rocket of ``bank`` (use the *train* split: the test
        split's parameters are what an evaluation must not have seen), with the median of
        its traces' rigs."""
        if len(bank) == 0:
            raise ValueError(f"{bank.description} has no traces to take a nominal model from")
        p = np.array(
            [
                [q.beta_bar_per_s, q.alpha, q.theta_bar_deg, q.alpha_bar_per_deg_s]
                for q in bank.params
            ]
        )
        a, alpha, theta_bar, alpha_bar = np.median(p, axis=0)
        rigs = np.array([[getattr(r, name) for name in RIG_LIMITS] for r in bank.rigs])
        rig = Rig(**dict(zip(RIG_LIMITS, np.median(rigs, axis=0).tolist(), strict=True)))
        return cls(
            float(a),
            float(alpha),
            float(theta_bar),
            f"median of {bank.description}",
            float(alpha_bar),
            rig,
        )


class TrimController:
    """Open loop: fins held at the nominal trim ``-θ̄``, the floor every controller must beat.

    With ``θ = -θ̄`` the steady roll rate of the nominal rocket is zero
    (eq. 16); the rocket drifts with the turbulence and with the difference
    between its own θ̄ and the nominal one.
    """

    name = "trim"

    def __init__(self, model: NominalModel, fin_range_deg: float = 40.0) -> None:
        self.model = model
        fin = min(max(-model.theta_bar_deg, -fin_range_deg), fin_range_deg)
        self._action = np.array([fin / fin_range_deg], dtype=np.float32)

    def reset(self, env: FlightView) -> None:
        """Nothing to forget."""

    def act(self, obs: NDArray[np.float32], env: FlightView) -> NDArray[np.float32]:
        """The trim command, whatever ``obs`` says."""
        return self._action.copy()


def make_trim(design: Design) -> TrimController:
    """``--policy trim``: the trim floor of the train split's nominal rocket."""
    design.no_argument("trim")
    return TrimController(NominalModel.from_bank(design.train_bank), design.config.fin_range_deg)
