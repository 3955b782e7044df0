"""The paper's identification pipeline and everything it stands on.

* :mod:`identification.model` -- the one roll model (eq. 36/49, servo eq. 23),
  compiled once (:mod:`identification.compiled`); :mod:`identification.paper` --
  the paper's printed values, once.
* :mod:`identification.recordings` -- recording format v1, the importer of foreign
  CSV logs, what a flight log says of its flight.
* :mod:`identification.instruments` -- the virtual wind tunnel and flight recorder
  (synthetic data, known truth, a rocket outside the model), the bundled recordings.
* :mod:`identification.estimation` -- the Kalman filter, its smoothers and maximum
  likelihood on them.
* :mod:`identification.methods` -- every identification method behind one
  ``method=``: the paper's steps and pipeline, output error, maximum likelihood
  with posterior ``u_d``, the flight method; every fit's adequacy.
* :mod:`identification.reports` -- tables, figures and ``report.md``.

Each sub-package imports only those above it in this list (and the roll model).

The errors live in :mod:`rocketroll_common.errors` (``RocketrollError`` and
``UsageError`` are re-exported here, where they used to be defined).
"""

from identification.model import PAPER_CONSTANT, PAPER_THETA, RollParams, Servo, simulate
from identification.recordings.recording import (
    Recording,
    RecordingError,
    load_recording,
    save_recording,
)
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
