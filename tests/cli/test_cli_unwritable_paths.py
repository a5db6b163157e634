"""Outputs that cannot be written and inputs that cannot be read, tried for real (issue 27).

Permission bits do not stop root, and the CI runs the tests as root: there each command runs
in a subprocess as an unprivileged user (``UNPRIVILEGED_UID``), in a folder made for it;
otherwise directly as the user running the tests. Every case must end in one line
``hframe-id: error: ...`` naming the path and the problem, exit status 2, no traceback,
before any work, and leave nothing behind. Save one: a fit never replaces a parameter file,
read-only or not; it writes beside it, under the next free id.
"""

from __future__ import annotations

import os
import shutil
import site
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
from fit_rows import stored_fits

from hframe_id.digests import sha256_file
from hframe_id.fitting.output import make_fit_id

REPO = Path(__file__).resolve().parents[2]
H8 = REPO / "models" / "hframe-8-table4.2.yaml"
RECORDING = REPO / "datasets" / "5V_oneaxis.mcap"
ONE_AXIS = REPO / "models" / "one-axis-table2.1.yaml"
STEP = ["--step", "1,4", "--duration", "0.05", "--quiet"]
CSV = "t,u,x\n" + "".join(f"{k * 0.001:.3f},1,{k * 1e-4:g}\n" for k in range(50))
MANIFEST = (
    "format_version: '1.0'\ntitle: t\n"
    f"defaults: {{model: hframe-8, initial: {H8}}}\n"
    f"fits:\n- rig: rig-01\n  time: '2026-01-05T08:00:00+00:00'\n  recordings: [{RECORDING}]\n"
)
#: ``nobody`` on Debian and most Linux systems.
UNPRIVILEGED_UID = 65534
AS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0


def _pythons() -> Iterator[tuple[str, str]]:
    """Interpreters the unprivileged user may run, with the PYTHONPATH each needs: this one
    (a venv whose interpreter may sit in root's home, out of that user's reach), then the
    system's of the same version with this environment's packages on the path."""
    packages = os.pathsep.join([str(REPO), *site.getsitepackages()])
    yield sys.executable, packages
    version = f"python{sys.version_info.major}.{sys.version_info.minor}"
    for folder in ("/usr/bin", "/usr/local/bin"):
        candidate = Path(folder) / version
        if candidate.is_file():
            yield str(candidate), packages


@pytest.fixture(scope="module")
def runner() -> Iterator[Callable[..., subprocess.CompletedProcess]]:
    """``run(argv, cwd)``: ``hframe-id`` with ``argv`` in ``cwd``, as the unprivileged user
    when the tests run as root."""
    if not AS_ROOT:
        env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg"}

        def run_direct(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
            command = [sys.executable, "-m", "hframe_id", *argv]
            return subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True)

        yield run_direct
        return

    home = Path(tempfile.mkdtemp(prefix="hframe-id-home-"))
    os.chown(home, UNPRIVILEGED_UID, -1)
    try:
        tried = []
        for python, path in _pythons():
            env = {
                "PATH": "/usr/bin:/bin",
                "HOME": str(home),
                "MPLCONFIGDIR": str(home / "mpl"),
                "HFRAME_ID_CACHE": str(home / "cache"),
                "MPLBACKEND": "Agg",
                "PYTHONPATH": path,
            }
            try:
                probe = subprocess.run(
                    [python, "-c", "import hframe_id.cli, numpy, yaml"],
                    cwd=home,
                    env=env,
                    user=UNPRIVILEGED_UID,
                    capture_output=True,
                    text=True,
                )
            except OSError as err:  # the interpreter itself out of reach
                tried.append(f"{python}: {err.strerror}")
                continue
            if probe.returncode == 0:

                def run_unprivileged(argv, cwd, python=python, env=env):
                    command = [python, "-m", "hframe_id", *argv]
                    return subprocess.run(
                        command,
                        cwd=cwd,
                        env=env,
                        user=UNPRIVILEGED_UID,
                        capture_output=True,
                        text=True,
                    )

                yield run_unprivileged
                return
            tried.append(f"{python}: {probe.stderr.strip().splitlines()[-1:]}")
        pytest.fail(
            f"running as root, and uid {UNPRIVILEGED_UID} can run no Python with hframe_id "
            f"(tried {'; '.join(tried)}): make the repository and an interpreter with its "
            "packages readable by that user, or run the tests as a normal user"
        )
    finally:
        shutil.rmtree(home, ignore_errors=True)


@pytest.fixture
def folder() -> Iterator[Path]:
    """A folder the command's user owns (tmp_path may sit in root's private folder)."""
    path = Path(tempfile.mkdtemp(prefix="hframe-id-perm-"))
    if AS_ROOT:
        os.chown(path, UNPRIVILEGED_UID, -1)
    yield path
    for item in [path, *path.rglob("*")] if path.exists() else []:
        item.chmod(0o755 if item.is_dir() else 0o644)
    shutil.rmtree(path, ignore_errors=True)


def _prepare(folder: Path, name: str, mode: int, content: str | None = None) -> Path:
    """``folder/name``, a folder (``content`` None) or a file, owned by the command's user,
    with ``mode``."""
    path = folder / name
    if content is None:
        path.mkdir()
    else:
        path.write_text(content)
    if AS_ROOT:
        os.chown(path, UNPRIVILEGED_UID, -1)
    path.chmod(mode)
    return path


def _listing(folder: Path) -> dict[str, bytes | None]:
    """Every file under ``folder`` with its content (folders: None); read as root or as
    the owner after the run, modes restored first."""
    for item in folder.rglob("*"):
        if item.is_dir():
            item.chmod(0o755)
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
        for p in sorted(folder.rglob("*"))
    }


def _refused(result: subprocess.CompletedProcess, *fragments: str) -> str:
    """The one error line of a refused command, checked to hold ``fragments``."""
    assert "Traceback" not in result.stderr, result.stderr
    errors = [line for line in result.stderr.splitlines() if line.startswith("hframe-id: error:")]
    assert len(errors) == 1, result.stderr
    assert result.returncode == 2, result.stderr
    for fragment in fragments:
        assert fragment in errors[0], errors[0]
    return errors[0]


# (name, argv with OUT for the output, the output's name in the blocked place)
FILE_OUTPUTS = [
    ("export", ["export", str(H8), "--format", "json", "--out", "OUT"], "p.json"),
    ("simulate", ["simulate", "--params", str(H8), *STEP, "--out", "OUT"], "s.csv"),
    (
        "simulate-mcap",
        ["simulate", "--params", str(H8), *STEP, "--out", "{d}/s.csv", "--mcap", "OUT"],
        "s.mcap",
    ),
    (
        "design",
        [
            "design",
            "--params",
            str(H8),
            "--duration",
            "0.2",
            "--max-voltage",
            "2",
            "--travel",
            "x=-0.2:0.2",
            "--travel",
            "y=-0.2:0.2",
            "--draws",
            "1",
            "--out",
            "OUT",
        ],
        "d.csv",
    ),
    (
        "import",
        [
            "import",
            "{d}/in.csv",
            "--map",
            "t=time:s",
            "--map",
            "u=input:V",
            "--map",
            "x=output:m",
            "--variant",
            "my-axis",
            "--out",
            "OUT",
        ],
        "r.mcap",
    ),
    (
        "record",
        ["record", "--rig", "sim", "--params", str(H8), "--v1", "1", "--v2", "1"]
        + ["--step", "0.05", "--duration", "0.2", "--fast", "--quiet", "--out", "OUT"],
        "r.mcap",
    ),
    ("batch-results", ["batch", "{d}/m.yaml", "--results", "OUT", "--workers", "1"], "r.parquet"),
]
FOLDER_OUTPUTS = [
    (
        "fit",
        ["fit", str(RECORDING), "--initial", str(ONE_AXIS), "--no-plots"]
        + ["--no-cross-validation", "--max-iterations", "1", "--out-dir", "OUT"],
        "fits",
    ),
    ("validate", ["validate", str(ONE_AXIS), str(RECORDING), "--plot", "OUT"], "plots"),
    (
        "simulate-plot",
        ["simulate", "--params", str(H8), *STEP, "--out", "{d}/s.csv", "--plot", "OUT"],
        "plots",
    ),
    ("fleet-make", ["fleet", "make", "--rigs", "1", "--weeks", "2", "--out", "OUT"], "fleet"),
    ("reproduce", ["reproduce", "--no-sensitivity", "--out", "OUT"], "rep"),
    (
        "batch-out-dir",
        ["batch", "{d}/m.yaml", "--results", "{d}/r.parquet", "--out-dir", "OUT"],
        "fits",
    ),
]
# (kind of blocked place: the folder's mode, where the output goes in it, the error's words)
BLOCKED = {
    "read-only-folder": (0o555, "{name}", "cannot write in"),
    "folder-without-execute": (0o666, "{name}", "cannot be searched (Permission denied)"),
    "inside-unreadable-folder": (0o000, "sub/{name}", "cannot be searched (Permission denied)"),
}


def _argv(argv: list[str], folder: Path, out: Path) -> list[str]:
    return [a.replace("{d}", str(folder)).replace("OUT", str(out)) for a in argv]


def _inputs(folder: Path) -> None:
    _prepare(folder, "m.yaml", 0o644, MANIFEST)
    _prepare(folder, "in.csv", 0o644, CSV)


@pytest.mark.parametrize("blocked", sorted(BLOCKED))
@pytest.mark.parametrize(
    ("argv", "name"),
    [pytest.param(argv, name, id=case) for case, argv, name in FILE_OUTPUTS + FOLDER_OUTPUTS],
)
def test_output_in_a_blocked_folder_is_refused_before_any_work(runner, folder, blocked, argv, name):
    mode, where, words = BLOCKED[blocked]
    _inputs(folder)
    blocked_folder = _prepare(folder, "blocked", mode)
    out = blocked_folder / where.format(name=name)
    before = _listing(folder)
    blocked_folder.chmod(mode)  # _listing opened it

    result = runner(_argv(argv, folder, out), folder)

    _refused(result, str(out), words)
    assert "fitting" not in result.stderr  # refused before the work
    assert _listing(folder) == before


@pytest.mark.parametrize(
    ("argv", "name"),
    [pytest.param(argv, name, id=case) for case, argv, name in FILE_OUTPUTS],
)
def test_read_only_file_is_not_replaced_even_with_force(runner, folder, argv, name):
    _inputs(folder)
    out = _prepare(folder, name, 0o444, "kept\n")
    force = [] if argv[0] == "batch" else ["--force"]  # batch adds to its store
    before = _listing(folder)

    result = runner(_argv(argv, folder, out) + force, folder)

    _refused(result, str(out), "exists and is read-only")
    assert _listing(folder) == before


#: Seconds ahead for which ``test_fit_writes_beside_a_read_only_parameter_file_of_its_id``
#: lays the fit's files: longer than the fit (4 s as the unprivileged user, fresh cache).
FIT_WINDOW_S = 120


def test_fit_writes_beside_a_read_only_parameter_file_of_its_id(runner, folder):
    """A fit's id is its variant, data and second (``make_fit_id``); where the folder holds a
    file of that id already, the fit takes the next free one (``unused_fit_id``): a read-only
    parameter file of the id, in a folder that accepts new files, is left as it is, and the
    fit written beside it. Every id of the next ``FIT_WINDOW_S`` seconds is taken."""
    fits = _prepare(folder, "fits", 0o755)
    data = [sha256_file(RECORDING)]
    now = datetime.now(UTC)
    ids = [make_fit_id("one-axis", data, now + timedelta(seconds=s)) for s in range(FIT_WINDOW_S)]
    for fit_id in ids:
        _prepare(fits, f"{fit_id}.yaml", 0o444, "kept\n")
    before = _listing(folder)

    argv = ["fit", str(RECORDING), "--free", "b", "--no-first-stage", "--no-plots"]
    result = runner([*argv, "--no-cross-validation", "--quiet", "--out-dir", str(fits)], folder)

    assert result.returncode == 0, result.stderr
    after = _listing(folder)
    new = sorted(set(after) - set(before))
    assert len(new) == 2 and new[0].endswith("-2-report.md") and new[1].endswith("-2.yaml"), new
    assert new[1].removeprefix("fits/").removesuffix("-2.yaml") in ids
    assert {name: after[name] for name in before} == before
    assert all((fits / f"{fit_id}.yaml").stat().st_mode & 0o777 == 0o444 for fit_id in ids)


def _results(path: Path) -> Path:
    """A results store of one rig's two fits, enough for ``fleet report``."""
    return stored_fits(
        path,
        [(f"k{day}", "rig-01", datetime(2026, 1, day, tzinfo=UTC), value)
         for day, value in ((5, 13000.0), (12, 15000.0))],
    )  # fmt: skip


def test_read_only_folder_is_not_replaced_even_with_force(runner, folder):
    """``fleet report --force`` replaces its plots folder as a whole: moving the old one
    aside needs write permission on it, refused before the report is drawn instead of failing
    when it is put in place."""
    results = _results(folder / "r.parquet")
    report = _prepare(folder, "report", 0o755)
    _prepare(report, "fleet-report.md", 0o644, "kept\n")
    plots = _prepare(report, "plots", 0o755)
    _prepare(plots, "k_l.png", 0o644, "kept\n")
    before = _listing(folder)
    plots.chmod(0o555)

    argv = ["fleet", "report", str(results), "--out", str(report), "--force"]
    result = runner(argv, folder)

    _refused(result, f"--out {plots}", "exists and is read-only")
    assert _listing(folder) == before


# (name, argv with IN for the unreadable input, the input's name and content)
INPUTS = [
    ("export", ["export", "IN", "--format", "json"], "p.yaml", H8.read_text()),
    ("simulate", ["simulate", "--params", "IN", *STEP, "--out", "{d}/s.csv"], "p.yaml", None),
    ("validate", ["validate", str(ONE_AXIS), "IN", "--horizon", "0"], "r.mcap", None),
    (
        "fit",
        ["fit", "IN", "--no-plots", "--max-iterations", "1", "--out-dir", "{d}/fits"],
        "r.mcap",
        None,
    ),
    (
        "import",
        ["import", "IN", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m"]
        + ["--variant", "my-axis", "--out", "{d}/r.mcap"],
        "in.csv",
        CSV,
    ),
    ("batch", ["batch", "IN", "--results", "{d}/r.parquet"], "m.yaml", MANIFEST),
]


@pytest.mark.parametrize("unreadable", ["mode-000-file", "unreadable-folder"])
@pytest.mark.parametrize(
    ("argv", "name", "content"),
    [pytest.param(argv, name, content, id=case) for case, argv, name, content in INPUTS],
)
def test_unreadable_input_is_refused(runner, folder, unreadable, argv, name, content):
    if content is None:
        content = (H8 if name.endswith(".yaml") else RECORDING).read_bytes().decode("latin-1")
    place = folder
    if unreadable == "unreadable-folder":
        place = _prepare(folder, "private", 0o755)
    path = place / name
    path.write_bytes(content.encode("latin-1"))
    if AS_ROOT:
        os.chown(path, UNPRIVILEGED_UID, -1)
    before = _listing(folder)
    (path if unreadable == "mode-000-file" else place).chmod(0o000)

    result = runner(_argv([a.replace("IN", str(path)) for a in argv], folder, path), folder)

    _refused(result, str(path), "cannot read", "(Permission denied)")
    assert _listing(folder) == before
