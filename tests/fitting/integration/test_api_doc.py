"""docs/api.md's first Python block runs as it stands and fits through the public chain."""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

API_DOC = Path(__file__).resolve().parents[3] / "docs" / "api.md"


def test_the_first_block_of_the_api_doc_fits_and_prints_the_result():
    first = re.search(r"```python\n(.*?)```", API_DOC.read_text(encoding="utf-8"), re.S)
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(first.group(1), str(API_DOC), "exec"), {})
    lines = printed.getvalue().splitlines()
    assert lines[0].startswith("parameter") and "95 % interval" in lines[0]
    assert lines[-1].startswith("success:"), lines[-1]
