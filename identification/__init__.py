"""The paper's identification pipeline and everything it stands on.

* :mod:`identification.model` -- the one roll model (eq. 36/49, servo eq. 23).
* :mod:`identification.recording` -- recording format v1.
* :mod:`identification.importer` -- foreign CSV logs into format v1.
* :mod:`identification.tunnel` -- the virtual wind tunnel (synthetic data, known truth).
* :mod:`identification.bundled` -- the recordings shipped with the package.
* :mod:`identification.pipeline` -- the paper's steps 1-6 (``identify``).
* :mod:`identification.methods` -- every identification method behind one ``method=``.
* :mod:`identification.ml` -- maximum likelihood and posterior ``u_d``
  (:mod:`identification.statespace`: Kalman filter and smoothers).
* :mod:`identification.paper` -- the paper's printed values, once.

The errors live in :mod:`rocketroll_common.errors` (``RocketrollError`` and
``UsageError`` are re-exported here, where they used to be defined).
"""

from identification.model import PAPER_CONSTANT, PAPER_THETA, RollParams, Servo, simulate
from identification.recording import Recording, RecordingError, load_recording, save_recording
from rocketroll_common.errors import RocketrollError, UsageError

__all__ = [
    "PAPER_CONSTANT",
    "PAPER_THETA",
    "Recording",
    "RecordingError",
    "RocketrollError",
    "RollParams",
    "Servo",
    "UsageError",
    "load_recording",
    "save_recording",
    "simulate",
]
