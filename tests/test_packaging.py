"""A non-editable install works: the wheel carries the thesis's parameter files and the
shipped datasets, and ``hframe-id fit 4V_xmotion.mcap`` runs from an unrelated directory.

The wheel is built as ``python -m build`` would, offline: an sdist of a copy of this source
tree, then a wheel from that sdist (so a file the sdist forgets is missing from the wheel too).
It is installed into a bare folder and run with ``PYTHONPATH`` pointing there, not into a new
venv: the dependencies come from this environment and no network is needed.
"""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
import yaml

pytestmark = [pytest.mark.integration, pytest.mark.slow]

ROOT = Path(__file__).resolve().parents[1]
#: Not part of the source: the environment, caches, build output, results.
NOT_SOURCE = shutil.ignore_patterns(
    ".git", ".venv", "build", "dist", "*.egg-info", "__pycache__", "*.pyc", ".pytest_cache",
    ".ruff_cache", "fits", "reports", "out", "jit_tmp*", "tmp_casadi_compiler_shell*",
)  # fmt: skip


def _run(args: list[str], cwd: Path, env: dict | None = None) -> str:
    done = subprocess.run(args, cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{args} exited {done.returncode}:\n{done.stdout}\n{done.stderr}"
    return done.stdout


def _shipped_sources() -> list[str]:
    """The files the wheel must carry under hframe_id/_data/, from the checkout."""
    files = list((ROOT / "models").glob("*.yaml"))
    for pattern in ("*.mcap", "*.yaml", "README*"):
        files += (ROOT / "datasets").rglob(pattern)
    return sorted(p.relative_to(ROOT).as_posix() for p in files)


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The wheel, built from an sdist of the source tree and installed into a bare folder."""
    pytest.importorskip("setuptools", minversion="70.1", reason="builds wheels (test extra)")
    tmp = tmp_path_factory.mktemp("packaging")
    source = tmp / "source"
    shutil.copytree(ROOT, source, ignore=NOT_SOURCE)
    build_sdist = (
        "import sys; from setuptools import build_meta as b; print(b.build_sdist(sys.argv[1]))"
    )
    sdist = _run([sys.executable, "-c", build_sdist, str(tmp / "sdist")], cwd=source).split()[-1]
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "--no-input"]
    build = ["wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", str(tmp / "dist")]
    _run([*pip, *build, str(tmp / "sdist" / sdist)], cwd=tmp)
    (wheel,) = (tmp / "dist").glob("hframe_id-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    missing = [f for f in _shipped_sources() if f"hframe_id/_data/{f}" not in names]
    assert not missing, f"{wheel.name} lacks {missing}"
    assert "hframe_id/resources.py" in names
    research = sorted(
        n for n in names if n.split("/")[0] in ("studies", "bench") or "/studies/" in n
    )
    assert not research, f"{wheel.name} ships research code: {research[:5]}"
    assert wheel.stat().st_size < 10e6, "the wheel should hold the example data, not more"
    target = tmp / "site"
    install = ["install", "--no-deps", "--no-index", "--no-compile", "--target", str(target)]
    _run([*pip, *install, str(wheel)], cwd=tmp)
    return target


def _env(site: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    return env | {"PYTHONPATH": str(site), "MPLBACKEND": "Agg"}


def test_installed_package_finds_its_parameter_files_and_datasets(site, tmp_path):
    code = (
        "import hframe_id, json; from hframe_id import resources as r; print(json.dumps("
        "[hframe_id.__file__, r.project_root() is None, str(r.models_dir()),"
        " sorted(p.name for p in r.models_dir().glob('*.yaml')),"
        " str(r.dataset_file('4V_xmotion.mcap'))]))"
    )
    out = _run([sys.executable, "-c", code], cwd=tmp_path, env=_env(site))
    package, installed, models, listed, dataset = yaml.safe_load(out)
    # imported from the installed folder, not from this checkout (the editable install)
    assert Path(package).is_relative_to(site)
    assert installed
    assert Path(models) == site / "hframe_id" / "_data" / "models"
    assert listed == sorted(p.name for p in (ROOT / "models").glob("*.yaml"))
    assert "hframe-8-table4.2.yaml" in listed
    assert Path(dataset) == site / "hframe_id" / "_data" / "datasets" / "4V_xmotion.mcap"


def test_installed_command_fits_a_shipped_dataset_from_an_unrelated_directory(site, tmp_path):
    script = site / "bin" / "hframe-id"
    assert script.is_file(), "the console entry point was not installed"
    _run([str(script), "fit", "4V_xmotion.mcap", "--quiet"], cwd=tmp_path, env=_env(site))
    (parameter_file,) = (tmp_path / "fits").glob("*.yaml")
    assert list((tmp_path / "fits").glob("*-report.md"))
    provenance = yaml.safe_load(parameter_file.read_text())["provenance"]
    # a shipped dataset is recorded by its name in the project, not by site-packages' path;
    # there is no source tree, hence no commit
    assert provenance["datasets"][0]["file"] == "datasets/4V_xmotion.mcap"
    assert provenance["git_commit"] == "unknown"
    assert provenance["solver"]["success"] is True
