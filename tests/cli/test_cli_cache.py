"""The native-code cache from the command line (issue 27, item 5): ``cache info`` and ``cache
clear`` refuse a cache folder that cannot be used in one line (``$HFRAME_ID_CACHE`` naming a
file, a folder under a file, or a place that cannot be written) and touch nothing. (Fits and
simulations with such a cache still run, with one warning: tests/test_native_healing.py.)"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from refusals import refused


@pytest.fixture
def blocker(tmp_path) -> Path:
    path = tmp_path / "afile"
    path.write_text("not a folder\n")
    return path


@pytest.mark.parametrize("action", ["info", "clear"])
@pytest.mark.parametrize("where", ["a-file", "under-a-file", "proc"])
def test_an_unusable_cache_folder_is_one_line(blocker, capsys, monkeypatch, action, where):
    root = {"a-file": blocker, "under-a-file": blocker / "cache", "proc": Path("/proc/hf")}
    monkeypatch.setenv("HFRAME_ID_CACHE", str(root[where]))
    refused(["cache", action], capsys, "cache folder", root[where] / "native")
    assert blocker.read_text() == "not a folder\n"


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0] != "Z"
    except OSError:
        return False


def test_a_hanging_compiler_is_given_up_with_what_it_started(tmp_path, monkeypatch):
    """A $CC that never answers --version was waited on for 600 s, and killing the command
    left what the compiler had started running: the probe gives up after VERSION_TIMEOUT_S
    and kills the compiler's whole process group."""
    from hframe_id import native

    pid_file = tmp_path / "child.pid"
    compiler = tmp_path / "cc-hangs"
    compiler.write_text(f"#!/bin/sh\nsleep 300 &\necho $! > {pid_file}\nwait\n")
    compiler.chmod(0o755)
    monkeypatch.setenv("CC", str(compiler))
    monkeypatch.setattr(native, "VERSION_TIMEOUT_S", 0.5)
    start = time.monotonic()
    native.compiler()  # the next compiler on the list, or None
    assert time.monotonic() - start < 30
    child = int(pid_file.read_text())
    deadline = time.monotonic() + 5
    while _running(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _running(child)
