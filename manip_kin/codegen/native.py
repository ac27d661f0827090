"""Compiled backends: a C++ source of the package built once with the system's compiler, kept in a
cache, loaded with ctypes.

This is the door for native code, as :mod:`manip_kin.codegen.kernel_cache` is for generated
Python: a caller names its source and what it links (:class:`NativeRecipe`), and gets a
``ctypes.CDLL`` or :class:`NativeUnavailable` saying why not (no compiler, a header not found, a
compile error). Every native backend has a Python implementation behind it, so a machine without a
compiler runs the same, slower.

The library is cached under ``$MANIP_KIN_CACHE`` (default ``$XDG_CACHE_HOME/manip_kin``, else
``~/.cache/manip_kin``), in ``native/<name>-<key>.so``. The key hashes the source text, the
compiler's version line, the flags and the recipe's ``version`` (the linked library's release), so
an edit or a new release builds afresh and nothing stale is loaded. Builds take a file lock and
write through a temporary name, so processes that start together (a launch, the test workers)
build once and never load half a file. A failed build is remembered under the same key
(``.failed``, with its first error line), so later processes say why at once instead of compiling
again. ``MANIP_KIN_NATIVE=0`` turns native backends off.
"""

from __future__ import annotations

import ctypes
import fcntl
import functools
import hashlib
import os
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from manip_kin.errors import OperationError

#: Compile flags (with ``-I``, ``-L``, ``-l`` and the rpath of the recipe).
FLAGS = ("-O2", "-std=c++17", "-shared", "-fPIC", "-DNDEBUG")

#: A build longer than this is abandoned [s] (coal's headers take about 10 s on one core here).
BUILD_TIMEOUT_S = 300.0


class NativeUnavailable(OperationError):
    """A native backend cannot be used here; the message says why (its callers fall back to Python)."""


@dataclass(frozen=True)
class NativeRecipe:
    """How to build one library.

    Attributes:
        name: the library's name in the cache (``narrow_phase``).
        source: the C++ file.
        include_dirs: ``-I`` directories.
        library_dirs: ``-L`` directories, also the library's run path.
        libraries: ``-l`` names.
        version: what else the build depends on (the linked library's release), for the key.
    """

    name: str
    source: Path
    include_dirs: tuple[str, ...] = ()
    library_dirs: tuple[str, ...] = ()
    libraries: tuple[str, ...] = ()
    version: str = ""


def disabled() -> bool:
    """True when ``MANIP_KIN_NATIVE`` turns native backends off (``0``, ``off``, ``false``)."""
    return os.environ.get("MANIP_KIN_NATIVE", "").strip().lower() in ("0", "off", "false", "no")


def require_enabled() -> None:
    """Raise :class:`NativeUnavailable` when :func:`disabled` (looked at on every call, so that a
    library loaded before the switch was set is not used after it)."""
    if disabled():
        raise NativeUnavailable("MANIP_KIN_NATIVE turns native backends off")


def cache_dir() -> Path:
    """Where built libraries are kept (see the module docstring)."""
    root = os.environ.get("MANIP_KIN_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "manip_kin"
    )
    return Path(root) / "native"


def _compiler() -> tuple[str, str]:
    """The C++ compiler (``$CXX``, else ``c++``/``g++``/``clang++``) and its version line."""
    return _compiler_on(os.environ.get("CXX", ""), os.environ.get("PATH", ""))


@functools.lru_cache(maxsize=8)
def _compiler_on(cxx: str, search_path: str) -> tuple[str, str]:
    """:func:`_compiler` for one ``$CXX`` and ``$PATH``: asked once per process (a node's start
    asks whether a build is pending, then builds or loads)."""
    candidates = [cxx] if cxx else ["c++", "g++", "clang++"]
    for candidate in candidates:
        path = shutil.which(candidate, path=search_path or None)
        if path is None:
            continue
        try:
            version = subprocess.run([path, "--version"], capture_output=True, text=True, timeout=30).stdout
        except (OSError, subprocess.SubprocessError):
            continue
        return path, version.splitlines()[0] if version else ""
    raise NativeUnavailable(f"no C++ compiler found (tried {', '.join(candidates)}; set CXX)")


def _command(recipe: NativeRecipe, compiler: str, output: Path) -> list[str]:
    return [
        compiler,
        *FLAGS,
        *(f"-I{d}" for d in recipe.include_dirs),
        str(recipe.source),
        "-o",
        str(output),
        *(f"-L{d}" for d in recipe.library_dirs),
        *(f"-Wl,-rpath,{d}" for d in recipe.library_dirs),
        *(f"-l{lib}" for lib in recipe.libraries),
    ]


def _target(recipe: NativeRecipe) -> tuple[str, Path]:
    """The compiler and the cache path of ``recipe``'s library (see the module docstring)."""
    require_enabled()
    compiler, version = _compiler()
    try:
        text = recipe.source.read_bytes()
    except OSError as error:
        raise NativeUnavailable(f"{recipe.source}: {error.strerror}") from None
    digest = hashlib.sha256()
    # Not the source's path: checkouts that build against the same coal (the flags hold its
    # directories, which the library's run path points at) share the build.
    flags = (FLAGS, recipe.include_dirs, recipe.library_dirs, recipe.libraries)
    for part in (text, version.encode(), repr(flags).encode(), recipe.version.encode()):
        digest.update(part)
        digest.update(b"\0")
    return compiler, cache_dir() / f"{recipe.name}-{digest.hexdigest()[:16]}.so"


def build_pending(recipe: NativeRecipe) -> bool:
    """True when :func:`library_path` would compile (not built yet, not failed before, not off)."""
    try:
        _, target = _target(recipe)
    except NativeUnavailable:
        return False
    return not target.exists() and not target.with_suffix(".failed").exists()


def library_path(recipe: NativeRecipe) -> tuple[Path, float]:
    """The built library of ``recipe`` (building it if it is not cached) and the build's
    duration [s] (0 when it was cached).

    Raises:
        NativeUnavailable: disabled, no compiler, or the compile failed (with its first error line).
    """
    compiler, target = _target(recipe)
    directory = target.parent
    failed = target.with_suffix(".failed")
    if target.exists():
        return target, 0.0
    if failed.exists():  # the same source, compiler and flags failed before: say why, at once
        raise NativeUnavailable(failed.read_text(errors="replace").strip())
    try:
        directory.mkdir(parents=True, exist_ok=True)
        lock = open(directory / f"{target.name}.lock", "w")  # noqa: SIM115 - held across the build
    except OSError as error:
        raise NativeUnavailable(f"cache {directory}: {error.strerror}") from None
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # another process may be building it: wait, then reuse
        if target.exists():
            return target, 0.0
        if failed.exists():
            raise NativeUnavailable(failed.read_text(errors="replace").strip())
        handle, temporary = tempfile.mkstemp(dir=directory, prefix=f".{recipe.name}-", suffix=".so")
        os.close(handle)
        start = time.monotonic()
        try:
            done = subprocess.run(
                _command(recipe, compiler, Path(temporary)), capture_output=True, text=True, timeout=BUILD_TIMEOUT_S
            )
            if done.returncode != 0:
                lines = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.splitlines()
                problem = f"{recipe.source.name} does not compile: {lines[0] if lines else done.returncode}"
                failed.write_text(problem + "\n")
                raise NativeUnavailable(problem)
            os.replace(temporary, target)
        except subprocess.TimeoutExpired:
            raise NativeUnavailable(f"{recipe.source.name}: compile took over {BUILD_TIMEOUT_S:.0f} s") from None
        finally:
            if os.path.exists(temporary):
                os.unlink(temporary)
    return target, time.monotonic() - start


def load_library(recipe: NativeRecipe, hold_gil: bool = False) -> tuple[ctypes.CDLL, float]:
    """The built ``recipe`` loaded, and the build's duration [s] (see :func:`library_path`).

    ``hold_gil``: its functions keep the GIL while they run (``ctypes.PyDLL``). For short calls
    in a control loop: releasing it would let another thread take it, and the loop wait for its
    return. The functions must not call back into Python.
    """
    path, seconds = library_path(recipe)
    try:
        return (ctypes.PyDLL if hold_gil else ctypes.CDLL)(str(path)), seconds
    except OSError as error:
        raise NativeUnavailable(f"{path}: cannot load: {error}") from None
