"""rocketroll: rocket roll dynamics under turbulence -- the command line.

The distribution's packages, lowest layer first::

    rocketroll_common  errors, atomic files, headless figures, settings, registries
    identification     the paper's pipeline, recording format, roll model, virtual tunnel
    disturbances       database of identified parameters and u_d traces
    rollenv            Gymnasium environments RocketRoll-v0 and its variants
    agents             controllers, training and the evaluation protocol

This package holds only the ``rocketroll`` command line (``rocketroll`` or
``python -m rocketroll``), which sits above all of them.
"""

from rocketroll_common import __version__

__all__ = ["__version__"]
