"""The check shared by the bad-input tests of the command line: a refusal is exit status 2,
exactly one short ``hframe-id: error:`` line naming what was wrong, and no traceback."""

from hframe_id.cli import main

#: An error line longer than this echoes too much of the input (issue 27: values shown with a
#: bounded length).
MAX_LINE = 400


def refused(argv: list, capsys, *named: str) -> str:
    """Run ``argv``: exit status 2, exactly one error line under ``MAX_LINE`` characters naming
    each of ``named``, no traceback; the line."""
    code = main([str(word) for word in argv])
    err = capsys.readouterr().err
    assert code == 2, err[:2000]
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hframe-id: error: "), err[:2000]
    assert len(lines[0]) < MAX_LINE, lines[0][:2000]
    for word in named:
        assert str(word) in lines[0], lines[0]
    return lines[0]
