"""A batch fit's row and its files are stored together (issue 27, item 6): each fit writes into
a hidden folder of its own, which the client moves into the output folder when it stores the
row (``runner.place_files``); a fit whose row is never stored leaves nothing."""

from __future__ import annotations

from pathlib import Path

from hframe_id.fleet.keys import staged_folder
from hframe_id.fleet.runner import place_files

KEY = "0123456789abcdef0123456789abcdef"


def _staged(out: Path) -> Path:
    staged = staged_folder(out, KEY)
    (staged / "fit-plots").mkdir(parents=True)
    (staged / "fit-plots" / "x.png").write_bytes(b"png")
    (staged / "fit.yaml").write_text("fit\n")
    (staged / "fit-report.md").write_text("report\n")
    return staged


def test_a_stored_row_brings_its_files(tmp_path):
    staged = _staged(tmp_path)
    row = {"key": KEY, "status": "ok", "parameter_file": str(tmp_path / "fit.yaml")}
    assert place_files(row, tmp_path) == row
    assert not staged.exists()
    assert sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*")) == [
        "fit-plots", "fit-plots/x.png", "fit-report.md", "fit.yaml"
    ]  # fmt: skip


def test_a_file_of_that_name_already_there_makes_an_error_row_and_moves_nothing(tmp_path):
    staged = _staged(tmp_path)
    (tmp_path / "fit-report.md").write_text("older\n")
    row = {"key": KEY, "status": "ok", "parameter_file": str(tmp_path / "fit.yaml")}
    placed = place_files(row, tmp_path)
    assert placed["status"] == "error" and "fit-report.md exists already" in placed["message"]
    assert placed["parameter_file"] is None
    assert not staged.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fit-report.md"]
    assert (tmp_path / "fit-report.md").read_text() == "older\n"


def test_a_row_without_files_is_stored_as_it_is(tmp_path):
    row = {"key": KEY, "status": "error", "message": "broken.mcap: not an MCAP file"}
    assert place_files(row, tmp_path) == row
    assert list(tmp_path.iterdir()) == []
