"""Model and controller files loaded in a guarded way (issue 27, item 4): however a file's code
ends while it is loaded (an exception, ``sys.exit`` with any status, a ``KeyboardInterrupt``
of its own, ``os._exit``, a crash, or running past the load timeout) the command prints one
``hframe-id: error:`` line naming the file, exits 2 and writes nothing; a thread the file
leaves running does not keep the finished command alive."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from refusals import refused

ROOT = Path(__file__).resolve().parents[2]
EMPS_MODEL = ROOT / "models" / "emps_axis.py"
EMPS_PARAMS = ROOT / "models" / "emps-idim-ls.yaml"

#: Code a file runs at import, and a word the error line must carry.
ENDINGS = {
    "exit-0": ("import sys\nsys.exit(0)\n", "sys.exit(0)"),
    "exit-3": ("import sys\nsys.exit(3)\n", "sys.exit(3)"),
    "keyboard-interrupt": ("raise KeyboardInterrupt\n", "KeyboardInterrupt"),
    "exception": ("x = 1\nraise RuntimeError('boom')\n", "RuntimeError (line 2): boom"),
    "system-error": ("raise SystemError('from C')\n", "SystemError (line 1)"),
}


@pytest.mark.parametrize("ending", ENDINGS)
def test_a_model_file_ending_at_import_is_one_line(tmp_path, capsys, ending):
    code, word = ENDINGS[ending]
    model = tmp_path / "model.py"
    model.write_text(code)
    refused(["models", "--model-file", model], capsys, "model file", model, word)


@pytest.mark.parametrize("ending", ENDINGS)
def test_a_controller_file_ending_at_import_is_one_line(tmp_path, capsys, ending):
    code, word = ENDINGS[ending]
    controller = tmp_path / "controller.py"
    controller.write_text(code)
    argv = ["control", "--params", EMPS_PARAMS, "--model-file", EMPS_MODEL]
    argv += ["--controller", controller, "--reference", tmp_path / "none.mcap"]
    refused(argv, capsys, "controller file", controller, word)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["controller.py"]


def test_a_model_whose_equations_exit_is_one_line(tmp_path, capsys):
    source = EMPS_MODEL.read_text()
    assert "def equations(" in source
    shutil.copy(EMPS_PARAMS, tmp_path)  # the model's reference file, beside it
    model = tmp_path / "exits.py"
    exits = "def equations(*args):\n    raise SystemExit(0)\n\n\ndef _equations("
    model.write_text(source.replace("def equations(", exits, 1))
    refused(["models", "--model-file", model], capsys, "model file", model, "sys.exit(0)")


def test_a_bad_load_timeout_setting_is_one_line(tmp_path, capsys, monkeypatch):
    model = tmp_path / "model.py"
    model.write_text("x = 1\n")
    monkeypatch.setenv("HFRAME_ID_LOAD_TIMEOUT", "soon")
    refused(["models", "--model-file", model], capsys, "HFRAME_ID_LOAD_TIMEOUT", "soon")


def _models_under_half_a_second(model, code: str) -> subprocess.CompletedProcess:
    """``hframe-id models --model-file MODEL`` with ``code`` in it and a 0.5 s load timeout,
    in a process of its own (the timer needs the main thread, which a pytest-xdist worker may
    not run tests on); 120 s at most."""
    model.write_text(code)
    return subprocess.run(
        [sys.executable, "-m", "hframe_id", "models", "--model-file", str(model)],
        capture_output=True,
        text=True,
        env={**os.environ, "HFRAME_ID_LOAD_TIMEOUT": "0.5"},
        timeout=120,
    )


@pytest.mark.parametrize(
    "code",
    [
        "while True:\n    pass\n",
        # a wait whose interruption the file tries to swallow
        "import time\ntry:\n    time.sleep(300)\nexcept Exception:\n    pass\n",
    ],
    ids=["busy-loop", "swallowing-sleep"],
)
def test_a_file_hanging_at_import_times_out(tmp_path, code):
    model = tmp_path / "hangs.py"
    start = time.monotonic()
    done = _models_under_half_a_second(model, code)
    assert time.monotonic() - start < 60  # generous: the limit is 0.5 s plus start-up
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hframe-id: error: model file"), done.stderr
    assert str(model) in lines[0] and "still running after 0.5 s" in lines[0]


@pytest.mark.parametrize(
    "code",
    [
        "import time\nwhile True:\n    try:\n        time.sleep(300)\n    except BaseException:\n"
        "        pass\n",
        "import signal\nsignal.signal(signal.SIGALRM, signal.SIG_IGN)\nwhile True:\n    pass\n",
        "import signal, time\nsignal.setitimer(signal.ITIMER_REAL, 0)\ntime.sleep(300)\n",
    ],
    ids=["swallows-every-exception", "ignores-sigalrm", "stops-the-timer"],
)
def test_a_file_defeating_the_load_timer_still_ends(tmp_path, code):
    """A file that defeats a timer in its own process (catches its exception in a loop,
    ignores SIGALRM, stops the timer) used to hang the command for ever: the probe's child
    is killed at the limit, whatever the file does."""
    done = _models_under_half_a_second(tmp_path / "stubborn.py", code)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "still running after 0.5 s" in lines[0], done.stderr


def test_a_file_raising_generator_exit_is_one_line(tmp_path, capsys):
    """GeneratorExit is a BaseException that is neither SystemExit nor KeyboardInterrupt: it
    was a traceback."""
    model = tmp_path / "odd.py"
    model.write_text("raise GeneratorExit\n")
    refused(["models", "--model-file", model], capsys, model, "GeneratorExit (line 1)")


def _hframe_id(argv: list, timeout: float = 120) -> subprocess.CompletedProcess:
    """The command in a process of its own (``python -m hframe_id``, which owns the process
    as the console script does): a file ending the process must not end pytest's."""
    return subprocess.run(
        [sys.executable, "-m", "hframe_id", *map(str, argv)],
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def _one_error_line(done: subprocess.CompletedProcess, *named) -> str:
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hframe-id: error: "), done.stderr
    for word in named:
        assert str(word) in lines[0], lines[0]
    return lines[0]


#: Code that ends the process at import, which no handler in the process can catch, and the
#: words of its error line.
PROCESS_ENDINGS = {
    "os-exit-0": ("import os\nos._exit(0)\n", "ends the process at once (os._exit(0))"),
    "os-exit-3": ("import os\nos._exit(3)\n", "ends the process at once (os._exit(3))"),
    "killed": (
        "import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n",
        "kills the process (SIGKILL)",
    ),
}


@pytest.mark.parametrize("ending", PROCESS_ENDINGS)
def test_a_model_file_ending_the_process_at_import_is_one_line(tmp_path, ending):
    """``os._exit(0)`` at import used to end the command at once with exit status 0 and no
    output: the file is run in a forked child first, which reports whether it came back."""
    code, words = PROCESS_ENDINGS[ending]
    model = tmp_path / "model.py"
    model.write_text(code)
    done = _hframe_id(["models", "--model-file", model])
    _one_error_line(done, "model file", model, words, "while loaded")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["model.py"]


@pytest.mark.parametrize("ending", PROCESS_ENDINGS)
def test_a_controller_file_ending_the_process_at_import_is_one_line(tmp_path, ending):
    code, words = PROCESS_ENDINGS[ending]
    controller = tmp_path / "controller.py"
    controller.write_text(code)
    argv = ["control", "--params", EMPS_PARAMS, "--model-file", EMPS_MODEL]
    argv += ["--controller", controller, "--reference", tmp_path / "none.mcap"]
    _one_error_line(_hframe_id(argv), "controller file", controller, words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["controller.py"]


def test_a_model_whose_equations_end_the_process_is_one_line(tmp_path):
    """The probe covers the whole load: deriving the equations calls the file's code too."""
    shutil.copy(EMPS_PARAMS, tmp_path)
    model = tmp_path / "exits.py"
    exits = "def equations(*args):\n    import os\n    os._exit(0)\n\n\ndef _equations("
    model.write_text(EMPS_MODEL.read_text().replace("def equations(", exits, 1))
    _one_error_line(_hframe_id(["models", "--model-file", model]), model, "os._exit(0)")


def test_a_files_output_at_import_is_shown_once(tmp_path):
    """The probe's child discards its output: the file prints once, when run for real."""
    model = tmp_path / "model.py"
    model.write_text("print('hello from the model file')\nMODEL = 1\n")
    done = _hframe_id(["models", "--model-file", model])
    _one_error_line(done, model, "defines no MODEL")
    assert done.stdout.count("hello from the model file") == 1, done.stdout


#: A thread that is not a daemon and would run for 300 s.
THREAD = (
    "import threading, time\n"
    "threading.Thread(target=time.sleep, args=(300,), name='spin').start()\n"
)


def test_a_thread_left_by_a_model_file_does_not_keep_the_command_alive(tmp_path):
    """A thread the file starts (not a daemon) used to keep the process alive after the
    command, as Python waits for such threads at exit: the command ends at once with its
    status and one warning line."""
    shutil.copy(EMPS_PARAMS, tmp_path)
    model = tmp_path / "spins.py"
    model.write_text(EMPS_MODEL.read_text() + "\n" + THREAD)
    start = time.monotonic()
    done = _hframe_id(["models", "--model-file", model], timeout=100)
    assert time.monotonic() - start < 60  # generous: start-up; the thread runs 300 s
    assert done.returncode == 0, done.stderr
    assert "emps-axis" in done.stdout
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith("hframe-id: warning: model file") and str(model) in lines[0]
    assert "left a thread running ('spin')" in lines[0]


@pytest.mark.parametrize("kind", ["model", "controller"])
def test_a_thread_left_by_a_refused_file_does_not_keep_the_command_alive(tmp_path, kind):
    """A refused file: its one error line, exit 2, and no wait for its thread."""
    source = tmp_path / f"{kind}.py"
    source.write_text(THREAD)  # no MODEL, no CONTROLLER: refused after it ran
    if kind == "model":
        argv = ["models", "--model-file", source]
    else:
        argv = ["control", "--params", EMPS_PARAMS, "--model-file", EMPS_MODEL]
        argv += ["--controller", source, "--reference", tmp_path / "none.mcap"]
    start = time.monotonic()
    done = _hframe_id(argv, timeout=100)
    assert time.monotonic() - start < 60
    _one_error_line(done, f"{kind} file", source, "defines no")


def test_a_model_file_ignoring_ctrl_c_cannot_keep_the_command_running(tmp_path):
    """A model file setting SIGINT and SIGTERM to be ignored at import made a long simulation
    impossible to interrupt (only SIGKILL ended it): the command's handlers are put back
    once the file has run, and Ctrl-C ends it with exit status 130, writing nothing."""
    shutil.copy(EMPS_PARAMS, tmp_path)  # the model's reference file, beside it
    model = tmp_path / "deaf.py"
    deaf = "import signal\nfor s in (signal.SIGINT, signal.SIGTERM):\n"
    model.write_text(deaf + "    signal.signal(s, signal.SIG_IGN)\n" + EMPS_MODEL.read_text())
    argv = ["simulate", "--model-file", model, "--params", EMPS_PARAMS, "--step", "1,1"]
    argv += ["--duration", "3000", "--out", tmp_path / "s.csv"]
    process = subprocess.Popen(
        [sys.executable, "-m", "hframe_id", *map(str, argv)],
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        time.sleep(5)  # start-up, the model's equations, the simulation under way
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode == 130, err
    assert err.strip().splitlines()[-1] == "hframe-id: interrupted: SIGINT received"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["deaf.py", EMPS_PARAMS.name]


EMPS_CONTROLLER = ROOT / "models" / "emps_controller.py"
EMPS_RECORDING = ROOT / "datasets" / "real" / "emps-estimation.mcap"


@pytest.mark.parametrize(
    ("body", "words"),
    [
        ("raise SystemExit(4)", ("calls sys.exit(4) in its sample period function",)),
        ("raise KeyboardInterrupt", ("raises KeyboardInterrupt in its sample period function",)),
        ("raise ValueError('no period')", ("ValueError (line", "no period")),
        ("return 1e-12", ("--controller", "2.48e+13 samples; at most 10,000,000")),
    ],
    ids=["exit-4", "keyboard-interrupt", "exception", "too-short"],
)
@pytest.mark.parametrize("command", ["control", "validate"])
def test_a_controllers_sample_period_function_ending_is_one_line(
    tmp_path, capsys, body, words, command
):
    """The sample period function runs when the closed loop is set up, after the load: its
    sys.exit(4) ended the command with status 4 and no word, its KeyboardInterrupt read as
    the user's Ctrl-C (status 130), an exception and a period of 1e-12 s (181 TiB of time
    stamps) were tracebacks."""
    source = EMPS_CONTROLLER.read_text()
    default = "    return BENCHMARK_SAMPLE_TIMES_S.get(source, recording.sample_period_s)"
    assert default in source
    controller = tmp_path / "controller.py"
    controller.write_text(source.replace(default, f"    {body}"))
    argv = [command, "--params", EMPS_PARAMS, "--model-file", EMPS_MODEL]
    if command == "control":
        argv += ["--controller", controller, "--reference", EMPS_RECORDING]
    else:
        argv = [command, EMPS_PARAMS, EMPS_RECORDING, "--model-file", EMPS_MODEL]
        argv += ["--controller", controller, "--horizon", "0"]
    refused([*argv, "--quiet"], capsys, controller, *words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["controller.py"]


@pytest.mark.parametrize(
    ("code", "words"),
    [
        ("raise SystemExit(7)", ("calls sys.exit(7) in its law at the loop's period",)),
        ("raise KeyboardInterrupt", ("raises KeyboardInterrupt in its law at the loop's period",)),
        ("raise ValueError('period')", ("law: ValueError (line", "period")),
    ],
    ids=["exit-7", "keyboard-interrupt", "exception"],
)
def test_a_controllers_law_ending_at_the_loops_period_is_one_line(tmp_path, capsys, code, words):
    """The loader traces the law at 1 ms; the closed loop traces it again at the recording's
    period (0.99998 ms for the EMPS file), where its ending was not guarded: exit status 7
    without a word, a Ctrl-C, or a traceback."""
    source = EMPS_CONTROLLER.read_text()
    first = '    q = y["qm"]\n'
    assert first in source
    controller = tmp_path / "controller.py"
    controller.write_text(
        source.replace(first, f"    if sample_period_s != 1e-3:\n        {code}\n" + first)
    )
    argv = ["control", "--params", EMPS_PARAMS, "--model-file", EMPS_MODEL]
    argv += ["--controller", controller, "--reference", EMPS_RECORDING, "--quiet"]
    refused(argv, capsys, controller, *words)
