"""The command line answers at once: ``--help`` imports no numerical library."""

from __future__ import annotations

import argparse
import importlib
import subprocess
import sys

import pytest

from hframe_id.cli import COMMANDS

#: Commands whose --help states choices held in modules that import NumPy or CasADi.
HEAVY_HELP = {"export", "control"}

#: Prints, after a command line has run, which modules costing 0.1-2 s each it imported.
PROBE = """
import sys
from hframe_id.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
print("imported:", *sorted(m for m in sys.modules if m.split(".")[0] in ("casadi", "scipy", "numpy",
      "pandas", "matplotlib") or m in ("hframe_id.models", "hframe_id.fitting.fit")))
"""


def _heavy_modules(*argv: str) -> set[str]:
    done = subprocess.run(
        [sys.executable, "-c", PROBE, *argv], capture_output=True, text=True, check=True
    )
    return set(done.stdout.splitlines()[-1].split()[1:])


def test_top_level_help_lists_every_command_without_importing_them():
    done = subprocess.run(
        [sys.executable, "-m", "hframe_id", "--help"], capture_output=True, text=True, check=True
    )
    for name, _, _ in COMMANDS:
        assert f"    {name}" in done.stdout
    assert not _heavy_modules("--help")


@pytest.mark.parametrize("name", [c[0] for c in COMMANDS if c[0] not in HEAVY_HELP])
def test_command_help_imports_no_numerical_library(name):
    assert not _heavy_modules(name, "--help")


@pytest.mark.parametrize(("name", "module", "help_line"), COMMANDS)
def test_table_help_is_the_modules_own(name, module, help_line):
    subparsers = argparse.ArgumentParser().add_subparsers()
    importlib.import_module(module).register(subparsers)
    assert name in subparsers.choices
    assert [a.help for a in subparsers._choices_actions] == [help_line]


def test_help_defaults_agree_with_the_library():
    from hframe_id.cli.validate_command import HELP_DEFAULTS
    from hframe_id.models import VARIANTS, declaration
    from hframe_id.validation import ValidationOptions

    assert HELP_DEFAULTS == {k: getattr(ValidationOptions(), k) for k in HELP_DEFAULTS}
    parser = argparse.ArgumentParser().add_subparsers()
    importlib.import_module("hframe_id.cli.fit_command").register(parser)
    text = parser.choices["fit"].format_help().replace("\n", " ")
    for variant in VARIANTS:
        assert variant in text
        assert declaration(variant).reference_file.name in text.replace(" ", "")


def test_a_fit_imports_neither_scipy_nor_pandas(tmp_path):
    """SciPy's first submodule costs 0.3 s of every fit's start-up (0.49 s of imports before
    the solve, 0.18 s without): ``fit`` reaches its solve without it, and without pandas."""
    from hframe_id.resources import dataset_file

    data = str(dataset_file("4V_xmotion.mcap"))
    heavy = _heavy_modules("fit", data, "--out-dir", str(tmp_path), "--quiet", "--no-plots")
    assert "hframe_id.fitting.fit" in heavy  # the probe saw the fit run
    assert not {m for m in heavy if m.split(".")[0] in ("scipy", "pandas")}
