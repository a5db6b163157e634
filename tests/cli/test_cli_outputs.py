"""The output guard (issue 27, item 1): every file and folder a command writes is checked
before any work (kind, existence without ``--force``, parent, writability), and the outputs of
one command are put in place together or not at all. Each refusal is one ``hframe-id: error:``
line naming the option and the path, exit status 2, no traceback and nothing left behind."""

from __future__ import annotations

import datetime as dt
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from fit_rows import stored_fits
from refusals import refused

from hframe_id.cli import main

ROOT = Path(__file__).resolve().parents[2]
H8 = ROOT / "models" / "hframe-8-table4.2.yaml"
REC = ROOT / "datasets" / "4V_xmotion.mcap"
STEP = ("--step", "1,4", "--duration", "0.05")


def _listing(folder: Path) -> dict[str, bytes | None]:
    """Every path under ``folder`` (hidden temporaries too) with a file's content."""
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
        for p in folder.rglob("*")
    }


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    """A folder holding a plain file ``afile`` (to put outputs on and under), as the cwd."""
    (tmp_path / "afile").write_text("not a folder\n")
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.fixture(scope="module")
def results(tmp_path_factory) -> Path:
    """A results store of two rigs, two runs each (enough for a report)."""
    path = tmp_path_factory.mktemp("store") / "results.parquet"
    rows = [
        (f"k{i}", f"rig-{1 + i // 2:02d}", dt.datetime(2026, 1, 5 + 7 * (i % 2), tzinfo=dt.UTC),
         13000.0 * (1 + 0.2 * (i % 2) * (i < 2)))
        for i in range(4)
    ]  # fmt: skip
    return stored_fits(path, rows)


#: A folder output on a file, under a file, and where nothing can be created.
BAD_FOLDERS = (("afile", "exists and is not a directory"), ("afile/sub", "afile is not a"),
               ("/proc/nope", "cannot write in /proc"))  # fmt: skip


@pytest.mark.parametrize(("out", "problem"), BAD_FOLDERS)
def test_fleet_report_out(results, work, capsys, out, problem):
    before = _listing(work)
    refused(["fleet", "report", results, "--out", out], capsys, "--out", out, problem)
    assert _listing(work) == before


@pytest.mark.parametrize(("out", "problem"), BAD_FOLDERS)
def test_fleet_make_out(work, capsys, out, problem):
    before = _listing(work)
    refused(["fleet", "make", "--rigs", "1", "--weeks", "2", "--out", out], capsys, out, problem)
    assert _listing(work) == before


def test_fleet_make_refuses_a_folder_with_content_and_leaves_nothing_on_failure(work, capsys):
    (work / "full").mkdir()
    (work / "full" / "x").write_text("x")
    refused(["fleet", "make", "--rigs", "1", "--weeks", "2", "--out", "full"], capsys, "not empty")
    before = _listing(work)
    refused(
        ["fleet", "make", "--rigs", "0", "--weeks", "2", "--out", "new/fleet"], capsys, "--rigs"
    )
    assert _listing(work) == before  # neither new/ nor a hidden staging folder


def test_fleet_report_replaces_an_earlier_report_only_with_force(results, work, capsys):
    out = work / "report"
    assert main(["fleet", "report", str(results), "--out", str(out)]) == 0
    page = (out / "fleet-report.md").read_text()
    assert "![k_l](plots/k_l.png)" in page and (out / "plots" / "k_l.png").is_file()
    before = _listing(work)
    refused(
        ["fleet", "report", results, "--out", out, "--json"], capsys, "fleet-report.md", "--force"
    )
    assert _listing(work) == before
    assert main(["fleet", "report", str(results), "--out", str(out), "--force"]) == 0
    assert sorted(_listing(out)) == ["fleet-report.md", "plots", "plots/k_l.png"]


def test_simulate_plot_onto_a_folder_writes_no_csv(work, capsys):
    (work / "plots" / "open_loop.png").mkdir(parents=True)
    before = _listing(work)
    argv = ["simulate", "--params", H8, *STEP, "--out", "s.csv", "--plot", "plots"]
    refused(argv, capsys, "--plot", "open_loop.png", "is a directory")
    assert _listing(work) == before


def test_simulate_mcap_refused_before_the_csv(work, capsys):
    (work / "run.mcap").write_bytes(b"keep")
    before = _listing(work)
    for mcap, problem in (("run.mcap", "exists already"), ("run.txt", ".mcap file name")):
        argv = ["simulate", "--params", H8, *STEP, "--out", "s.csv", "--mcap", mcap]
        refused(argv, capsys, mcap, problem)
        assert _listing(work) == before


def test_simulate_writes_its_outputs_together(work, capsys):
    argv = ["simulate", "--params", str(H8), *STEP, "--out", "s.csv", "--mcap", "r.mcap",
            "--plot", "plots"]  # fmt: skip
    assert main(argv) == 0
    assert sorted(_listing(work)) == ["afile", "plots", "plots/open_loop.png", "r.mcap", "s.csv"]
    before = _listing(work)
    refused(argv, capsys, "--out s.csv: exists already; pass --force to replace it")
    assert _listing(work) == before
    assert main([*argv, "--force"]) == 0
    assert sorted(_listing(work)) == sorted(before)  # replaced, no temporary left


def test_validate_plot_writes_both_pngs_or_none(work, capsys):
    blocker = work / "plots" / "4V_xmotion-resid-hframe-8-table4.2.png"
    blocker.mkdir(parents=True)
    before = _listing(work)
    argv = ["validate", H8, REC, "--horizon", "0", "--plot", "plots"]
    refused(argv, capsys, "--plot", blocker.relative_to(work), "is a directory")
    assert _listing(work) == before
    blocker.rmdir()
    assert main([str(w) for w in argv]) == 0
    capsys.readouterr()
    written = sorted(_listing(work / "plots"))
    assert written == ["4V_xmotion-compare.png", blocker.name]
    refused(argv, capsys, "4V_xmotion-compare.png", "--force")


@pytest.mark.parametrize(
    ("argv", "existing"),
    [
        (["inspect", REC, "--plot", "keep.png"], "keep.png"),
        (["control", "--params", H8, "--kp", "150", "--csv", "keep.csv"], "keep.csv"),
        (["control", "--params", H8, "--kp", "150", "--plot", "p"], "p/fig5_9_path.png"),
        (["reproduce", "--out", "rep", "--params", H8], "rep/report.md"),
    ],
    ids=["inspect-plot", "control-csv", "control-plot", "reproduce-out"],
)
def test_an_existing_output_needs_force(work, capsys, argv, existing):
    (work / existing).parent.mkdir(exist_ok=True)
    (work / existing).write_text("precious\n")
    before = _listing(work)
    refused(argv, capsys, existing, "exists already; pass --force to replace it")
    assert _listing(work) == before


def test_inspect_plot_force_replaces_the_png(work, capsys):
    (work / "keep.png").write_text("precious\n")
    assert main(["inspect", str(REC), "--plot", "keep.png", "--force"]) == 0
    assert (work / "keep.png").read_bytes().startswith(b"\x89PNG")
    assert sorted(_listing(work)) == ["afile", "keep.png"]


@pytest.mark.parametrize(
    ("option", "value", "problem"),
    [
        ("--out-dir", "/proc/nope", "cannot write in /proc"),
        ("--out-dir", "afile", "exists and is not a directory"),
        ("--results", "afile/r.parquet", "afile is not a directory"),
    ],
)
def test_batch_outputs_checked_before_any_fit(work, capsys, option, value, problem):
    manifest = work / "manifest.yaml"
    manifest.write_text("format_version: '1.0'\nfits: []\n")
    argv = ["batch", manifest, "--results", "r.parquet", "--workers", "1", option, value]
    before = _listing(work)
    refused(argv, capsys, option, value, problem)
    assert _listing(work) == before


@pytest.mark.parametrize(
    "argv",
    [
        ["export", H8, "--format", "json", "--out", "pipe", "--force"],
        ["simulate", "--params", H8, *STEP, "--out", "pipe", "--force"],
        ["control", "--params", H8, "--kp", "150", "--csv", "pipe", "--force"],
    ],
    ids=["export", "simulate", "control"],
)
def test_force_never_replaces_a_device_or_pipe(work, capsys, argv):
    """An output is put in place by a rename: onto a pipe or a device (as root, --out
    /dev/null) it would replace the node itself."""
    os.mkfifo(work / "pipe")
    refused(argv, capsys, "pipe", "device, pipe or socket")
    assert stat.S_ISFIFO((work / "pipe").lstat().st_mode)
    assert sorted(_listing(work)) == ["afile", "pipe"]


@pytest.mark.parametrize(
    "argv",
    [
        ["record", "--rig", "sim", "--params", H8, "--fast", "--quiet", "--out", "new/"],
        ["simulate", "--params", H8, *STEP, "--out", "new/"],
        ["export", H8, "--format", "json", "--out", ""],
    ],
    ids=["record-slash", "simulate-slash", "export-empty"],
)
def test_an_output_file_needs_a_file_name(work, capsys, argv):
    """'new/' names a folder (Path would drop the slash and write a file 'new'); an empty
    --out is no file (export used to print to standard output)."""
    refused(argv, capsys, "a file's path is needed")
    assert sorted(_listing(work)) == ["afile"]


def test_inspect_plot_is_a_png_whatever_its_name(work, capsys):
    assert main(["inspect", str(REC), "--plot", "figure.out"]) == 0
    assert (work / "figure.out").read_bytes().startswith(b"\x89PNG")


def test_standard_output_on_a_full_disk_is_one_line(tmp_path):
    """Printing to a full device: one error line and exit status 2, not a traceback (nor
    Python's complaint at exit)."""
    with open("/dev/full", "wb") as full:
        done = subprocess.run(
            [sys.executable, "-m", "hframe_id", "models"],
            stdout=full,
            stderr=subprocess.PIPE,
            text=True,
            timeout=60,
        )
    assert done.returncode == 2
    assert done.stderr == "hframe-id: error: standard output: No space left on device\n"


@pytest.mark.parametrize("argv", [["models"], ["inspect", str(REC), "--json"]])
def test_a_closed_standard_output_is_one_line(argv):
    """Started with standard output closed (``hframe-id models >&-``): an AttributeError
    traceback at the final flush, the output dropped without a word."""
    done = subprocess.run(
        [sys.executable, "-m", "hframe_id", *argv],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        timeout=60,
        preexec_fn=lambda: os.close(1),
    )
    assert done.returncode == 2, done.stderr
    assert done.stderr == "hframe-id: error: standard output: Bad file descriptor\n"


def test_a_path_too_long_for_the_file_system_is_one_line(work, capsys):
    """A 300-character file name: the output guard's checks raise ENAMETOOLONG, which was a
    traceback; the line shows the path shortened and the problem."""
    name = "a" * 300
    refused(["export", H8, "--format", "json", "--out", name], capsys, "File name too long")
    assert sorted(_listing(work)) == ["afile"]


def test_reproduce_runs_outside_the_checkout(work, capsys):
    """Its default --params was models/... relative to the working directory: outside the
    checkout, 'no such parameter file'."""
    assert main(["reproduce", "--no-sensitivity", "--out", "rep"]) == 0
    assert (work / "rep" / "report.md").is_file()


@pytest.mark.parametrize(
    ("fault", "named"),
    [
        ("writer", "hframe-id: error: run.mcap.partial: writing failed"),
        ("close", "hframe-id: error: run.mcap: cannot write"),
    ],
)
def test_import_on_a_full_disk_names_its_output(work, capsys, monkeypatch, fault, named):
    """A write that fails (a full disk) named the hidden staging file
    (.run.mcap.x1y2.tmp/run.mcap.partial) instead of the output, and one found when the
    file was closed (an OSError without a file name) escaped the importer unnamed."""
    from hframe_id.errors import LogFormatError
    from hframe_id.recordings import importer

    def failing(path):
        if fault == "close":
            raise OSError(28, "No space left on device")
        raise LogFormatError(f"{path}.partial: writing failed (No space left on device)")

    monkeypatch.setattr(importer, "read_recording", failing)
    (work / "log.csv").write_text("t,u,x\n0,1,0\n0.001,1,0\n")
    argv = ["import", "log.csv", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m"]
    line = refused([*argv, "--variant", "a", "--out", "run.mcap"], capsys, "No space left")
    assert named in line
    assert sorted(_listing(work)) == ["afile", "log.csv"]


@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["reduce", "in.yaml", "--out", "in.yaml", "--force"], "in.yaml"),
        (["export", "in.yaml", "--format", "json", "--out=in.yaml", "--force"], "in.yaml"),
        (["simulate", "--params", "in.yaml", *STEP, "--out", "link.csv", "--force"], "link.csv"),
        (["import", "in.csv", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m",
          "--variant", "a", "--out", "link.mcap", "--force"], "link.mcap"),
    ],
    ids=["reduce", "export", "simulate-through-a-link", "import-through-a-link"],
)  # fmt: skip
def test_an_input_is_never_replaced_by_an_output(work, capsys, argv, name):
    """``reduce F --out F --force`` replaced the parameter file it read (so did export,
    simulate and import): an output the command line also names as an input is refused,
    even with ``--force`` and through a symbolic link."""
    source = ROOT / "models" / ("hframe-20-table3.1.yaml" if argv[0] == "reduce" else H8.name)
    (work / "in.yaml").write_bytes(source.read_bytes())
    (work / "in.csv").write_text("t,u,x\n0,1,0\n0.001,1,0\n")
    (work / "link.csv").symlink_to("in.yaml")
    (work / "link.mcap").symlink_to("in.csv")
    before = _listing(work)
    refused(argv, capsys, name, "is also an input of this command")
    assert _listing(work) == before


@pytest.mark.parametrize(
    ("argv", "named"),
    [
        (["control", "--params", H8, "--kp", "150", "--csv", "p", "--plot", "p"], "--plot p"),
        (["simulate", "--params", H8, *STEP, "--out", "s.csv", "--plot", "s.csv"], "--plot"),
    ],
    ids=["control", "simulate"],
)
def test_two_outputs_on_one_path_are_refused_before_any_work(work, capsys, argv, named):
    """``control --csv p --plot p`` ran the closed loop, then failed writing p/fig5_9_path.png
    under the file p: two outputs of one command on one path are refused at once."""
    before = _listing(work)
    refused(argv, capsys, named, "is written there too")
    assert _listing(work) == before


@pytest.mark.parametrize(
    "argv",
    [
        ["record", "--rig", "sim", "--params", H8, "--fast", "--quiet", "--out", "run.csv"],
        ["import", "log.csv", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m",
         "--variant", "a", "--out", "run.txt"],
    ],
    ids=["record", "import"],
)  # fmt: skip
def test_a_recording_is_written_under_an_mcap_name(work, capsys, argv):
    """record --out run.csv wrote a recording that --csv run.csv then could not read; the
    recording's name ends in .mcap, as simulate --mcap already asked."""
    (work / "log.csv").write_text("t,u,x\n0,1,0\n0.001,1,0\n")
    before = _listing(work)
    refused(argv, capsys, "--out needs a .mcap file name", argv[-1])
    assert _listing(work) == before


@pytest.mark.parametrize(
    "argv",
    [
        ["validate", H8, REC, "--plot", ""],
        ["fit", REC, "--out-dir", " "],
        ["fleet", "make", "--rigs", "1", "--weeks", "2", "--out", ""],
        ["reproduce", "--out", ""],
        ["datasets", "make", "--only", "4V_xmotion.mcap", "--out", ""],
    ],
    ids=["validate-plot", "fit-out-dir", "fleet-make", "reproduce", "datasets-make"],
)
def test_an_empty_folder_path_is_refused(work, capsys, argv):
    """validate --plot '' drew nothing without a word, datasets make --out '' wrote into
    ./datasets, fleet make --out '' failed after its work leaving a hidden folder."""
    before = _listing(work)
    refused(argv, capsys, argv[argv.index(argv[-1]) - 1], "a folder's path is needed")
    assert _listing(work) == before


def test_fleet_make_into_the_current_folder_is_refused(work, capsys, monkeypatch):
    """fleet make --out . (an empty current folder) recorded the fleet, then could not put
    its folder in place of '.' and left a hidden folder behind."""
    (work / "empty").mkdir()
    monkeypatch.chdir(work / "empty")
    refused(["fleet", "make", "--rigs", "1", "--weeks", "2", "--out", "."], capsys, "--out .")
    assert list((work / "empty").iterdir()) == []
