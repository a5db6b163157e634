"""Hostile files (issue 27, item 2): YAML and JSON are read with limits (depth, size, alias
expansion), a key given twice is refused, integers beyond int64 in a sample are refused, and
an error line shows a bounded part of any value. Each is one ``hframe-id: error:`` line naming
the file (and the field or line), exit status 2, no traceback, nothing written."""

from __future__ import annotations

import datetime as dt
import json
import os
from collections.abc import Callable
from pathlib import Path

import pandas as pd
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from refusals import refused

from hframe_id.cli import main
from hframe_id.documents import MAX_ALIAS_NODES, MAX_DEPTH
from hframe_id.errors import MAX_SHOWN

ROOT = Path(__file__).resolve().parents[2]
H8 = ROOT / "models" / "hframe-8-table4.2.yaml"
REC = ROOT / "datasets" / "4V_xmotion.mcap"
PLANT = ROOT / "datasets" / "realistic" / "plants" / "hframe-realistic.yaml"
SAMPLE_TOPIC = "/rig/sample"


def _parameter_file(path: Path, edit: Callable[[str], str]) -> Path:
    path.write_text(edit(H8.read_text()))
    return path


def _recording(
    path: Path,
    payload: Callable[[int, dict], bytes | dict],
    rig: dict | None = None,
    source: Path = REC,
) -> Path:
    """``source`` (4V_xmotion.mcap) with each sample message ``i`` replaced by ``payload(i,
    message)`` (bytes as they are, a dict as JSON) and the ``rig`` metadata updated with
    ``rig``."""
    with source.open("rb") as source, path.open("wb") as out:
        reader = make_reader(source)
        summary = reader.get_summary()
        writer = Writer(out)
        writer.start()
        schemas = {
            i: writer.register_schema(s.name, s.encoding, s.data)
            for i, s in summary.schemas.items()
        }
        channels = {
            i: writer.register_channel(
                c.topic, c.message_encoding, schemas.get(c.schema_id, 0), c.metadata
            )
            for i, c in summary.channels.items()
        }
        for record in reader.iter_metadata():
            changes = rig if record.name == "rig" and rig else {}
            writer.add_metadata(record.name, {**record.metadata, **changes})
        for attachment in reader.iter_attachments():
            writer.add_attachment(
                attachment.log_time,
                attachment.create_time,
                attachment.name,
                attachment.media_type,
                attachment.data,
            )
        k = 0
        for _, channel, message in reader.iter_messages():
            data = message.data
            if channel.topic == SAMPLE_TOPIC:
                new = payload(k, json.loads(data))
                data = new if isinstance(new, bytes) else json.dumps(new).encode()
                k += 1
            writer.add_message(channels[channel.id], message.log_time, data, message.publish_time)
        writer.finish()
    return path


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _listing(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


# -- YAML: parameter, plant and manifest files --------------------------------------------------


def test_deeply_nested_yaml(work, capsys):
    path = work / "deep.yaml"
    path.write_text("notes: " + "[" * 100_000 + "]" * 100_000 + "\n")
    refused(["params", "check", path], capsys, path, f"nested deeper than {MAX_DEPTH} levels")


def test_nesting_up_to_the_limit_is_read(work, capsys):
    nested = "[" * (MAX_DEPTH - 2) + "]" * (MAX_DEPTH - 2)
    path = _parameter_file(work / "ok.yaml", lambda t: f"provenance: {{x: {nested}}}\n{t}")
    assert main(["params", "check", str(path)]) == 0


def test_yaml_alias_bomb_is_refused_in_one_short_line(work, capsys):
    """3 kB that would expand to 9^8 strings ("billion laughs"): refused while composing,
    before any consumer expands it."""
    anchors = ['  - &a ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    for prev, name in zip("abcdefg", "bcdefgh", strict=True):
        anchors.append(f"  - &{name} [" + ", ".join([f"*{prev}"] * 9) + "]")
    bomb = "provenance:\n  x:\n" + "\n".join(anchors) + "\n"
    path = _parameter_file(
        work / "bomb.yaml",
        lambda t: bomb + t.replace("format_version: '1.0'", "format_version: *h"),
    )
    assert path.stat().st_size < 3000
    refused(["params", "check", path], capsys, path, f"more than {MAX_ALIAS_NODES:,} values")


def test_a_few_aliases_are_fine(work, capsys):
    path = _parameter_file(work / "alias.yaml", lambda t: "provenance: {a: &s [1, 2], b: *s}\n" + t)
    assert main(["params", "check", str(path)]) == 0


@pytest.mark.parametrize(
    ("edit", "key", "lines"),
    [
        (lambda t: t.replace("title:", "title: first\ntitle:", 1), "'title'", "(lines 3 and 4)"),
        (
            lambda t: t.replace("  k_l [N/m]: 13167.0", "  k_l [N/m]: 13167.0\n  k_l [N/m]: 1.0"),
            "'k_l [N/m]'",
            "given twice",
        ),
    ],
    ids=["header", "parameter"],
)
def test_a_key_given_twice_in_yaml(work, capsys, edit, key, lines):
    path = _parameter_file(work / "twice.yaml", edit)
    refused(["params", "show", path], capsys, path, key, lines)


def test_a_key_given_twice_in_a_manifest(work, capsys):
    manifest = work / "manifest.yaml"
    manifest.write_text("format_version: '1.0'\nfits: []\nfits: []\n")
    before = _listing(work)
    argv = ["batch", manifest, "--results", "r.parquet", "--workers", "1"]
    refused(argv, capsys, manifest, "'fits' given twice")
    assert _listing(work) == before


@pytest.mark.parametrize(
    ("text", "named"),
    [
        (
            f"rig,rig,time,recordings,model\na,b,2026-01-05T08:00:00+00:00,{REC},hframe-8\n",
            "column 'rig' twice",
        ),
        (
            "rig,time,recordings,model\na," + "x" * 200_000 + ",r.mcap,hframe-8\n",
            "field larger than field limit",
        ),
    ],
    ids=["column-twice", "cell-beyond-the-csv-limit"],
)
def test_a_csv_manifest_the_csv_module_cannot_take_as_it_is(work, capsys, text, named):
    """A column given twice took its last cell without a word (rig 'b' fitted); a cell of
    200 kB ended in a csv.Error traceback."""
    manifest = work / "manifest.csv"
    manifest.write_text(text)
    argv = ["batch", manifest, "--results", "r.parquet", "--workers", "1"]
    refused(argv, capsys, manifest, named)
    assert not (work / "r.parquet").exists()


def test_a_huge_value_is_echoed_shortened(work, capsys):
    huge = "9" * 100_000
    path = _parameter_file(
        work / "huge.yaml", lambda t: t.replace("k_l [N/m]: 13167.0", f"k_l [N/m]: '{huge}'")
    )
    line = refused(["params", "check", path], capsys, path, "k_l [N/m] must be a number")
    assert "..." in line and len(line) < len(str(path)) + 100 + MAX_SHOWN


def test_deeply_nested_plant_file(work, capsys):
    path = work / "plant.yaml"
    path.write_text("friction: " + "{a: " * 5_000 + "1" + "}" * 5_000 + "\n")
    argv = ["simulate", "--plant", path, "--step", "1,4", "--duration", "0.1", "--out", "s.csv"]
    refused(argv, capsys, path, "nested deeper")
    assert _listing(work) == {"plant.yaml"}


# -- JSON: the messages of a recording ----------------------------------------------------------


def test_deeply_nested_json_sample(work, capsys):
    deep = b"[" * 100_000 + b"]" * 100_000
    path = _recording(work / "deep.mcap", lambda i, m: deep if i == 5 else m)
    refused(["inspect", path], capsys, path, "/rig/sample message 5", "nested deeper")


def test_a_key_given_twice_in_a_json_sample(work, capsys):
    def twice(i: int, message: dict) -> bytes | dict:
        if i != 3:
            return message
        return json.dumps(message)[:-1].encode() + b', "u1_V": 7.0}'

    path = _recording(work / "twice.mcap", twice)
    refused(["inspect", path], capsys, path, "/rig/sample message 3", "'u1_V' given twice")


@pytest.mark.parametrize("field", ["sequence", "device_time_us"])
@pytest.mark.parametrize("offset", [2**63, 2**64, 10**30])
def test_sample_integers_beyond_int64(work, capsys, field, offset):
    path = _recording(work / "big.mcap", lambda i, m: {**m, field: m[field] + offset})
    refused(["inspect", path], capsys, path, f"sample 0: {field}", str(offset))


def test_a_number_beyond_any_float(work, capsys):
    path = _recording(work / "big.mcap", lambda i, m: {**m, "u1_V": 10**400} if i == 2 else m)
    line = refused(["inspect", path], capsys, path, "sample 2: u1_V must be a number")
    assert "..." in line


@pytest.mark.parametrize(
    "argv",
    [["params", "show", "{p}"], ["linearize", "{p}"], ["simulate", "--plant", "{p}"]],
    ids=["params-show", "linearize", "plant"],
)
def test_an_integer_beyond_any_float_in_yaml(work, capsys, argv):
    """1 and 400 zeros: refused by the loader with its line, not an OverflowError where a
    value is turned into a float."""
    source = PLANT if argv[0] == "simulate" else H8
    path = work / "big.yaml"
    path.write_text(source.read_text().replace(": 0.0194", ": 1" + "0" * 400))
    argv = [word.replace("{p}", str(path)) for word in argv]
    if argv[0] == "simulate":
        argv += ["--step", "1,4", "--duration", "0.05", "--out", "s.csv"]
    refused(argv, capsys, path, "integer of 401 digits", "line ")
    assert _listing(work) == {"big.yaml"}


@pytest.mark.parametrize(
    ("key", "value", "problem"),
    [
        ("encoder_counts_per_rev", "0", "must be a number >= 1, got 0"),
        ("laser_noise_std_m", "nan", "must be a number >= 0, got nan"),
        ("dac_min_v", "20", "must be a number below rig.dac_max_v"),
        ("encoder_counts_per_rev", "1" + "0" * 400, "must be a number >= 1, got '100"),
        ("limit_x_max_m", "1" + "0" * 400, "must be a number below rig.limit_x_max_m '100"),
        ("outputs", "phi1,phi1,x,y", "must name u1, u2 and phi1, phi2, x, y, each once"),
    ],
)
def test_rig_metadata_out_of_range(work, capsys, key, value, problem):
    """A recording's numeric rig metadata are range-checked when it is read (0 counts per
    revolution was a ZeroDivisionError traceback in the fitter, an integer beyond any float
    an OverflowError traceback in the check itself, an output named twice was shown twice by
    inspect, with the same data)."""
    path = _recording(work / "rig.mcap", lambda i, m: m, rig={key: value})
    refused(["fit", path, "--out-dir", "fits"], capsys, path, f"rig.{key}", problem)
    assert _listing(work) == {"rig.mcap"}
    refused(["inspect", path], capsys, path, f"rig.{key}", problem)


@pytest.mark.parametrize(
    ("field", "named"),
    [
        ("u1_V", "u1_V 1e+300 is outside rig.dac_min_v .. rig.dac_max_v [-10, 10]"),
        ("laser_x_m", "laser_x_m (valid) 1e+300 is outside rig.laser_min_m .. rig.laser_max_m"),
    ],
)
@pytest.mark.parametrize("command", ["inspect", "fit"])
def test_a_sample_beyond_the_rigs_ranges(work, capsys, field, named, command):
    """A command of 1e300 V (the rig clamps to its DAC range) or a valid laser reading of
    1e300 m (valid: the target inside the measuring range) was read as data: the fit ran
    for seconds with numpy overflow warnings to exit status 1."""
    path = _recording(work / "far.mcap", lambda i, m: {**m, field: 1e300} if i == 7 else m)
    argv = [command, path] + (["--quiet", "--out-dir", "fits"] if command == "fit" else [])
    refused(argv, capsys, path, "sample 7", named)
    assert _listing(work) == {"far.mcap"}


def test_a_named_pipe_without_writer_is_not_waited_on(work, capsys):
    """A FIFO given as a parameter file used to block the command forever."""
    os.mkfifo(work / "pipe.yaml")
    refused(["params", "show", work / "pipe.yaml"], capsys, "pipe.yaml")


def test_a_huge_csv_header_is_echoed_shortened(work, capsys):
    """The voltage CSV's header was echoed whole (a 100 000-column header: a 690 kB error
    line); every message is now bounded, whichever value it shows."""
    path = work / "wide.csv"
    path.write_text("time [s]," + ",".join(f"c{i}" for i in range(100_000)) + "\n")
    argv = ["simulate", "--params", H8, "--csv", path, "--out", "s.csv"]
    line = refused(argv, capsys, path, "header must be")
    assert "..." in line
    assert _listing(work) == {"wide.csv"}


@pytest.mark.parametrize(
    "argv",
    [
        ["inspect", "/dev/zero"],
        ["params", "show", "/dev/zero"],
        ["simulate", "--params", H8, "--csv", "/dev/zero", "--out", "s.csv"],
    ],
    ids=["recording", "parameter-file", "voltage-csv"],
)
def test_a_device_as_input_is_refused_before_reading(work, capsys, argv):
    """/dev/zero never ends: a recording or voltage CSV was read whole until memory ran
    out (a MemoryError traceback)."""
    refused(argv, capsys, "/dev/zero", "a device, not a file")
    assert _listing(work) == set()


def _results(path: Path, **columns) -> Path:
    """A results store of two runs of one rig, with ``columns`` replacing its columns."""
    frame = pd.DataFrame(
        {
            "key": ["k0", "k1"],
            "rig": ["rig-01", "rig-01"],
            "run_time": [dt.datetime(2026, 1, d, tzinfo=dt.UTC) for d in (5, 12)],
            "status": ["ok", "ok"],
            "k_l [N/m]": [13000.0, 15000.0],
            "k_l identified": [True, True],
            **columns,
        }
    )
    frame.to_parquet(path)
    return path


@pytest.mark.parametrize(
    ("column", "values", "problem"),
    [
        ("rig", [5, 6], "must hold text"),
        ("run_time", ["yesterday", "today"], "times with a time zone"),
        ("status", ["ok", "great"], "'great', not one of ok, failed, error"),
        ("k_l [N/m]", ["abc", "def"], "must hold numbers"),
        ("k_l [N/m]", [1.0, float("inf")], "an infinite value"),
        ("k_l identified", ["maybe", "yes"], "must hold true or false"),
    ],
)
def test_a_results_store_with_a_column_of_the_wrong_kind(work, capsys, column, values, problem):
    """A store edited or written by another program: a traceback (a value that is text) or a
    report of nonsense with exit 0 (a rig that is a number, an unknown status)."""
    path = _results(work / "r.parquet", **{column: values})
    refused(["fleet", "report", path, "--out", "rep"], capsys, path, repr(column), problem)
    assert _listing(work) == {"r.parquet"}


def test_a_results_store_without_fits(work, capsys):
    """An empty store was reported (a matplotlib warning, exit 0)."""
    path = _results(work / "r.parquet")
    pd.read_parquet(path).iloc[:0].to_parquet(path)
    refused(["fleet", "report", path, "--out", "rep"], capsys, path, "holds no fits")
    assert _listing(work) == {"r.parquet"}


def test_a_mat_file_cut_in_its_header(work, capsys):
    """scipy raises what it meets in a corrupt file (an IndexError for one cut at 100
    bytes): a traceback; any error of the reader is now the file's one line."""
    import io

    import numpy as np
    from scipy.io import savemat

    buffer = io.BytesIO()
    savemat(buffer, {"t": np.arange(10) * 1e-3, "u": np.ones(10), "x": np.zeros(10)})
    path = work / "cut.mat"
    path.write_bytes(buffer.getvalue()[:100])
    argv = ["import", path, "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m"]
    refused([*argv, "--variant", "a", "--out", "cut.mcap"], capsys, path, "not a readable")
    assert _listing(work) == {"cut.mat"}


@pytest.mark.parametrize(
    ("make", "problem"),
    [
        (lambda p: p.mkdir(), "is a directory, not a file"),
        (lambda p: p.symlink_to("/dev/null"), "is a device, pipe or socket, not a file"),
        (lambda p: None, "no such file"),
    ],
    ids=["folder", "device", "missing"],
)
def test_import_source_that_is_not_a_file(work, capsys, make, problem):
    """import said 'no such file' of a folder and of a device."""
    make(work / "log.csv")
    argv = ["import", "log.csv", "--map", "t=time:s", "--map", "u=input:V", "--map", "x=output:m"]
    refused([*argv, "--variant", "a", "--out", "i.mcap"], capsys, "log.csv", problem)
    assert not (work / "i.mcap").exists()


@pytest.mark.parametrize(
    ("block", "named"),
    [
        ("  parameters: [1, 2]\n", "uncertainty.parameters must be a mapping"),
        ("  parameters:\n    k_l [N/m]: 5\n", "uncertainty.parameters.'k_l [N/m]' must be"),
        ("  parameters:\n    k_l [N/m]: {std_error: lots}\n", ".std_error must be a number"),
    ],
    ids=["list", "entry", "std-error"],
)
def test_a_fits_uncertainty_of_the_wrong_shape(work, capsys, block, named):
    """design --params on a file whose uncertainty section had the wrong shape ended in an
    AttributeError traceback; the file is refused as it is read, by every command."""
    path = _parameter_file(work / "fit.yaml", lambda t: t + "uncertainty:\n" + block)
    refused(["params", "check", path], capsys, path, named)


def test_datasets_verify_names_each_file_once(work, capsys):
    """A copy of the datasets without its truth files and with one recording changed: the
    shared truth file was reported missing once per dataset, and the bounded error line
    ended before it named the changed recording."""
    datasets = ROOT / "datasets"
    copy = work / "copy"
    copy.mkdir()
    for path in [datasets / "manifest.yaml", *datasets.glob("*.mcap")]:
        (copy / path.name).write_bytes(path.read_bytes())
    with (copy / "6V_ymotion.mcap").open("ab") as stream:
        stream.write(b"x")
    line = refused(["datasets", "verify", "--dir", copy], capsys, "6V_ymotion.mcap: sha256 differs")
    assert line.count("hframe-8-rig.yaml: missing") == 1


@pytest.mark.parametrize(
    ("entry", "named"),
    [
        ("file: 123\n  sha256: ab", "file must be a file name, got 123"),
        ("file: {a: 1}\n  sha256: ab", "file must be a file name"),
        ("file: r.mcap\n  sha256: [1]", "sha256 must be a sha256 digest"),
        ("file: r.mcap\n  sha256: ab\n  reference:", "reference must be a file name, got None"),
    ],
    ids=["file-number", "file-mapping", "digest-list", "reference-empty"],
)
def test_datasets_verify_a_manifest_entry_of_the_wrong_type(work, capsys, entry, named):
    """A dataset's file, truth or digest that is not text ended in a TypeError traceback."""
    (work / "manifest.yaml").write_text(
        f"datasets:\n- {entry}\n  truth: truth/t.yaml\n  truth_sha256: ab\n  seed: 1\n"
    )
    refused(["datasets", "verify", "--dir", work], capsys, "manifest.yaml", "dataset 1", named)


def test_datasets_verify_a_listed_folder_is_not_a_file(work, capsys):
    (work / "sub").mkdir()
    (work / "manifest.yaml").write_text(
        "datasets:\n- {file: sub, sha256: ab, truth: sub, truth_sha256: ab, seed: 1}\n"
    )
    refused(["datasets", "verify", "--dir", work], capsys, "sub: not a file")


def test_a_zero_filled_recording_is_refused_at_once(work, capsys):
    """The MCAP magic and then 200 MB of zeros (sparse): walked as 9-byte records for over
    two minutes; a record of opcode 0 ends the readable part at once."""
    path = work / "zeros.mcap"
    with path.open("wb") as stream:
        stream.write(REC.read_bytes()[:8])
        stream.truncate(200 * 2**20)
    refused(["inspect", path], capsys, path, "byte 8", "opcode 0x00")


def test_a_recording_followed_by_zeros_is_salvaged(work, capsys):
    """What comes before the zeros (a writer's preallocated file) is recovered."""
    data = REC.read_bytes()
    end = 8  # after the magic: whole records (opcode, length, body) up to 40 kB
    while end < 40_000:
        end += 9 + int.from_bytes(data[end + 1 : end + 9], "little")
    path = work / "padded.mcap"
    path.write_bytes(data[:end] + bytes(1_000_000))
    assert main(["inspect", str(path)]) == 0
    shown_to_user = capsys.readouterr()
    assert "opcode 0x00" in shown_to_user.out + shown_to_user.err
