"""The native-code cache heals itself (issue 27, item 5): a cached library that does not load
is built again, once; a build that does not load either falls back to CasADi with one
warning; an unusable cache folder costs one warning (the libraries are kept for the process
only); a long compile is announced; Ctrl-C while the compiler runs kills its process group."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import casadi as ca
import pytest

from hframe_id import native

needs_compiler = pytest.mark.skipif(not native.compiler_available(), reason="needs a C compiler")


@pytest.fixture
def cache(monkeypatch, tmp_path) -> Path:
    """An empty cache folder for this test (``HFRAME_ID_CACHE``), and warnings not yet given."""
    monkeypatch.setenv("HFRAME_ID_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(native, "_warned", False)
    monkeypatch.setattr(native, "_private", None)
    return tmp_path / "cache"


def _halve() -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function("halve_healing", [x], [x / 2])


def _fake_compiler(folder: Path, body: str) -> Path:
    """A compiler that answers ``--version`` and otherwise runs ``body`` (sh)."""
    compiler = folder / "fake-cc"
    compiler.write_text(
        f'#!/bin/sh\nif [ "$1" = --version ]; then echo "fake 1.0"; exit 0; fi\n{body}\n'
    )
    compiler.chmod(0o755)
    return compiler


COMPILE = """
import casadi as ca
from hframe_id import native
x = ca.SX.sym("x")
native.compile_function(ca.Function("halve_healing", [x], [x / 2]))
"""


@needs_compiler
@pytest.mark.parametrize("damage", [b"", b"\x7fELF garbage" * 100], ids=["empty", "garbage"])
def test_a_cached_library_that_does_not_load_is_built_again(cache, recwarn, damage):
    # Built by another process: one loaded here would be found by the loader by its name.
    subprocess.run([sys.executable, "-c", COMPILE], check=True, timeout=120)
    (library,) = (cache / "native").glob("halve_healing-*.so")
    library.write_bytes(damage)
    f = native.compile_function(_halve())
    assert library.stat().st_size > 1000 and float(f(3.0)) == 1.5
    assert not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_a_build_that_does_not_load_falls_back_with_one_warning(cache, monkeypatch, tmp_path):
    # The "compiler" writes garbage where the library goes ("-o" is the argument before
    # "-lm", the last one).
    body = 'out=""; prev=""; for a in "$@"; do [ "$prev" = -o ] && out="$a"; prev="$a"; done\n'
    body += 'echo garbage > "$out"'
    monkeypatch.setenv("CC", str(_fake_compiler(tmp_path, body)))
    with pytest.warns(native.NativeCodeWarning) as caught:
        assert native.compile_function(_halve()) is None
        assert native.compile_function(_halve(), ("-O1",)) is None
    assert len(caught) == 1 and "does not load" in str(caught[0].message)
    assert native.cache_info().libraries == 0


@needs_compiler
@pytest.mark.parametrize("where", ["a-file", "under-a-file", "proc"])
def test_an_unusable_cache_folder_warns_once_and_still_compiles(
    cache, monkeypatch, tmp_path, where
):
    blocker = tmp_path / "blocker"
    blocker.write_text("not a folder")
    root = {"a-file": blocker, "under-a-file": blocker / "cache", "proc": Path("/proc/hf")}
    monkeypatch.setenv("HFRAME_ID_CACHE", str(root[where]))
    with pytest.warns(native.NativeCacheWarning) as caught:
        f = native.compile_function(_halve())
        g = native.compile_function(_halve(), ("-O1",))
    assert float(f(3.0)) == float(g(3.0)) == 1.5
    assert len(caught) == 1 and str(root[where]) in str(caught[0].message)
    assert blocker.read_text() == "not a folder"


def test_a_long_compile_is_announced(cache, monkeypatch, tmp_path, caplog):
    monkeypatch.setenv("CC", str(_fake_compiler(tmp_path, "sleep 0.5; exit 1")))
    monkeypatch.setattr(native, "ANNOUNCE_AFTER_S", 0.1)
    with caplog.at_level(logging.INFO, logger="hframe_id"), pytest.warns(native.NativeCodeWarning):
        assert native.compile_function(_halve()) is None
    assert [r.getMessage() for r in caplog.records if r.name == "hframe_id.native"] == [
        f"compiling halve_healing ({len(native.c_source(_halve())) // 1000} kB of C) to "
        f"native code, once: it is kept in {cache / 'native'}"
    ]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_ctrl_c_during_a_compile_kills_the_compilers_group(tmp_path):
    started = tmp_path / "started"
    body = f'sleep 60 &\necho "$$ $!" > {started}.tmp; mv {started}.tmp {started}\nwait'
    env = {**os.environ, "CC": str(_fake_compiler(tmp_path, body))}
    env["HFRAME_ID_CACHE"] = str(tmp_path / "cache")
    # A child inherits its parent's ignored and blocked signals (a test worker's may differ
    # from a terminal's): it takes Ctrl-C as a command run from a terminal does.
    catch_interrupts = (
        "import signal\nsignal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})\n"
        "signal.signal(signal.SIGINT, signal.default_int_handler)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", catch_interrupts + COMPILE],
        env=env,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 60
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        driver, child = map(int, started.read_text().split())
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode != 0 and "KeyboardInterrupt" in err
    deadline = time.monotonic() + 10
    while (_alive(driver) or _alive(child)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(driver) and not _alive(child)
