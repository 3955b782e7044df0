"""The paper's identification pipeline and everything it stands on.

* :mod:`identification.model` -- the one roll model (eq. 36/49, servo eq. 23).
* :mod:`identification.recording` -- recording format v1.
* :mod:`identification.importer` -- foreign CSV logs into format v1.
* :mod:`identification.tunnel` -- the virtual wind tunnel (synthetic data, known truth).
* :mod:`identification.bundled` -- the recordings shipped with the package.
"""

from identification.model import PAPER_CONSTANT, PAPER_THETA, RollParams, Servo, simulate
from identification.recording import Recording, RecordingError, load_recording, save_recording

__all__ = [
    "PAPER_CONSTANT",
    "PAPER_THETA",
    "Recording",
    "RecordingError",
    "RollParams",
    "Servo",
    "load_recording",
    "save_recording",
    "simulate",
]
