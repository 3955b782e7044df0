"""The pinned numerics: the same last bits under every numerical environment of a machine.

The environments varied here are what differs between machines of one kind:
OpenBLAS's kernel (chosen by processor, or by ``OPENBLAS_CORETYPE``) and numpy's
SIMD level (AVX-512, AVX2 or none; a machine without AVX-512 is one with it
disabled).  The checks can fail: without the pin the same arithmetic gives
other bits under each of them.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import signal
import subprocess
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from rocketroll_common import numerics
from rocketroll_common.errors import RocketrollError, SettingError
from tests.cli import python

REPO = Path(__file__).resolve().parents[1]

#: The settings that change numpy's and OpenBLAS's bits (the others do not touch them).
VARIED = (
    "this machine",
    "OpenBLAS picks its kernel",
    "OpenBLAS's AVX kernel",
    "numpy without AVX-512",
    "numpy without AVX2",
)

pinnable = pytest.mark.skipif(
    numerics.pinned_environment() is None,
    reason="the numerics are pinned only on x86-64 Linux with AVX2 and FMA (x86-64-v3), and "
    "not with ROCKETROLL_NUMERICS=unpinned",
)


def fingerprint() -> str:
    """A hash of the bits of a matrix product, a solve and numpy's SIMD functions."""
    rng = np.random.default_rng(0)
    a = rng.standard_normal((64, 64))
    x = rng.standard_normal(4096) * 3.0
    h = hashlib.sha256()
    for value in (a @ a, np.linalg.solve(a, x[:64]), np.exp(x), np.log1p(np.abs(x)), np.sin(x)):
        h.update(np.ascontiguousarray(value).tobytes())
    return h.hexdigest()


def how_pinned() -> dict[str, object]:
    """What the pinned process sees of itself."""
    features = importlib.import_module("numpy._core._multiarray_umath").__cpu_features__
    return {
        "pid": os.getpid(),
        "pinned": numerics.is_pinned(),
        "core": os.environ.get("OPENBLAS_CORETYPE"),
        "avx512": bool(features.get("X86_V4")),
    }


def fails(message: str) -> None:
    raise SettingError("--size", message)


def openblas_function(*symbols: str) -> Any:
    """The first of ``symbols`` that numpy's scipy-openblas exports (the 64-bit
    interface's name first), or None where numpy is not linked with it."""
    import ctypes

    libs = Path(np.__file__).parent.with_name("numpy.libs")
    for lib in sorted(libs.glob("libscipy_openblas*.so*")):
        handle = ctypes.CDLL(str(lib))
        for symbol in symbols:
            found = getattr(handle, symbol, None)
            if found is not None:
                return found
    return None


def openblas_kernel() -> str:
    """The kernel OpenBLAS chose in this process (``openblas_get_corename``), by the
    instruction set it computes with: a processor's own kernels of one level (Haswell,
    Zen: AVX2 and FMA) are the same arithmetic."""
    import ctypes

    corename = openblas_function("scipy_openblas_get_corename64_", "scipy_openblas_get_corename")
    if corename is None:
        return "unknown"
    corename.restype = ctypes.c_char_p
    name = corename().decode()
    return _KERNEL_LEVELS.get(name.lower(), name)


def test_the_suite_runs_on_the_openblas_threads_its_environment_names() -> None:
    """tests/conftest.py asks for one OpenBLAS thread before numpy loads, as the
    `rocketroll` command does; numpy's OpenBLAS took the number (or what it was told)."""
    get = openblas_function("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads")
    if get is None:
        pytest.skip("numpy is not linked with a scipy-openblas that says its number of threads")
    assert get() == int(os.environ["OPENBLAS_NUM_THREADS"])


#: OpenBLAS's kernel names -> the instruction set they compute with.
_KERNEL_LEVELS = {
    **dict.fromkeys(("skylakex", "cooperlake", "sapphirerapids"), "AVX-512"),
    **dict.fromkeys(("haswell", "zen"), "AVX2 and FMA"),
    **dict.fromkeys(("sandybridge",), "AVX"),
}


def measured() -> tuple[str, str, str, bool]:
    """(pinned, unpinned) fingerprints, the OpenBLAS kernel, and whether numpy's loops use
    AVX-512, as this process sees them."""
    features = importlib.import_module("numpy._core._multiarray_umath").__cpu_features__
    pinned = numerics.call_pinned(fingerprint)
    return pinned, fingerprint(), openblas_kernel(), bool(features.get("X86_V4"))


def _in_a_process(setting: str) -> tuple[str, str, str, bool]:
    """:func:`measured` by a new process under ``setting``."""
    env = numerics.with_settings(numerics.MACHINE_SETTINGS[setting])
    code = "from tests.test_numerics import measured\nprint(*measured())\n"
    done = python(["-c", code], REPO, env, check=True)
    pinned, unpinned, *kernel, avx512 = done.stdout.split()
    return pinned, unpinned, " ".join(kernel), avx512 == "True"


@pinnable
def test_the_pinned_bits_are_the_same_under_every_environment() -> None:
    found = {name: _in_a_process(name) for name in VARIED}
    assert len({pinned for pinned, *_ in found.values()}) == 1, found
    # The environments are really different, and as different as the processor makes them:
    # unpinned, two settings compute the same bits exactly when they run the same arithmetic
    # (OpenBLAS's kernel and numpy's AVX-512 loops, as each process reports them).  Without
    # AVX-512 (the processor's, or hidden by NPY_DISABLE_CPU_FEATURES) that is two kinds,
    # OpenBLAS's AVX kernel and the processor's own; with it, three or more.
    kinds = {name: (kernel, avx512) for name, (_, _, kernel, avx512) in found.items()}
    for a in VARIED:
        for b in VARIED:
            same_bits = found[a][1] == found[b][1]
            assert same_bits == (kinds[a] == kinds[b]), (a, b, found)
    assert len(set(kinds.values())) >= 2, found


@pinnable
def test_a_call_runs_in_a_pinned_process() -> None:
    seen = numerics.call_pinned(how_pinned)
    assert seen == {"pid": seen["pid"], "pinned": True, "core": "Haswell", "avx512": False}
    assert seen["pid"] != os.getpid()


@pinnable
def test_its_exception_is_raised_here_with_the_childs_traceback() -> None:
    with pytest.raises(ValueError, match="bad"):
        numerics.call_pinned(int, "bad")
    # An exception that does not survive pickling comes back as its family with its text.
    with pytest.raises(RocketrollError, match="--size: too big") as raised:
        numerics.call_pinned(fails, "too big")
    assert "in the pinned process" in "".join(raised.value.__notes__)


def test_a_pinned_process_or_a_local_function_computes_here(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv(numerics.MARKER, "pinned")
    assert numerics.call_pinned(os.getpid) == os.getpid()
    monkeypatch.setenv(numerics.MARKER, "unpinned")  # the user's choice: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert numerics.call_pinned(os.getpid) == os.getpid()
    # ... and it stands for a machine that cannot be pinned: a default database built so is
    # the default one, its fingerprint saying "as found".
    from disturbances import default
    from identification.instruments.bundled import bundled_paths
    from identification.methods.pipeline import IdentifyOptions

    assert numerics.pinned_environment() is None
    files = bundled_paths()[:1]
    here = default.fingerprint(files, IdentifyOptions(), 0, ("iaaft",), 0, ["paper"])
    assert here == default.fingerprint(
        files, IdentifyOptions(), 0, ("iaaft",), 0, ["paper"], pinned=False
    )
    monkeypatch.delenv(numerics.MARKER)
    if numerics.pinned_environment() is None:
        return
    with pytest.warns(RuntimeWarning, match="not pinned"):
        assert numerics.call_pinned(lambda: os.getpid()) == os.getpid()


def test_the_pinned_environment_overrides_the_machines() -> None:
    env = numerics.pinned_environment(
        {"OPENBLAS_CORETYPE": "SkylakeX", "NPY_DISABLE_CPU_FEATURES": "X86_V3", "HOME": "/h"}
    )
    if env is None:
        pytest.skip("the numerics are pinned only on x86-64 Linux with AVX2 and FMA")
    assert env["OPENBLAS_CORETYPE"] == "Haswell" and env["OPENBLAS_NUM_THREADS"] == "1"
    assert "NPY_DISABLE_CPU_FEATURES" not in env
    enabled = env["NPY_ENABLE_CPU_FEATURES"].split()
    assert "X86_V3" in enabled or "AVX2" in enabled  # numpy 2.4 names the level, 1.x-2.3 each
    assert not {"X86_V4", "AVX512F", "AVX512_SKX", "AVX512_ICL"} & set(enabled)
    assert env["HOME"] == "/h" and env[numerics.MARKER] == "pinned"


def sleeps(folder: str) -> None:
    """Write this process's id, wait to be interrupted, and clean up slowly on the way out
    (a second interrupt during the clean-up would break it)."""
    Path(folder, "pid").write_text(str(os.getpid()))
    try:
        time.sleep(60)
    finally:
        time.sleep(1.0)
        Path(folder, "cleaned").write_text("yes")


_PARENT = """
import sys
from rocketroll_common.numerics import call_pinned
from tests.test_numerics import sleeps
try:
    call_pinned(sleeps, sys.argv[1])
except KeyboardInterrupt:
    print("interrupted")
"""


def _parent(folder: Path) -> tuple[subprocess.Popen[str], int]:
    """A process, leading a process group as a shell's job does, waiting on a pinned child
    that sleeps; the child's id."""
    env = numerics.with_settings({"PYTHONPATH": str(REPO), "TMPDIR": str(folder)})
    proc = subprocess.Popen(
        [sys.executable, "-c", _PARENT, str(folder)],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        text=True,
        process_group=0,
    )
    deadline = time.monotonic() + 60
    while not (folder / "pid").exists():
        assert time.monotonic() < deadline, "the child never started"
        time.sleep(0.05)
    return proc, int((folder / "pid").read_text())


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended within 10 s (a zombie waiting to be reaped has)."""
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
        except (FileNotFoundError, ProcessLookupError):
            return True
        if state == "Z":
            return True
        time.sleep(0.05)
    return False


@pinnable
def test_an_interrupt_of_the_child_alone_interrupts_the_caller(tmp_path: Path) -> None:
    """A Ctrl-C that reached the child but not the waiting caller's main thread (the kernel
    may give a process's signal to another of its threads) still interrupts the call."""
    proc, child = _parent(tmp_path)
    os.kill(child, signal.SIGINT)
    out, _ = proc.communicate(timeout=30)
    assert out.strip() == "interrupted"
    assert (tmp_path / "cleaned").read_text() == "yes"
    assert _gone(child)
    assert not list(tmp_path.glob("rocketroll-pinned-*"))


@pinnable
def test_ctrl_c_interrupts_the_child_once_and_it_cleans_up(tmp_path: Path) -> None:
    proc, child = _parent(tmp_path)
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C at a terminal: to the whole job
    out, _ = proc.communicate(timeout=30)
    assert out.strip() == "interrupted"
    assert (tmp_path / "cleaned").read_text() == "yes"  # the parent's own interrupt ignored
    assert _gone(child)
    assert not list(tmp_path.glob("rocketroll-pinned-*"))


@pinnable
def test_the_child_ends_with_its_parent(tmp_path: Path) -> None:
    proc, child = _parent(tmp_path)
    proc.kill()
    proc.communicate(timeout=30)
    assert _gone(child)


@pinnable
def test_an_import_that_fails_in_the_child_is_an_error(tmp_path: Path) -> None:
    """Only what names the caller's __main__ falls back to the caller; a module the child
    cannot import is an error (a silent unpinned computation would hide it)."""
    module = tmp_path / "vanishing.py"
    module.write_text("def answer():\n    return 42\n")
    sys.path.insert(0, str(tmp_path))
    try:
        import vanishing  # type: ignore[import-not-found]

        module.unlink()
        with pytest.raises(ModuleNotFoundError, match="vanishing"):
            numerics.call_pinned(vanishing.answer)
    finally:
        sys.path.remove(str(tmp_path))
        sys.modules.pop("vanishing", None)


@pinnable
def test_the_child_imports_what_the_caller_does_not_its_working_folder(tmp_path: Path) -> None:
    """A console script (``rocketroll``) run in a folder that holds a package of the same
    name as one of ours: the child must not import that one."""
    work = tmp_path / "work"
    (work / "identification").mkdir(parents=True)
    (work / "identification" / "__init__.py").write_text("raise ImportError('the wrong one')\n")
    script = tmp_path / "bin" / "run.py"
    script.parent.mkdir()
    script.write_text(
        "from identification.instruments.bundled import bundled_paths\n"
        "from rocketroll_common.numerics import call_pinned\n"
        "print(len(call_pinned(bundled_paths)))\n"
    )
    env = numerics.with_settings({"PYTHONPATH": str(REPO)})
    done = python([str(script)], work, env, check=False)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "9"


def warns() -> int:
    warnings.warn("from the pinned process", UserWarning, stacklevel=1)
    return 1


@pinnable
def test_the_child_applies_the_callers_warning_filters() -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning, match="from the pinned process"):
            numerics.call_pinned(warns)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert numerics.call_pinned(warns) == 1


_SCRIPT = """
import os, warnings
from rocketroll_common.numerics import call_pinned

def mine():
    return os.getpid()

with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    print(call_pinned(mine) == os.getpid(), [str(w.message) for w in caught])
"""


@pinnable
def test_a_function_of_the_callers_script_is_computed_there_with_a_warning() -> None:
    """A function of ``__main__`` pickles by name, but the child's ``__main__`` is another."""
    env = numerics.with_settings({"PYTHONPATH": str(REPO)})
    done = python(["-c", _SCRIPT], REPO, env, check=True)
    assert done.stdout.startswith("True ["), done.stdout + done.stderr
    assert "mine runs in this process, its numerics not pinned" in done.stdout
