"""The loader's probe (``hframe_id.models.user.load_guarded``), from the library: a model
file that ends the process or hangs at import is a ``ModelError`` naming the file, and the
threads a file leaves running are noted with the file."""

from __future__ import annotations

import os
import threading

import pytest

from hframe_id.errors import ModelError
from hframe_id.models import load_model_file
from hframe_id.models.user import threads_left_running

#: The probe forks from the main thread only; elsewhere a file's os._exit would end the test
#: process (a pytest-xdist worker may run tests on another thread).
probing = pytest.mark.skipif(
    not (hasattr(os, "fork") and threading.current_thread() is threading.main_thread()),
    reason="the load probe runs on the main thread of a POSIX process only",
)


@probing
def test_os_exit_at_import_is_a_model_error_and_this_process_lives_on(tmp_path):
    model = tmp_path / "model.py"
    model.write_text("import os\nos._exit(0)\n")
    with pytest.raises(ModelError) as err:
        load_model_file(model)
    assert str(err.value) == (
        f"model file {model}: ends the process at once (os._exit(0)) while loaded"
    )


@probing
def test_a_hang_at_import_is_a_model_error_at_the_limit(tmp_path, monkeypatch):
    monkeypatch.setenv("HFRAME_ID_LOAD_TIMEOUT", "0.3")
    model = tmp_path / "model.py"
    model.write_text(
        "import signal\nsignal.signal(signal.SIGALRM, signal.SIG_IGN)\nwhile 1:\n pass\n"
    )
    with pytest.raises(ModelError, match=r"still running after 0\.3 s"):
        load_model_file(model)


def test_a_thread_left_running_is_noted_with_its_file(tmp_path):
    stop = tmp_path / "stop"
    model = tmp_path / "model.py"
    model.write_text(
        "import os, threading, time\n"
        "def wait():\n"
        f"    while not os.path.exists({str(stop)!r}):\n"
        "        time.sleep(0.01)\n"
        "threading.Thread(target=wait, name='waiter').start()\n"
    )
    with pytest.raises(ModelError, match="defines no MODEL"):
        load_model_file(model)
    left = [(file, t) for file, t in threads_left_running() if t.name == "waiter"]
    assert [file for file, _ in left] == [f"model file {model}"]
    stop.touch()
    left[0][1].join(10)
    assert not any(t.name == "waiter" for _, t in threads_left_running())


def test_no_process_to_spare_loads_the_file_here(tmp_path, monkeypatch):
    """A fork that fails (EAGAIN: no process to spare) leaves the load to this process."""

    def no_fork():
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    model = tmp_path / "model.py"
    model.write_text("MODEL = 1\n")
    with pytest.raises(ModelError, match="defines no MODEL"):
        load_model_file(model)
