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

A folder output (``rocketroll eval --out FOLDER``) holds files the user may have
put there.  A command writes into it only the files it names, and over an
existing one only when rocketroll wrote that file there and it has not changed
since: the folder's manifest (:data:`MANIFEST`) lists each file rocketroll wrote
with its SHA-256, and is written with the outputs in the same all-or-nothing
step (:func:`write_all_atomic` with ``folder=``).  Any other existing file is
refused (:func:`check_folder_files`), before the work where the names are known,
unless the command runs with ``--force`` (:func:`forcing`).
Missing folders above an output are created when it is written, for every
output alike; nothing is created before the work has succeeded.
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import stat
import tempfile
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from rocketroll_common.errors import UsageError

__all__ = [
    "KINDS",
    "MANIFEST",
    "check_folder_files",
    "check_output",
    "content_kind",
    "created_folders_removed_on_error",
    "file_mode",
    "forced",
    "forcing",
    "record_outputs",
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


# ----------------------------------------------------------------------------- folders
#: The manifest of an output folder: each file rocketroll wrote there (its path in the
#: folder, ``/``-separated) with the SHA-256 it was written with.
MANIFEST = ".rocketroll-outputs.json"
_MANIFEST_FORMAT = "rocketroll-outputs/1"
_FORCE: ContextVar[bool] = ContextVar("rocketroll_force", default=False)


@contextmanager
def forcing(force: bool = True) -> Iterator[None]:
    """Within the block, a file in an output folder that rocketroll did not write there
    (or that was changed since) is replaced instead of refused: a command's ``--force``."""
    token = _FORCE.set(force)
    try:
        yield
    finally:
        _FORCE.reset(token)


def forced() -> bool:
    """Whether the block runs under :func:`forcing` (a command's ``--force``)."""
    return _FORCE.get()


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _refuse(what: str, folder: Path, problem: str) -> UsageError:
    return UsageError(f"{what} {folder}: {problem}; give another folder, or --force to replace it")


def _read_manifest(folder: Path, what: str) -> dict[str, str]:
    """The files rocketroll wrote in ``folder`` -> their SHA-256 (none without a manifest).

    A file of the manifest's name that is not one is the user's: refused, or under
    :func:`forcing` replaced (as if there were none).
    """
    path = folder / MANIFEST
    if not (path.exists() or path.is_symlink()):
        return {}
    try:
        data = json.loads(path.read_text("utf-8"))
        files = data.get("files") if data.get("format") == _MANIFEST_FORMAT else None
        valid = isinstance(files, dict) and all(isinstance(v, str) for v in files.values())
    except (OSError, ValueError, AttributeError):
        valid = False
    if not valid or not isinstance(files, dict):
        if forced():
            return {}
        raise _refuse(what, folder, f"{MANIFEST} exists and is not rocketroll's list of its files")
    return {str(name): str(digest) for name, digest in files.items()}


def check_folder_files(
    folder: str | os.PathLike[str], names: Iterable[str | os.PathLike[str]], what: str
) -> None:
    """Refuse writing the files ``names`` (paths in ``folder``) into the output folder
    ``folder`` where one exists that rocketroll did not write there, or that has changed
    since it did (its manifest, :data:`MANIFEST`, says); under :func:`forcing` only a
    folder in a file's place is refused.

    Raises
    ------
    UsageError
        One line naming ``what``, the folder and the file, and how to go on.
    """
    root = Path(folder)
    if not root.is_dir():
        return  # a new folder holds nothing; a file in its place is check_output's
    known = _read_manifest(root, what)  # one that is not rocketroll's is refused too
    for name in (Path(n).as_posix() for n in names):
        target = root / name
        if target.is_dir():
            raise UsageError(f"{what} {root}: {name} is a folder there; give another folder")
        if not (target.exists() or target.is_symlink()) or forced():
            continue
        recorded = known.get(name)
        if recorded is None:
            raise _refuse(what, root, f"{name} exists and rocketroll did not write it there")
        if not target.is_file() or _sha256(target) != recorded:
            raise _refuse(what, root, f"{name} was changed since rocketroll wrote it")


def _manifest_text(folder: Path, written: Mapping[str, str], what: str) -> str:
    """The manifest of ``folder`` once the files ``written`` (name -> SHA-256) are: the
    files it listed that are still there, and these."""
    listed = {
        name: digest
        for name, digest in _read_manifest(folder, what).items()
        if (folder / name).is_file()
    }
    listed.update(written)
    record = {"format": _MANIFEST_FORMAT, "files": dict(sorted(listed.items()))}
    return json.dumps(record, indent=1) + "\n"


def record_outputs(
    folder: str | os.PathLike[str], names: Iterable[str | os.PathLike[str]], what: str = "--out"
) -> None:
    """Add files rocketroll wrote into ``folder`` other than by :func:`write_all_atomic`
    (a library's own saves: a training run's checkpoints and logs) to its manifest, as
    they are now; names of files that do not exist are left out."""
    root = Path(folder)
    hashes = {
        Path(name).as_posix(): _sha256(root / name) for name in names if (root / name).is_file()
    }
    if hashes:
        write_all_atomic({root / MANIFEST: _manifest_text(root, hashes, what)})


def check_output(
    path: str | os.PathLike[str],
    what: str,
    *,
    folder: bool = False,
    kind: str | None = None,
    inputs: Sequence[tuple[str, str | os.PathLike[str]]] = (),
    files: Iterable[str | os.PathLike[str]] = (),
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
    files : iterable of str
        With ``folder=True``, the files the command writes there (paths in the
        folder): an existing one that rocketroll did not write there, or that
        was changed since, is refused (:func:`check_folder_files`).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    UsageError
        A file output that is a folder, a folder output that is a file, a
        place whose nearest existing folder is not a writable folder, an
        output that is an input, an existing file of another kind, or a file in
        a folder output that rocketroll did not write.
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
    names = list(files)
    if folder and names:
        check_folder_files(target, names, what)
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


def write_all_atomic(
    outputs: Mapping[str | os.PathLike[str], str | bytes],
    *,
    folder: str | os.PathLike[str] | None = None,
    what: str = "--out",
) -> None:
    """Write several files all or nothing.

    With ``folder`` (an output folder, as the user named it ``what``), the
    outputs inside it are first checked (:func:`check_folder_files`: an
    existing file rocketroll did not write there is refused, unless
    :func:`forcing`) and recorded in its manifest (:data:`MANIFEST`), which is
    staged and renamed with them, last.

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
    if folder is not None:
        root = Path(folder)
        inside: dict[str, bytes] = {}
        for path, data in outputs.items():
            try:
                name = Path(path).relative_to(root).as_posix()
            except ValueError:
                continue
            inside[name] = data.encode("utf-8") if isinstance(data, str) else data
        if MANIFEST in inside:
            raise ValueError(f"{MANIFEST} is rocketroll's own file in an output folder")
        if inside:
            check_folder_files(root, inside, what)
            hashes = {name: hashlib.sha256(data).hexdigest() for name, data in inside.items()}
            outputs = {**outputs, root / MANIFEST: _manifest_text(root, hashes, what)}
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
