"""Bad input to every command that reads or writes a file: one clean error line, exit 2, no
traceback and nothing written (empty, binary, non-UTF-8, truncated, oversized, wrong schema,
wrong variant, NaN, unknown keys, unwritable outputs)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hframe_id.cli import main

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"
DATASETS = ROOT / "datasets"
H8 = MODELS / "hframe-8-table4.2.yaml"
REC = DATASETS / "4V_xmotion.mcap"
CSV_HEADER = "time [s],u1 [V],u2 [V]\n"


def _wrong_schema_mcap(path: Path) -> None:
    """A valid MCAP file whose one channel is not the log format's."""
    from mcap.writer import Writer

    with path.open("wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema("foo.Bar", "jsonschema", b"{}")
        channel = writer.register_channel("/foo", "json", schema)
        writer.add_message(channel, 0, b'{"a": 1}', 0)
        writer.finish()


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """The bad files, in a folder of their own (checked to stay unchanged)."""
    d = tmp_path_factory.mktemp("inputs")
    binary = bytes(range(256)) * 64
    text = H8.read_text()
    for suffix in ("yaml", "mcap", "csv", "py", "mat"):
        (d / f"empty.{suffix}").write_bytes(b"")
        (d / f"binary.{suffix}").write_bytes(binary)
    (d / "latin1.yaml").write_bytes(text.replace("nonlinear", "non-linéaire").encode("latin-1"))
    (d / "notyaml.yaml").write_text("model: [hframe-8\nparameters: {")
    (d / "list.yaml").write_text("- 1\n- 2\n")
    (d / "unknown.yaml").write_text(text.replace("  r [m]:", "  r_pulley [m]: 0.02\n  r [m]:"))
    (d / "nan.yaml").write_text(text.replace("k_l [N/m]: 13167.0", "k_l [N/m]: .nan"))
    (d / "missing_key.yaml").write_text(text.replace("  k_l [N/m]: 13167.0\n", ""))
    (d / "old_version.yaml").write_text(
        text.replace("format_version: '1.0'", "format_version: '9'")
    )
    with (d / "huge.yaml").open("wb") as stream:  # sparse: 200 MB on paper, no disk used
        stream.truncate(200 * 2**20)
    data = REC.read_bytes()
    (d / "tiny.mcap").write_bytes(data[:30])
    (d / "text.mcap").write_text("time,u1\n0,1\n")
    _wrong_schema_mcap(d / "schema.mcap")
    (d / "nan.csv").write_text(CSV_HEADER + "0,nan,0\n0.1,1,1\n")
    (d / "header.csv").write_text("t,volts\n0,1\n")
    (d / "good.csv").write_text(CSV_HEADER + "0,1,0\n0.001,1,1e-6\n0.002,1,2e-6\n")
    with (d / "huge.csv").open("wb") as stream:  # sparse, all NUL bytes
        stream.truncate(200 * 2**20)
    (d / "longseq.csv").write_text(CSV_HEADER + "0,1,1\n1e9,0,0\n")  # 10^12 samples
    (d / "longfield.csv").write_text(CSV_HEADER + "0," + "1" * 200_000 + ",0\n")
    (d / "latin1.csv").write_bytes(("time [s],u1 [V],u2 [V] é\n0,1,1\n").encode("latin-1"))
    (d / "syntax.py").write_text("def broken(:\n")
    (d / "noop.py").write_text("x = 1\n")
    (d / "adir.yaml").mkdir()
    for name, manifest in (
        ("binary", binary),
        ("notyaml", b"a: [1\n"),
        ("entry", b"datasets: [1]\n"),
    ):
        (d / f"manifest_{name}").mkdir()
        (d / f"manifest_{name}" / "manifest.yaml").write_bytes(manifest)
    return d


#: Parameter-file kinds and the commands that read one ({p}: the file).
BAD_PARAMS = (
    "empty.yaml", "binary.yaml", "latin1.yaml", "notyaml.yaml", "list.yaml", "unknown.yaml",
    "nan.yaml", "missing_key.yaml", "old_version.yaml", "huge.yaml", "adir.yaml", "absent.yaml",
)  # fmt: skip
PARAM_READERS = (
    ("params", "show", "{p}"),
    ("params", "check", "{p}"),
    ("linearize", "{p}"),
    ("export", "{p}", "--format", "json"),
    ("reduce", "{p}", "--out", "{out}/r.yaml"),
    ("simulate", "--params", "{p}", "--step", "1,4", "--duration", "0.1", "--out", "{out}/s.csv"),
    ("control", "--params", "{p}", "--kp", "150"),
    ("record", "--rig", "sim", "--params", "{p}", "--v1", "1", "--v2", "1", "--duration",
     "0.05", "--fast", "--out", "{out}/r.mcap"),
    ("fit", str(REC), "--initial", "{p}", "--out-dir", "{out}/fits"),
    ("validate", "{p}", str(REC)),
    ("reproduce", "--out", "{out}/rep", "--params", "{p}"),
    ("simulate", "--plant", "{p}", "--step", "1,4", "--duration", "0.1", "--out", "{out}/p.csv"),
)  # fmt: skip
#: Recording kinds and the commands that read one ({r}).
BAD_RECORDINGS = (
    "empty.mcap",
    "binary.mcap",
    "tiny.mcap",
    "text.mcap",
    "schema.mcap",
    "absent.mcap",
)
RECORDING_READERS = (
    ("inspect", "{r}"),
    ("fit", "{r}", "--out-dir", "{out}/fits"),
    ("validate", str(H8), "{r}"),
    ("simulate", "--params", str(H8), "--recording", "{r}", "--out", "{out}/s.csv"),
)
#: Voltage-sequence CSV kinds and the commands that read one ({c}).
IMPORT_MAP = ("--map", "time [s]=time:s", "--map", "u1 [V]=input:V:u1",
              "--map", "u2 [V]=output:m:x", "--variant", "a")  # fmt: skip
MAT_MAP = ("--map", "t=time:s", "--map", "u=input:V", "--map", "y=output:m", "--variant", "a")
BAD_CSVS = (
    "empty.csv", "binary.csv", "nan.csv", "header.csv", "latin1.csv", "huge.csv", "longfield.csv"
)  # fmt: skip
CSV_READERS = (
    ("simulate", "--params", str(H8), "--csv", "{c}", "--out", "{out}/s.csv"),
    ("record", "--rig", "sim", "--params", str(H8), "--protocol", "csv", "--csv", "{c}",
     "--fast", "--out", "{out}/r.mcap"),
    ("import", "{c}", *IMPORT_MAP, "--out", "{out}/i.mcap"),
)  # fmt: skip
OTHER = {
    # model files
    "model-file-empty": ("models", "--model-file", "{in}/empty.py"),
    "model-file-binary": ("models", "--model-file", "{in}/binary.py"),
    "model-file-syntax": ("models", "--model-file", "{in}/syntax.py"),
    "model-file-declares-nothing": ("models", "--model-file", "{in}/noop.py"),
    "import-mat-empty": ("import", "{in}/empty.mat", *MAT_MAP, "--out", "{out}/i.mcap"),
    "import-mat-binary": ("import", "{in}/binary.mat", *MAT_MAP, "--out", "{out}/i.mcap"),
    # wrong variant
    "simulate-wrong-variant": ("simulate", "--params", str(H8), "--variant", "one-axis",
                               "--step", "1,4", "--duration", "0.1", "--out", "{out}/s.csv"),
    "control-one-axis": ("control", "--params", str(MODELS / "one-axis-table2.3.yaml"),
                         "--kp", "150"),
    "fit-model-one-axis-on-hframe": ("fit", str(REC), "--model", "one-axis",
                                     "--out-dir", "{out}/fits"),
    "fit-initial-other-variant": ("fit", str(REC), "--initial",
                                  str(MODELS / "one-axis-table2.3.yaml"), "--out-dir", "{out}/f"),
    "validate-one-axis-on-hframe": ("validate", str(MODELS / "one-axis-table2.3.yaml"), str(REC)),
    "reduce-not-hframe-20": ("reduce", str(H8), "--out", "{out}/r.yaml"),
    "linearize-unknown-input": ("linearize", str(H8), "--input", "u9"),
    "export-unknown-format": ("export", str(H8), "--format", "excel"),
    "datasets-verify-absent": ("datasets", "verify", "--dir", "{in}/absent"),
    "datasets-verify-empty-dir": ("datasets", "verify", "--dir", "{in}/adir.yaml"),
    "datasets-verify-binary-manifest": ("datasets", "verify", "--dir", "{in}/manifest_binary"),
    "datasets-verify-manifest-not-yaml": ("datasets", "verify", "--dir", "{in}/manifest_notyaml"),
    "datasets-verify-manifest-entry": ("datasets", "verify", "--dir", "{in}/manifest_entry"),
    # runs too long to hold in memory
    "simulate-duration-1e9": ("simulate", "--params", str(H8), "--step", "1,4", "--duration",
                              "1e9", "--out", "{out}/s.csv"),
    "record-duration-1e9": ("record", "--rig", "sim", "--params", str(H8), "--v1", "1", "--v2",
                            "1", "--duration", "1e9", "--fast", "--out", "{out}/r.mcap"),
    "record-multisine-period-1e9": ("record", "--rig", "sim", "--params", str(H8), "--protocol",
                                    "multisine", "--period", "1e9", "--fast", "--out",
                                    "{out}/r.mcap"),
    "simulate-csv-longseq": ("simulate", "--params", str(H8), "--csv", "{in}/longseq.csv",
                             "--out", "{out}/s.csv"),
    "record-csv-longseq": ("record", "--rig", "sim", "--params", str(H8), "--protocol", "csv",
                           "--csv", "{in}/longseq.csv", "--fast", "--out", "{out}/r.mcap"),
    "control-settle-1e9": ("control", "--params", str(H8), "--kp", "150", "--settle", "1e9"),
    "control-v-max-1e-9": ("control", "--params", str(H8), "--kp", "150", "--v-max", "1e-9"),
    # unwritable outputs
    "simulate-out-proc": ("simulate", "--params", str(H8), "--step", "1,4", "--duration", "0.05",
                          "--out", "/proc/nope.csv"),
    "simulate-mcap-proc": ("simulate", "--params", str(H8), "--step", "1,4", "--duration",
                           "0.05", "--out", "{out}/s.csv", "--mcap", "/proc/nope.mcap"),
    "simulate-plot-proc": ("simulate", "--params", str(H8), "--step", "1,4", "--duration",
                           "0.05", "--out", "{out}/s.csv", "--plot", "/proc/nope"),
    "simulate-out-under-file": ("simulate", "--params", str(H8), "--step", "1,4", "--duration",
                                "0.05", "--out", str(H8) + "/s.csv"),
    "inspect-plot-proc": ("inspect", str(REC), "--plot", "/proc/nope.png"),
    "inspect-plot-under-file": ("inspect", str(REC), "--plot", str(H8) + "/p.png"),
    "reproduce-out-proc": ("reproduce", "--out", "/proc/nope"),
    "export-out-proc": ("export", str(H8), "--format", "json", "--out", "/proc/nope.json"),
    "export-matlab-out-proc": ("export", str(H8), "--format", "matlab", "--out", "/proc/n.mat"),
    "reduce-out-proc": ("reduce", str(MODELS / "hframe-20-table3.1.yaml"), "--out",
                        "/proc/nope.yaml"),
    "record-out-proc": ("record", "--rig", "sim", "--params", str(H8), "--v1", "1", "--v2", "1",
                        "--duration", "0.05", "--fast", "--out", "/proc/nope.mcap"),
    "import-out-proc": ("import", "{in}/good.csv", *IMPORT_MAP, "--out", "/proc/nope.mcap"),
    "control-csv-proc": ("control", "--params", str(H8), "--kp", "150", "--csv",
                         "/proc/nope.csv"),
    "control-plot-proc": ("control", "--params", str(H8), "--kp", "150", "--plot", "/proc/nope"),
    "fit-out-dir-proc": ("fit", str(REC), "--out-dir", "/proc/nope"),
    "validate-plot-proc": ("validate", str(H8), str(REC), "--plot", "/proc/nope"),
    "datasets-make-proc": ("datasets", "make", "--out", "/proc/nope", "--only",
                           "4V_xmotion.mcap"),
}  # fmt: skip


def _cases() -> dict[str, tuple[str, ...]]:
    cases = dict(OTHER)
    for kinds, readers, key in (
        (BAD_PARAMS, PARAM_READERS, "{p}"),
        (BAD_RECORDINGS, RECORDING_READERS, "{r}"),
        (BAD_CSVS, CSV_READERS, "{c}"),
    ):
        for reader in readers:
            for kind in kinds:
                before = reader[reader.index(key) - 1].removeprefix("--")
                name = reader[0] if before == reader[0] else f"{reader[0]}-{before}"
                cases[f"{name}-{kind}"] = tuple(w.replace(key, f"{{in}}/{kind}") for w in reader)
    return cases


CASES = _cases()


def _listing(folder: Path) -> set[tuple[str, int]]:
    return {(str(p.relative_to(folder)), p.stat().st_size) for p in folder.rglob("*")}


def test_battery_is_large_enough():
    assert len(CASES) >= 60


@pytest.mark.parametrize("argv", CASES.values(), ids=CASES.keys())
def test_bad_input_is_one_clean_error(argv, inputs, tmp_path, monkeypatch, capsys):
    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.chdir(tmp_path)
    words = [w.replace("{in}", str(inputs)).replace("{out}", str(out)) for w in argv]
    before, inputs_before = _listing(tmp_path), _listing(inputs)
    try:
        code = main(words)
    except SystemExit as exit_:  # argparse's usage errors
        code = exit_.code
    err = capsys.readouterr().err
    assert code == 2, err
    lines = err.strip().splitlines()
    assert "Traceback" not in err
    assert lines and lines[-1].startswith("hframe-id") and "error:" in lines[-1], err
    assert all(len(line) < 400 for line in lines)
    assert _listing(tmp_path) == before
    assert _listing(inputs) == inputs_before
    assert not any(p.exists() for p in (Path("/proc/nope.csv"), Path("/proc/nope")))
