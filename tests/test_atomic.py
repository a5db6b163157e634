"""``hframe_id.atomic.Staging``: the outputs of one command are put in place together or not at
all, and leave no temporary behind."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from hframe_id.atomic import Staging, staged_directory


def _tree(folder: Path) -> dict[str, str | None]:
    return {
        str(p.relative_to(folder)): p.read_text() if p.is_file() else None
        for p in folder.rglob("*")
    }


def test_commit_puts_files_and_folders_in_place(tmp_path):
    (tmp_path / "old.txt").write_text("old")
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "stale.png").write_text("stale")
    staging = Staging()
    staging.write(tmp_path / "old.txt", "new")
    staging.write(tmp_path / "a" / "b" / "c.csv", "c")
    (staging.folder(tmp_path / "plots") / "k_l.png").write_text("png")
    assert staging.file(tmp_path / "x.png").suffix == ".png"  # writers go by the suffix
    assert set(_tree(tmp_path)) >= {"old.txt", "plots/stale.png"}  # nothing in place yet
    staging.commit()
    assert _tree(tmp_path) == {
        "old.txt": "new",
        "a": None,
        "a/b": None,
        "a/b/c.csv": "c",
        "plots": None,
        "plots/k_l.png": "png",  # a staged folder replaces its target as a whole
        "x.png": "",
    }


def test_discard_leaves_the_tree_as_it_was(tmp_path):
    (tmp_path / "old.txt").write_text("old")
    before = _tree(tmp_path)
    staging = Staging()
    staging.write(tmp_path / "old.txt", "new")
    staging.write(tmp_path / "new" / "deep" / "f.txt", "f")
    staging.folder(tmp_path / "plots")
    staging.discard()
    assert _tree(tmp_path) == before


def test_a_failed_commit_puts_nothing_in_place(tmp_path):
    (tmp_path / "old.txt").write_text("old")
    (tmp_path / "plots").mkdir()
    (tmp_path / "plots" / "kept.png").write_text("kept")
    staging = Staging()
    staging.write(tmp_path / "old.txt", "new")
    (staging.folder(tmp_path / "plots") / "k_l.png").write_text("png")
    staging.write(tmp_path / "gone" / "last.txt", "last")
    shutil.rmtree(tmp_path / "gone")  # the folder of the last output vanishes meanwhile
    with pytest.raises(FileNotFoundError):
        staging.commit()
    staging.discard()
    assert _tree(tmp_path) == {"old.txt": "old", "plots": None, "plots/kept.png": "kept"}


def test_staged_directory_is_removed_on_an_exception(tmp_path):
    with pytest.raises(RuntimeError), staged_directory(tmp_path / "out") as folder:
        (folder / "half.png").write_text("half")
        raise RuntimeError("interrupted")
    assert _tree(tmp_path) == {}
