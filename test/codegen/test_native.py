"""The native build door: built once per source and compiler, reused, a failure remembered and said."""

import ctypes
import shutil
import subprocess

import pytest

from manip_kin.codegen import native
from manip_kin.codegen.native import NativeRecipe, NativeUnavailable, build_pending, library_path, load_library

pytestmark = pytest.mark.skipif(shutil.which("c++") is None, reason="no C++ compiler")


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("MANIP_KIN_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("MANIP_KIN_NATIVE", raising=False)
    return tmp_path / "cache" / "native"


def _compiles(monkeypatch) -> list:
    """Records the compiler runs (not its --version) from now on."""
    runs, real = [], subprocess.run

    def run(command, *args, **kwargs):
        if "-o" in command:
            runs.append(command)
        return real(command, *args, **kwargs)

    monkeypatch.setattr(native.subprocess, "run", run)
    return runs


def test_a_library_is_built_once_and_rebuilt_when_its_source_changes(tmp_path, cache, monkeypatch):
    source = tmp_path / "answer.cpp"
    source.write_text('extern "C" int answer() { return 42; }\n')
    recipe = NativeRecipe("answer", source)
    runs = _compiles(monkeypatch)
    assert build_pending(recipe)
    library, seconds = load_library(recipe)
    assert library.answer() == 42 and seconds > 0 and len(runs) == 1
    assert not build_pending(recipe)
    path, seconds = library_path(recipe)
    assert seconds == 0.0 and len(runs) == 1 and path.parent == cache
    source.write_text('extern "C" int answer() { return 43; }\n')
    changed, _ = library_path(recipe)
    assert changed != path and len(runs) == 2
    assert ctypes.CDLL(str(changed)).answer() == 43


def test_a_failed_build_is_remembered_and_says_why(tmp_path, cache, monkeypatch):
    source = tmp_path / "broken.cpp"
    source.write_text('extern "C" int answer() { return undefined_name; }\n')
    recipe = NativeRecipe("broken", source)
    runs = _compiles(monkeypatch)
    with pytest.raises(NativeUnavailable, match=r"broken\.cpp does not compile: .*undefined_name"):
        library_path(recipe)
    assert len(runs) == 1 and not build_pending(recipe)
    with pytest.raises(NativeUnavailable, match="undefined_name"):
        library_path(recipe)
    assert len(runs) == 1  # said again without compiling again
    assert list(cache.glob("*.so")) == []  # nothing half-built is left to be loaded


def test_native_off_and_no_compiler_are_said(tmp_path, cache, monkeypatch):
    source = tmp_path / "answer.cpp"
    source.write_text('extern "C" int answer() { return 42; }\n')
    monkeypatch.setenv("MANIP_KIN_NATIVE", "0")
    with pytest.raises(NativeUnavailable, match="MANIP_KIN_NATIVE turns native backends off"):
        library_path(NativeRecipe("answer", source))
    monkeypatch.delenv("MANIP_KIN_NATIVE")
    monkeypatch.setenv("CXX", str(tmp_path / "no-such-compiler"))
    with pytest.raises(NativeUnavailable, match="no C\\+\\+ compiler found"):
        library_path(NativeRecipe("answer", source))


def test_the_same_source_elsewhere_reuses_the_build(tmp_path, cache, monkeypatch):
    text = 'extern "C" int answer() { return 42; }\n'
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    (tmp_path / "one" / "answer.cpp").write_text(text)
    (tmp_path / "two" / "answer.cpp").write_text(text)  # another clone of the same release
    runs = _compiles(monkeypatch)
    first, _ = library_path(NativeRecipe("answer", tmp_path / "one" / "answer.cpp"))
    second, seconds = library_path(NativeRecipe("answer", tmp_path / "two" / "answer.cpp"))
    assert second == first and seconds == 0.0 and len(runs) == 1
