"""Before and after in the same run: a benchmark's timed blocks in another checkout.

``--against REF`` makes a benchmark time the same tasks twice: here, and in a
git worktree of ``REF`` (a commit, a branch, ``HEAD~3``) made beside the
repository.  The other checkout runs the *same* benchmark script as a second
process with that checkout's packages first on ``PYTHONPATH`` and a default
database of its own; the two alternate block by block, so a busy spell of a
shared machine slows both alike.  The script builds its tasks through APIs both
checkouts have (``gym.make``, ``identify``, ``TraceBank.from_db``), so the same
work is timed.

Protocol: the script started with :data:`SERVE` builds its tasks, prints
``ready``, then reads one task name per line and answers the seconds of one
timed block of it; an empty line ends it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Mapping
from pathlib import Path

__all__ = ["SERVE", "Remote", "checkout", "serve", "start_against"]

#: The option that puts a benchmark script into block-serving mode.
SERVE = "--serve-blocks"

REPO = Path(__file__).resolve().parents[1]


def checkout(ref: str) -> tuple[Path, str]:
    """A worktree of ``ref`` (reused if it exists) and the commit it is at."""
    sha = subprocess.run(
        ["git", "rev-parse", "--verify", f"{ref}^{{commit}}"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=False,
    )
    if sha.returncode != 0:
        raise SystemExit(f"--against {ref}: not a commit of {REPO} ({sha.stderr.strip()})")
    commit = sha.stdout.strip()
    tree = Path(tempfile.gettempdir()) / "rocketroll-against" / commit[:12]
    if not (tree / ".git").exists():
        tree.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            ["git", "worktree", "add", "--detach", str(tree), commit],
            cwd=REPO,
            capture_output=True,
            check=True,
        )
    return tree, commit


def start_against(script: str, words: list[str], ref: str | None) -> tuple[Remote | None, str]:
    """The benchmark ``script`` started in a checkout of ``ref`` with the same command-line
    ``words`` (less ``--against``), and the commit it runs; ``(None, "")`` without a ref."""
    if not ref:
        return None, ""
    tree, commit = checkout(ref)
    print(f"against {ref} ({commit[:12]}), checked out at {tree}: starting it")
    rest = [w for k, w in enumerate(words) if w != "--against" and words[k - 1] != "--against"]
    return Remote(script, [w for w in rest if not w.startswith("--against=")], tree), commit


class Remote:
    """The benchmark script serving timed blocks from another checkout."""

    def __init__(self, script: str, argv: list[str], tree: Path) -> None:
        env = {
            **os.environ,
            "PYTHONPATH": str(tree),
            "ROCKETROLL_DB": str(tree / ".benchmark-db" / "disturbances.sqlite"),
        }
        (tree / ".benchmark-db").mkdir(exist_ok=True)
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(script).resolve()), SERVE, *argv],
            cwd=tree,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            env=env,
        )
        said = self._line()
        if said != "ready":
            raise SystemExit(f"the other checkout did not start its benchmark (said {said!r})")

    def _line(self) -> str:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            self.proc.wait()
            raise SystemExit(f"the other checkout's benchmark ended (exit {self.proc.returncode})")
        return line.strip()

    def block(self, name: str) -> float:
        """Seconds of one timed block of task ``name`` in the other checkout."""
        assert self.proc.stdin is not None
        self.proc.stdin.write(name + "\n")
        self.proc.stdin.flush()
        return float(self._line())

    def close(self) -> None:
        """End the other process."""
        if self.proc.stdin is not None and not self.proc.stdin.closed:
            self.proc.stdin.write("\n")
            self.proc.stdin.close()
        self.proc.wait(timeout=60)


def serve(tasks: Mapping[str, Callable[[], float]]) -> int:
    """Serve timed blocks of ``tasks`` over stdin/stdout (the other side of :class:`Remote`)."""
    out = sys.stdout
    sys.stdout = sys.stderr  # anything a task prints must not break the protocol
    print("ready", file=out, flush=True)
    for line in sys.stdin:
        name = line.rstrip("\n")
        if not name.strip():
            break
        print(repr(tasks[name]()), file=out, flush=True)
    return 0
