"""What a flight log says of its flight: the pad's elevation, the Mach number, the mean
airspeed."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from identification.recordings.recording import Recording
from rocketroll_common.arrays import FloatArray
from rocketroll_physics.atmosphere import isa

__all__ = ["SITE_ELEVATION_KEY", "mach_numbers", "mean_airspeed", "site_elevation"]

#: The metadata key of a recording whose altitude is above the pad: the pad's elevation, m.
SITE_ELEVATION_KEY = "flight.site_elevation_m"


def site_elevation(recording: Recording) -> float:
    """The elevation to add to a recording's ``altitude_m`` for the height above sea level:
    the pad's, where the log says its altitude is above the ground
    (:data:`SITE_ELEVATION_KEY`), 0 otherwise."""
    return float(recording.metadata.get(SITE_ELEVATION_KEY, 0.0))


def mean_airspeed(recordings: Sequence[Recording]) -> float:
    """The airspeed's mean over the flights' time, rounded to 0.1 m/s (at least 0.1): the
    default reference airspeed of a flight fit."""
    total = 0.0
    for recording in recordings:
        assert recording.airspeed_mps is not None
        total += float(np.trapezoid(recording.airspeed_mps, recording.time_s))
    duration = sum(float(r.time_s[-1] - r.time_s[0]) for r in recordings)
    return max(round(total / duration, 1), 0.1)


def mach_numbers(recording: Recording) -> FloatArray:
    """A flight's Mach number at each sample: its airspeed over the ISA speed of sound at
    its altitude (at sea level without an altitude column)."""
    assert recording.airspeed_mps is not None
    altitude = (
        recording.altitude_m + site_elevation(recording)
        if recording.altitude_m is not None
        else np.zeros(recording.n_samples)
    )
    return np.asarray(recording.airspeed_mps) / np.asarray(isa(altitude).speed_of_sound_mps)
