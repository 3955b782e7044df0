"""What every rocketroll package stands on, and nothing of the domain.

The packages of the distribution form layers, lowest first::

    rocketroll_common  errors, files written atomically, headless figures, settings
                       dataclasses and their command lines, registries, the version
    identification     the paper's pipeline, recording format, roll model, virtual tunnel
    disturbances       database of identified parameters and u_d traces
    rollenv            Gymnasium environments RocketRoll-v0 and its variants
    agents             controllers, training and the evaluation protocol
    rocketroll         the ``rocketroll`` command line

A package imports only the packages below it (``tests/test_layers.py`` checks).
This one imports none of them.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rocketroll")
except PackageNotFoundError:  # a source tree that is not installed
    __version__ = "0+unknown"

__all__ = ["__version__"]
