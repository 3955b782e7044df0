"""Outputs written all or nothing, and checked before any work is done.

Every file a rocketroll command writes is staged in a temporary file beside
its target and renamed into place only when all of the command's outputs are
complete, so a reader never sees a half-written file and a failure leaves
every target as it was.  A new file gets the permissions a plain ``open()``
would give (``mkstemp`` makes them private), a replaced one keeps its own.
Errors name the user's path, never the temporary one.

Before a command starts its work it checks that each output can be written
(:func:`check_output`): a long run must not end in "File exists".  And that
writing it destroys nothing the command did not make: an output that is one of
the command's inputs (the same file, links included) is refused, and so is an
existing file that holds another kind of content than the command writes
(:func:`content_kind`, read from the file's first bytes, not its name).
Writing again over a command's own earlier output of the same kind is what
re-running a command does, and stays allowed.
Missing folders above an output are created when it is written, for every
output alike; nothing is created before the work has succeeded.
"""

from __future__ import annotations

import errno
import os
import stat
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path

from rocketroll_common.errors import UsageError

__all__ = [
    "KINDS",
    "check_output",
    "content_kind",
    "created_folders_removed_on_error",
    "file_mode",
    "write_all_atomic",
    "write_atomic",
]


def _umask() -> int:
    """The process's umask, read without changing it where the system tells it (Linux);
    elsewhere set and restored at once."""
    try:
        with open("/proc/self/status", encoding="ascii") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The permissions a plain ``open()`` gives a new file (0o666 less the umask)."""
    return 0o666 & ~_umask()


def _named(exc: OSError, target: Path) -> OSError:
    """``exc`` about ``target`` (the user's path) instead of a temporary file."""
    return OSError(exc.errno, exc.strerror or str(exc), str(target))


def _existing_ancestor(path: Path) -> Path:
    """The nearest folder above ``path`` (or ``path`` itself) that exists."""
    current = path
    while not current.exists():
        if current.parent == current:
            break
        current = current.parent
    return current


#: What a file can hold, as :func:`content_kind` names it -> how a message says it.
KINDS = {
    "recording": "a rocketroll recording",
    "json": "JSON",
    "png": "a PNG image",
    "sqlite": "an SQLite database",
    "empty": "nothing",
    "other": "other content (text or data of another kind)",
}


def content_kind(path: str | os.PathLike[str]) -> str:
    """What the file at ``path`` holds, read from its first bytes: one of :data:`KINDS`."""
    with open(path, "rb") as handle:
        head = handle.read(64)
    if not head:
        return "empty"
    if head.startswith(b"SQLite format 3\x00"):
        return "sqlite"
    if head.startswith(b"\x89PNG\r\n\x1a\n"):
        return "png"
    if head.startswith(b"# format: rocketroll-recording/"):
        return "recording"
    if head.lstrip(b" \t\r\n\xef\xbb\xbf")[:1] in (b"{", b"["):
        return "json"
    return "other"


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist
        return False


def check_output(
    path: str | os.PathLike[str],
    what: str,
    *,
    folder: bool = False,
    kind: str | None = None,
    inputs: Sequence[tuple[str, str | os.PathLike[str]]] = (),
) -> Path:
    """Refuse, before any work, an output that could not be written or that would destroy
    a file the command did not make.

    Parameters
    ----------
    path : str or PathLike
        The output: a file, or with ``folder=True`` a folder the command
        writes files into (it may exist).
    what : str
        How the user named it, e.g. ``"--out"``, for the message.
    folder : bool
        The output is a folder.
    kind : str, optional
        What the command writes there (a key of :data:`KINDS`): an existing
        file of another kind is refused (an empty one is not).  A PNG's name
        must end in ``.png``.
    inputs : sequence of (name, path)
        The command's input files, by the name the user gave them: an output
        that is one of them is refused.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    UsageError
        A file output that is a folder, a folder output that is a file, a
        place whose nearest existing folder is not a writable folder, an
        output that is an input, or an existing file of another kind.
    """
    target = Path(path)
    if folder:
        if target.exists() and not target.is_dir():
            raise UsageError(f"{what} {target}: exists and is not a folder")
    elif target.is_dir():
        raise UsageError(f"{what} {target}: is a folder; give a file name")
    if not folder:
        if kind == "png" and target.suffix.lower() != ".png":
            raise UsageError(f"{what} {target}: the figure is a PNG; give a path ending in .png")
        for name, source in inputs:
            if _same_file(target, Path(source)):
                raise UsageError(
                    f"{what} {target}: is the input {name}; write the output to another file"
                )
        if kind is not None and target.is_file():
            found = content_kind(target)
            if found not in (kind, "empty"):
                raise UsageError(
                    f"{what} {target}: exists and holds {KINDS[found]}, not {KINDS[kind]}; "
                    "give another file (or remove that one)"
                )
    base = _existing_ancestor(target if folder else target.parent)
    if not base.is_dir():
        raise UsageError(f"{what} {target}: {base} is not a folder")
    if not os.access(base, os.W_OK | os.X_OK):
        raise UsageError(f"{what} {target}: cannot write in {base} (permission denied)")
    return target


def _make_parents(folder: Path) -> list[Path]:
    """Create ``folder`` and its missing parents; the ones created, outermost first."""
    made: list[Path] = []
    current = folder
    while not current.exists():
        made.append(current)
        if current.parent == current:
            break
        current = current.parent
    made.reverse()
    for path in made:
        try:
            path.mkdir()
        except FileExistsError:
            continue
    return made


def _remove_folders(folders: list[Path]) -> None:
    """Remove folders this process made, innermost first, if they are still empty."""
    for path in reversed(folders):
        try:
            path.rmdir()
        except OSError:
            break


def write_atomic(path: str | os.PathLike[str], data: str | bytes) -> None:
    """Write ``data`` (text as UTF-8) to ``path`` via a temporary file and a rename.

    See :func:`write_all_atomic`.
    """
    write_all_atomic({path: data})


def write_all_atomic(outputs: Mapping[str | os.PathLike[str], str | bytes]) -> None:
    """Write several files all or nothing.

    Every file is first written in full to a temporary file beside its target
    (missing folders are created) and flushed to disk; only when all of them
    are staged are they renamed into place.  Any error while staging (a folder
    as target, an unwritable folder, a full disk) leaves every target as it
    was and removes the folders it created.  The renames stay within each
    target's folder and need no space, so only a failure between them (the
    disk removed mid-way) could leave some targets replaced.  A replaced file
    keeps its permissions; a new one gets those a plain ``open()`` would.  An
    ``OSError`` names the target, not the temporary file.
    """
    staged: list[tuple[str, Path]] = []
    made: list[Path] = []
    done = False
    try:
        for path, data in outputs.items():
            target = Path(path)
            if target.is_dir():
                raise IsADirectoryError(errno.EISDIR, "is a directory", str(target))
            try:
                made += _make_parents(target.parent)
                fd, tmp = tempfile.mkstemp(
                    prefix=f".{target.name}.", suffix=".tmp", dir=target.parent
                )
                staged.append((tmp, target))
                with os.fdopen(fd, "wb") as handle:
                    handle.write(data.encode("utf-8") if isinstance(data, str) else data)
                    handle.flush()
                    os.fsync(handle.fileno())
                # mkstemp makes 0600 files: the target's own permissions, or a new file's.
                mode = stat.S_IMODE(target.stat().st_mode) if target.exists() else file_mode()
                os.chmod(tmp, mode)
            except OSError as exc:
                raise _named(exc, target) from None
        for tmp, target in staged:
            try:
                os.replace(tmp, target)
            except OSError as exc:
                raise _named(exc, target) from None
        done = True
    finally:
        for tmp, _ in staged:
            Path(tmp).unlink(missing_ok=True)
        if not done:
            _remove_folders(made)


@contextmanager
def created_folders_removed_on_error(path: str | os.PathLike[str]) -> Iterator[None]:
    """Create the missing folders above ``path``; remove them again if the block fails.

    For outputs that are not written through :func:`write_all_atomic` (an
    SQLite file opened in place).  The block must remove its own file.
    """
    made = _make_parents(Path(path).parent)
    try:
        yield
    except BaseException:
        _remove_folders(made)
        raise
