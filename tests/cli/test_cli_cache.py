"""The native-code cache from the command line (issue 27, item 5): ``cache info`` and ``cache
clear`` refuse a cache folder that cannot be used in one line (``$HFRAME_ID_CACHE`` naming a
file, a folder under a file, or a place that cannot be written) and touch nothing. (Fits and
simulations with such a cache still run, with one warning: tests/test_native_healing.py.)"""

from __future__ import annotations

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
