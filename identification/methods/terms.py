"""Terms beyond the paper's model, each admitted by a likelihood-ratio test: the test of a
parameter on its boundary (a lag, a play, a latency: 0 is none), and the sensors' latency
as such a term of any fit (:func:`latency_term`: used by ``ml``, which searches one where
none is stated, and by :mod:`identification.methods.actuation`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from scipy import stats

from identification.model import TERM_LEVEL

__all__ = ["LATENCY_SCREEN", "MAX_LATENCY_S", "boundary_p", "latency_term"]

#: The longest sensor latency looked for, s.
MAX_LATENCY_S = 0.1


def boundary_p(statistic: float) -> float:
    """p of a likelihood ratio for one parameter on its boundary (½χ²₀ + ½χ²₁)."""
    return 0.5 * float(stats.chi2.sf(max(statistic, 0.0), 1)) if statistic > 0.0 else 1.0


#: The rise of twice the log-likelihood at the screen's best delay from which a fit is
#: repeated there (:func:`latency_term`; the screen, at the undelayed fit's parameters, is
#: below the re-fit's).
LATENCY_SCREEN = 1.0


def latency_term(
    step_s: float,
    base: float,
    screen: Callable[[int], float],
    refit: Callable[[int], float],
    level: float = TERM_LEVEL,
    max_latency_s: float = MAX_LATENCY_S,
) -> dict[str, Any]:
    """The sensors' latency as a term of a fit that was made without one: each delay of
    the fin by ``d`` grid steps of ``step_s`` up to ``max_latency_s`` screened
    (``screen(d)``: the −log-likelihood at the undelayed fit's parameters, one pass each);
    where the screen's best is :data:`LATENCY_SCREEN` better than ``base`` (the undelayed
    fit's), the fit is repeated there (``refit(d)``) and at each delay on from it while it
    improves (the screen's peak leans towards none), and the best kept where its
    likelihood-ratio test against none (a parameter on its boundary: half a χ²₁ tail)
    admits it at ``level``.  Returns the term's figures: ``steps`` and ``estimate_s`` (the
    best delay, admitted or not), ``statistic``, ``p``, ``admitted``, ``level``,
    ``resolution_s``, ``searched_s``."""
    delays = range(1, round(max_latency_s / step_s) + 1)
    screened = {d: screen(d) for d in delays}
    top = min(screened, key=lambda d: screened[d])
    found: dict[str, Any] = {
        "steps": 0,
        "estimate_s": 0.0,
        "statistic": 0.0,
        "p": 1.0,
        "admitted": False,
        "level": level,
        "resolution_s": step_s,
        "searched_s": [step_s, delays[-1] * step_s],
    }
    if 2.0 * (base - screened[top]) < LATENCY_SCREEN:
        return found
    fitted: dict[int, float] = {}

    def value(d: int) -> float:
        if d not in fitted:
            fitted[d] = refit(d)
        return fitted[d]

    best = top
    for direction in (1, -1):
        d = best
        while d + direction in screened and value(d + direction) < value(d):
            d += direction
        best = min((best, d), key=value)
    statistic = max(2.0 * (base - value(best)), 0.0)
    p = boundary_p(statistic)
    found.update(steps=best, estimate_s=best * step_s, statistic=statistic, p=p, admitted=p < level)
    return found
