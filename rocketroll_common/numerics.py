"""One numerical environment on every x86-64 machine, for work whose last bits are quoted.

Two libraries choose their arithmetic from the processor when they load:

- **OpenBLAS** (inside numpy and scipy) picks its kernels by CPU model, or by
  ``OPENBLAS_CORETYPE`` where that is set, and splits long dot products between
  its threads.  The kernels of two processors sum in different orders, so a
  matrix product, a solve, a least-squares fit or L-BFGS-B's own dot products
  differ in the last bits.
- **numpy** runs the SIMD loops of ``exp``, ``log``, ``sin``, sums ... that the
  processor has (AVX2 or AVX-512, chosen at import); they round differently.

Identification turns those last bits into more: an optimiser (the ``ml`` and
``output-error`` fits) stops where its tolerance lets it, so a last-bit change
of the likelihood moves the identified parameters by about 1e-4, and every
trace and posterior draw with them; and a closed loop that chatters at the
fins' rate limit turns any change of its disturbance into other episodes (the
flight table's tunnel-gain PID: 7.43° on one machine, 6.54° on another).  The
evaluation that replays a database does not depend on either: numba compiles
the same IEEE arithmetic for every processor (no fast-math), and the
evaluation tables are bit for bit the same under every setting above
(``benchmarks/machine_dependence.py`` measures both).

Both choices are made once, when the libraries load, so a computation is
pinned by running it in a new interpreter started under :func:`pinned_environment`
(:func:`call_pinned`): OpenBLAS's Haswell kernels (AVX2 and FMA), numpy's loops
up to AVX2 and FMA (numpy's ``X86_V3`` level), one OpenBLAS thread -- what every
x86-64-v3 processor runs alike, AMD or Intel -- and the C library's own choice
of its ``exp``, ``log``, ``tanh`` ... (``GLIBC_TUNABLES`` cleared: with FMA, every
such processor takes the same ones).  Where the machine cannot be pinned (not
x86-64 Linux, or a processor without AVX2 and FMA), or the environment says
``ROCKETROLL_NUMERICS=unpinned``, the computation runs in this process, as it
would anyway.  The results are the same for the same versions
of numpy, scipy, numba and the C library (the Makefile's ``constraints.txt``
fixes the first three; machines of one kind share the last).
"""

from __future__ import annotations

import importlib
import os
import pickle
import platform
import re
import signal
import subprocess
import sys
import tempfile
import traceback
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

__all__ = [
    "MACHINE_SETTINGS",
    "MARKER",
    "call_pinned",
    "is_pinned",
    "is_unpinned",
    "one_blas_thread",
    "pinned_environment",
    "with_settings",
]

T = TypeVar("T")


def one_blas_thread() -> None:
    """One OpenBLAS thread for this process, unless its environment names a number
    (``OPENBLAS_NUM_THREADS``); effective only before numpy is first imported.

    The arrays here are small -- thousands of readings by a few columns -- so a second
    thread gains nothing on an idle machine, and where another program holds a core
    OpenBLAS's threads wait for each other: the paper's pipeline then took 3x its idle
    time and ml 1.6x (``benchmarks/speed.py --busy 1``).  The ``rocketroll`` command
    calls this before it imports a command.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


#: Set to ``pinned`` in a process started under :func:`pinned_environment`; set to
#: ``unpinned`` by a user (or a test run) to compute everything in its own process, under
#: the machine's own numerics, as on a machine that cannot be pinned.
MARKER = "ROCKETROLL_NUMERICS"
#: OpenBLAS's kernels for AVX2 and FMA, on any processor.
_OPENBLAS_CORE = "Haswell"
#: numpy's dispatch targets a pinned process may use: up to AVX2 and FMA (numpy 2.4 names
#: the level ``X86_V3``; earlier versions name each feature).
_NUMPY_AVX2 = frozenset(
    ("X86_V2", "X86_V3", "SSSE3", "SSE41", "POPCNT", "SSE42", "AVX", "F16C", "FMA3", "AVX2")
)
#: The numerical settings that differ between x86-64 machines of one kind, each imitated on
#: this one: name -> environment variables (None: unset).  ``tests/test_numerics.py`` and
#: ``benchmarks/machine_dependence.py`` run under each; the Makefile's ``pytest-varied``
#: under most of them at once.
MACHINE_SETTINGS: dict[str, dict[str, str | None]] = {
    "this machine": {},
    "OpenBLAS picks its kernel": {"OPENBLAS_CORETYPE": None},
    "OpenBLAS's AVX kernel": {"OPENBLAS_CORETYPE": "Sandybridge"},
    "numpy without AVX-512": {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR"},
    "numpy without AVX2": {"NPY_DISABLE_CPU_FEATURES": "X86_V3 X86_V4 AVX512_ICL AVX512_SPR"},
    "numba for a generic x86-64": {"NUMBA_CPU_NAME": "generic"},
    "torch unvectorised, MKL compatible": {
        "ATEN_CPU_CAPABILITY": "default",
        "MKL_CBWR": "COMPATIBLE",
    },
    "one thread each": {
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
        "NUMBA_NUM_THREADS": "1",
    },
}
#: How long an interrupted child has to clean up before it is killed, s.
_GRACE_S = 10.0


#: The processor flags (Linux's names) of x86-64-v3, the level pinned: AVX2, FMA and company.
_X86_V3_FLAGS = frozenset(("avx", "avx2", "bmi1", "bmi2", "f16c", "fma", "abm", "movbe"))


def _numpy_dispatch() -> list[str] | None:
    """The SIMD levels numpy was built to choose from at import, or None if unknown."""
    for name in ("numpy._core._multiarray_umath", "numpy.core._multiarray_umath"):  # 2.x, 1.x
        try:
            umath = importlib.import_module(name)
            break
        except ImportError:
            continue
    else:
        return None
    dispatch = getattr(umath, "__cpu_dispatch__", None)
    return None if dispatch is None else list(dispatch)


def _has_x86_v3() -> bool:
    """Whether the processor has AVX2, FMA and the rest of x86-64-v3.

    Read from the processor (``/proc/cpuinfo``), not from numpy: numpy reports
    what this process enabled, which ``NPY_DISABLE_CPU_FEATURES`` narrows.
    """
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            for line in info:
                if line.startswith("flags"):
                    return _X86_V3_FLAGS.issubset(line.partition(":")[2].split())
    except OSError:
        pass
    return False


def pinned_environment(environ: Mapping[str, str] | None = None) -> dict[str, str] | None:
    """``environ`` (default: this process's) with the numerics pinned, or None where this
    machine cannot be pinned (not x86-64 Linux, or a processor below x86-64-v3) or
    ``environ`` asks for the machine's own numerics (``ROCKETROLL_NUMERICS=unpinned``, which
    so stands for such a machine)."""
    linux_x86 = platform.system() == "Linux" and platform.machine().lower() == "x86_64"
    asked = (os.environ if environ is None else environ).get(MARKER) == "unpinned"
    if asked or not linux_x86 or not _has_x86_v3():
        return None
    dispatch = _numpy_dispatch()
    if dispatch is None:
        return None
    enabled = [f for f in dispatch if f in _NUMPY_AVX2]
    env = dict(os.environ if environ is None else environ)
    env.pop("NPY_DISABLE_CPU_FEATURES", None)  # numpy refuses both at once
    if enabled:
        env["NPY_ENABLE_CPU_FEATURES"] = " ".join(enabled)
    else:  # nothing above the baseline to choose from
        env.pop("NPY_ENABLE_CPU_FEATURES", None)
    env["OPENBLAS_CORETYPE"] = _OPENBLAS_CORE
    env["OPENBLAS_NUM_THREADS"] = "1"
    env.pop("GLIBC_TUNABLES", None)  # its hwcaps would narrow the C library's own choice
    env[MARKER] = "pinned"
    # The child imports what this process imports, from where this process does (run with
    # -P, it puts nothing of its own first: not its working folder).
    path = [os.getcwd() if p == "" else p for p in sys.path]
    env["PYTHONPATH"] = os.pathsep.join(path)
    return env


def with_settings(
    changes: Mapping[str, str | None], environ: Mapping[str, str] | None = None
) -> dict[str, str]:
    """``environ`` (default: this process's) with ``changes`` made (None: unset) and without
    :data:`MARKER`: the environment of a new process under one of :data:`MACHINE_SETTINGS`."""
    env = dict(os.environ if environ is None else environ)
    env.pop(MARKER, None)
    for name, value in changes.items():
        if value is None:
            env.pop(name, None)
        else:
            env[name] = value
    return env


def is_pinned() -> bool:
    """Whether this process was started under :func:`pinned_environment`."""
    return os.environ.get(MARKER) == "pinned"


def is_unpinned() -> bool:
    """Whether this process's environment asks for the machine's own numerics
    (``ROCKETROLL_NUMERICS=unpinned``): :func:`call_pinned` then computes here."""
    return os.environ.get(MARKER) == "unpinned"


def call_pinned(function: Callable[..., T], *args: Any, **kwargs: Any) -> T:
    """``function(*args, **kwargs)`` computed under the pinned numerics.

    In a new interpreter started under :func:`pinned_environment` (about two
    seconds of imports), unless this process already runs pinned or the
    machine cannot be pinned: then here.  ``function`` and its arguments must
    be picklable by name from an importable module, and so must its result;
    what cannot be sent (a lambda, a function of the caller's ``__main__``)
    is computed here with a ``RuntimeWarning``.  The child applies this
    process's warning filters; its exception is raised here, with the child's
    traceback as a note; its standard output and error are this process's.
    Interrupted (Ctrl-C, or any exception while waiting), this process
    interrupts the child once -- the child ignores a second interrupt, such as
    a terminal's Ctrl-C that reached it too -- and gives it :data:`_GRACE_S`
    seconds to clean up before it is killed; if this process dies, the child
    is ended too.  A child interrupted on its own (a Ctrl-C this process's
    main thread did not see: the kernel may hand a process's signal to any of
    its threads) raises ``KeyboardInterrupt`` here too, once it has cleaned up.
    """
    env = None if is_pinned() else pinned_environment()
    if env is None:
        return function(*args, **kwargs)
    try:
        payload = pickle.dumps((function, args, kwargs, list(warnings.filters)))
    except Exception as exc:  # pickling raises PicklingError, AttributeError, TypeError ...
        return _unpinned(function, f"{type(exc).__name__}: {exc}", args, kwargs)
    with tempfile.TemporaryDirectory(prefix="rocketroll-pinned-") as folder:
        call, answer = Path(folder, "call.pickle"), Path(folder, "answer.pickle")
        call.write_bytes(payload)
        command = [sys.executable, "-P", "-m", "rocketroll_common.numerics"]
        command += [str(call), str(answer), str(os.getpid())]
        child: subprocess.Popen[bytes] | None = None
        try:
            child = subprocess.Popen(command, env=env, stdin=subprocess.DEVNULL)
            returncode = child.wait()
        finally:
            if child is not None and child.poll() is None:
                _stop(child)
        if not answer.exists():
            if returncode == 130:  # interrupted while this process was not (see _child)
                raise KeyboardInterrupt
            raise RuntimeError(
                f"the pinned computation of {function.__qualname__} ended with exit code "
                f"{returncode} and no result"
            )
        status, value = pickle.loads(answer.read_bytes())
    if status == "returned":
        return value
    if status == "unloadable":
        return _unpinned(function, value, args, kwargs)
    raise value


def _unpinned(function: Callable[..., T], why: str, args: Any, kwargs: Any) -> T:
    """``function`` computed here, with a warning that its numerics are not pinned."""
    warnings.warn(
        f"{function.__qualname__} runs in this process, its numerics not pinned: a new "
        f"process cannot be given it and its arguments ({why})",
        RuntimeWarning,
        stacklevel=3,
    )
    return function(*args, **kwargs)


def _stop(child: subprocess.Popen[bytes]) -> None:
    """Interrupt the child once, let it clean up, then end it."""
    try:
        child.send_signal(signal.SIGINT)
        child.wait(timeout=_GRACE_S)
    except subprocess.TimeoutExpired:
        pass
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()


def _portable(exc: BaseException) -> BaseException:
    """``exc`` if it survives pickling, else a plain exception of its family with its text."""
    try:
        pickle.loads(pickle.dumps(exc))
    except Exception:
        from rocketroll_common.errors import RocketrollError

        family = RocketrollError if isinstance(exc, RocketrollError) else RuntimeError
        plain = family(str(exc))
        plain.__notes__ = list(getattr(exc, "__notes__", []))
        return plain
    return exc


class _CallersMain(Exception):
    """The call names something of the caller's ``__main__``, which this process lacks."""


class _Unpickler(pickle.Unpickler):
    """Refuses the caller's ``__main__``: here ``__main__`` is this module."""

    def find_class(self, module: str, name: str) -> Any:
        if module == "__main__":
            raise _CallersMain(f"{name} is defined in the caller's __main__")
        return super().find_class(module, name)


def _pattern(value: Any) -> str:
    """A filter's message or module as ``filterwarnings`` takes it (a plain string of the
    interpreter's own defaults matches exactly)."""
    if value is None:
        return ""
    if isinstance(value, str):
        return re.escape(value) + r"\Z"
    return str(value.pattern)


def _apply_filters(filters: list[tuple[Any, ...]]) -> None:
    """Make the warning filters those of the caller (first wins, as there)."""
    warnings.resetwarnings()
    for action, message, category, module, lineno in reversed(filters):
        warnings.filterwarnings(action, _pattern(message), category, _pattern(module), lineno)


def _child(call: Path, answer: Path) -> int:
    """Run a pickled call and pickle its outcome (the child's side of :func:`call_pinned`)."""
    outcome: tuple[str, Any]
    try:
        with open(call, "rb") as handle:
            function, args, kwargs, filters = _Unpickler(handle).load()
    except _CallersMain as exc:
        outcome = ("unloadable", str(exc))
    except Exception as exc:  # e.g. an import that fails here: an error, not a fallback
        exc.add_note("in the pinned process, loading the call")
        outcome = ("raised", _portable(exc))
    else:
        _apply_filters(filters)
        try:
            outcome = ("returned", function(*args, **kwargs))
        except KeyboardInterrupt:
            return 130  # the parent was interrupted and says so
        except Exception as exc:
            exc.add_note("in the pinned process:\n" + "".join(traceback.format_exception(exc)))
            outcome = ("raised", _portable(exc))
    try:
        data = pickle.dumps(outcome)
    except Exception as exc:
        data = pickle.dumps(("raised", RuntimeError(f"its result cannot be pickled: {exc}")))
    partial = answer.with_suffix(".partial")
    partial.write_bytes(data)
    partial.replace(answer)  # the parent reads a whole answer or none
    return 0


def _interrupt_once(signum: int, frame: Any) -> None:
    """The first SIGINT interrupts; the clean-up it starts is not interrupted again."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    raise KeyboardInterrupt


def _die_with(parent: int) -> None:
    """End this process when ``parent`` dies (Linux, where it runs)."""
    try:
        import ctypes

        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # it died before the request was made
        sys.exit(1)


if __name__ == "__main__":
    signal.signal(signal.SIGINT, _interrupt_once)
    _die_with(int(sys.argv[3]))
    sys.exit(_child(Path(sys.argv[1]), Path(sys.argv[2])))
