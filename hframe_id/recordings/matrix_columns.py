"""Matrix columns as ``--map`` sources: ``data(:,3)`` (MATLAB, 1-based) and ``data[:,2]``
(NumPy, 0-based) both name the third column of the variable ``data``.

The one parser of the syntax: ``sources.SourceTable.column`` resolves such a name to a vector,
``import_spec.ColumnMap`` asks for a channel name for it. Pure text, so that the command line
can be checked without numpy.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

_SYNTAX = re.compile(
    r"^(?P<variable>.+?)\s*(?:\(\s*:\s*,\s*(?P<matlab>[^()]*?)\s*\)|\[\s*:\s*,\s*(?P<numpy>[^\[\]]*?)\s*\])$"
)


@dataclass(frozen=True)
class MatrixColumn:
    """A column of a matrix variable, as written in ``--map``.

    Attributes
    ----------
    text : the source name as given (``data(:,3)``).
    variable : the matrix's name (``data``).
    index : the column's 0-based index, or None if the index text is not a valid index
        for its syntax (``problem`` says why).
    problem : why the index is not valid ("" if it is).
    """

    text: str
    variable: str
    index: int | None
    problem: str = ""

    def describe_range(self, n_columns: int) -> str:
        """Valid indices of a matrix with ``n_columns`` columns, in both syntaxes."""
        if n_columns == 0:
            return "it has no columns"
        return (
            f"columns are {self.variable}(:,1) to {self.variable}(:,{n_columns}) (MATLAB, "
            f"1-based) or {self.variable}[:,0] to {self.variable}[:,{n_columns - 1}] "
            "(NumPy, 0-based)"
        )


def parse_matrix_column(text: str) -> MatrixColumn | None:
    """``VAR(:,K)`` (K = 1, 2, ...) or ``VAR[:,K]`` (K = 0, 1, ...) as a ``MatrixColumn``;
    None if ``text`` is not in that form (a plain column or variable name)."""
    match = _SYNTAX.match(text.strip())
    if match is None:
        return None
    variable = match["variable"].strip()
    matlab = match["matlab"] is not None
    index_text = match["matlab"] if matlab else match["numpy"]
    first = 1 if matlab else 0
    if not re.fullmatch(r"[0-9]+", index_text) or int(index_text) < first:
        kind = "MATLAB, 1-based" if matlab else "NumPy, 0-based"
        return MatrixColumn(
            text,
            variable,
            None,
            f"column index {index_text!r} is not an integer >= {first} ({kind})",
        )
    return MatrixColumn(text, variable, int(index_text) - first)
