"""rocketroll: rocket roll dynamics under turbulence.

The distribution's top-level packages, lowest layer first::

    identification  the paper's pipeline, recording format, roll model, virtual tunnel
    disturbances    database of identified parameters and u_d traces
    rollenv         Gymnasium environment RocketRoll-v0
    agents          PID and PPO baselines, evaluation

This package holds only the ``rocketroll`` command line, which sits above all
of them.
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("rocketroll")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"
