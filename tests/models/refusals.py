"""The refusal every bad model file gets: one line naming the file, from the library and
from the command line (exit 2)."""

from __future__ import annotations

import pytest

from hframe_id.cli import main
from hframe_id.errors import ModelError
from hframe_id.models import load_model_file


def refused_model_file(path, message: str, capsys) -> None:
    """``path`` is refused with ``message``: ``load_model_file`` raises one line naming the
    file, and ``hframe-id models --model-file`` prints one line and exits 2."""
    with pytest.raises(ModelError) as err:
        load_model_file(path)
    assert message in str(err.value)
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    assert main(["models", "--model-file", str(path)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and message in error
