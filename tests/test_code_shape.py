"""The size limits issue 26 set for the code a reader has to follow: no module in
``hframe_id/`` over 600 lines, no function over 120, and ``docs/fitting.md`` a reference of at
most 300 lines (the dated study logs go to ``docs/studies/``)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 120
MAX_FITTING_DOC_LINES = 300


def _modules():
    return sorted((ROOT / "hframe_id").rglob("*.py"))


def _lines(path: Path) -> int:
    return len(path.read_text(encoding="utf-8").splitlines())


def test_no_module_is_over_600_lines():
    sizes = {str(p.relative_to(ROOT)): _lines(p) for p in _modules()}
    long = {name: n for name, n in sizes.items() if n > MAX_MODULE_LINES}
    assert not long


def test_no_function_is_over_120_lines():
    long = []
    for path in _modules():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.name} ({length})")
    assert not long


def test_the_fitting_reference_is_at_most_300_lines():
    assert _lines(ROOT / "docs" / "fitting.md") <= MAX_FITTING_DOC_LINES
