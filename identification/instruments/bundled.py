"""The synthetic recordings shipped with the package, and how each was made.

Each file in ``identification/data`` was written by the virtual wind tunnel
with the command listed here (also stored in the file's ``# command:`` line);
``tests/identification/test_bundled.py`` regenerates every one and compares
bytes.  Regenerate them all with ``make recordings`` or
``python -m identification.instruments.bundled --regenerate``.

All of them are ``source: synthetic``: the paper's own data are not public.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from identification.recordings.recording import Recording, load_recording, save_recording

__all__ = ["BUNDLED", "DATA_DIR", "bundled_path", "bundled_paths", "load_bundled", "regenerate"]

DATA_DIR = Path(__file__).resolve().parent.parent / "data"

#: file name -> the exact command that made it (run with ``--out DATA_DIR/<file>``).
BUNDLED: dict[str, str] = {
    # The paper's experiment (Table 1 schedule) at several turbulence seeds.
    "tunnel-paper-seed0.csv": "rocketroll tunnel --seed 0",
    "tunnel-paper-seed1.csv": "rocketroll tunnel --seed 1",
    "tunnel-paper-seed2.csv": "rocketroll tunnel --seed 2",
    # Non-Gaussian turbulence, which the paper says its method must handle.
    "tunnel-paper-seed3.csv": "rocketroll tunnel --seed 3 --turbulence laplace",
    # A flight-computer-like sensor set: rate gyro (eq. 52, 2 %) and measured fin.
    "tunnel-paper-seed4.csv": "rocketroll tunnel --seed 4 --gyro-noise 2.0 --measured-fin",
    # Random staircases for diverse data.
    "tunnel-staircase-seed10.csv": "rocketroll tunnel --seed 10 --schedule staircase --steps 12",
    "tunnel-staircase-seed11.csv": "rocketroll tunnel --seed 11 --schedule staircase --steps 12",
    # Held out for evaluation by declaration (metadata `split: test`); the rest
    # fall to train or test by content hash (disturbances.rows.split_of).
    "tunnel-paper-seed5.csv": "rocketroll tunnel --seed 5 --split test",
    "tunnel-staircase-seed12.csv": (
        "rocketroll tunnel --seed 12 --schedule staircase --steps 12 --split test"
    ),
}


def bundled_path(name: str) -> Path:
    """Path of a bundled recording by file name (``tunnel-paper-seed0.csv``; the
    ``.csv`` may be left out)."""
    if name not in BUNDLED and f"{name}.csv" in BUNDLED:
        name = f"{name}.csv"
    if name not in BUNDLED:
        raise KeyError(f"no bundled recording {name!r}; have {', '.join(BUNDLED)}")
    return DATA_DIR / name


def bundled_paths() -> list[Path]:
    """Paths of all bundled recordings, in :data:`BUNDLED` order."""
    return [DATA_DIR / name for name in BUNDLED]


def load_bundled(name: str) -> Recording:
    """Load a bundled recording by file name."""
    return load_recording(bundled_path(name))


def make(name: str) -> Recording:
    """Run the recorded command of a bundled file and return the recording."""
    from identification.instruments.tunnel import run_tunnel, spec_from_command

    return run_tunnel(spec_from_command(BUNDLED[name]))


def regenerate(directory: Path = DATA_DIR) -> list[Path]:
    """Write every bundled recording into ``directory``; returns the paths."""
    paths = []
    for name in BUNDLED:
        path = directory / name
        save_recording(make(name), path)
        paths.append(path)
    return paths


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m identification.instruments.bundled [--regenerate]``."""
    parser = argparse.ArgumentParser(
        prog="python -m identification.instruments.bundled", description=__doc__
    )
    parser.add_argument("--regenerate", action="store_true", help="rewrite the bundled files")
    ns = parser.parse_args(argv)
    if ns.regenerate:
        for path in regenerate():
            print(f"wrote {path}")
    else:
        for name, command in BUNDLED.items():
            print(f"{name:32s} {shlex.join(shlex.split(command))}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
