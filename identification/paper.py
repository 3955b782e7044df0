"""What the paper reports, written once: the values every comparison reads.

The numbers are kept as the paper prints them (strings, so a table shows the
paper's own digits); :func:`value` gives them as floats.  The roll model's
reference parameters (:data:`identification.model.PAPER_THETA`,
``PAPER_CONSTANT``), the virtual tunnel's schedule and ground truth, the
identification's tables and report all read them from here.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType

__all__ = [
    "HISTOGRAM_MAD",
    "INTERVAL",
    "MEAN_ABS_RATE_DPS",
    "NOISE_10",
    "PARAMETERS",
    "RESIMULATION",
    "T0_LAST_S",
    "TABLE1",
    "TABLE1_END_S",
    "value",
]

#: The identified parameters (eq. 17, 30, 46, 48; Figs. 5, 12), as printed.
PARAMETERS: Mapping[str, str] = MappingProxyType(
    {
        "alpha": "0.6590",
        "beta_dps": "2.8856",
        "theta_bar_deg": "4.38",
        "steady_state_r2": "0.9914",
        "a_per_s": "1.314",
        "b_per_s2": "0.8665",
        "alpha_bar_per_deg_s": "-0.0289",
        "beta_bar_per_s": "2.4075",
        "damping_vs_fin_r2": "0.8280",
    }
)
#: Re-simulation errors (§3.5): rate MAE, rate SD (°/s), angle MAE, angle SD (°).
#: The θ model's angle error is a *median* in the paper's text (footnote ¹).
RESIMULATION: Mapping[str, tuple[str, str, str, str]] = MappingProxyType(
    {
        "constant": ("0.094", "0.073", "0.13", "0.11"),
        "theta": ("0.097", "0.078", "0.18 ¹", "0.14"),
    }
)
#: 90 % intervals of ``u_d`` (§3.2), °.
INTERVAL: Mapping[str, str] = MappingProxyType(
    {"theta": "[-13.38, 14.28]", "constant": "[-14.07, 15.15]"}
)
#: Mean absolute error between the ``u_d`` histograms and the fitted normals (§3.4).
HISTOGRAM_MAD: Mapping[str, str] = MappingProxyType({"theta": "0.0278", "constant": "0.0294"})
#: The noise study at η = 10 % (§3.3): MAE and P90 of ``u_d``, °.
NOISE_10 = (0.62, 1.49)
#: Breakpoint of the 8th step's bi-linear fit (§2.5), s.
T0_LAST_S = 1.61
#: Mean absolute roll rate of the experiment (abstract), °/s.
MEAN_ABS_RATE_DPS = 16.4
#: Table 1: (start time s, fin angle °) of each step; 0° before 68.1 s.
TABLE1: tuple[tuple[float, float], ...] = (
    (68.1, 13.33),
    (131.4, -13.33),
    (194.7, 26.67),
    (258.2, -26.67),
    (321.7, 40.00),
    (384.7, -40.00),
    (448.3, 40.00),
    (511.6, -26.67),
)
#: End of the Table 1 run, s.
TABLE1_END_S = 573.0


def value(key: str) -> float:
    """A parameter of :data:`PARAMETERS` as a float (``value("alpha") == 0.659``)."""
    return float(PARAMETERS[key])
