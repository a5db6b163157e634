"""The one native-code path (``hframe_id.native``): cache keys, ``hframe-id cache``, the fitter's
compiled window loop against CasADi, and everything still working without a compiler."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from hframe_id import native
from hframe_id.cli import main

needs_compiler = pytest.mark.skipif(not native.compiler_available(), reason="needs a C compiler")
MODELS = Path(__file__).resolve().parents[1] / "models"


@pytest.fixture
def cache(monkeypatch, tmp_path) -> Path:
    """An empty cache folder for this test (``HFRAME_ID_CACHE``)."""
    monkeypatch.setenv("HFRAME_ID_CACHE", str(tmp_path))
    return tmp_path


def _halve() -> ca.Function:
    x = ca.SX.sym("x")
    return ca.Function("halve_native", [x], [x / 2])


def test_cache_key_covers_flags_compiler_and_casadi(monkeypatch):
    source = native.c_source(_halve())
    identity = ("/usr/bin/cc", "cc 12")
    key = native.cache_key(source, ("-O2",), identity)
    assert key == native.cache_key(source, ("-O2",), identity)
    assert key != native.cache_key(source, ("-O3",), identity)
    assert key != native.cache_key(source, ("-O2", "-march=native"), identity)
    assert key != native.cache_key(source, ("-O2",), ("/usr/bin/cc", "cc 13"))
    assert key != native.cache_key(source + " ", ("-O2",), identity)
    monkeypatch.setattr(ca, "__version__", "0.0.0")
    assert key != native.cache_key(source, ("-O2",), identity)


@needs_compiler
def test_other_flags_build_another_library_and_same_flags_reuse_it(cache):
    source = native.c_source(_halve())
    first = native.build("halve_native", source, ("-O1",))
    assert first is not None and first.parent == cache / "native"
    assert native.build("halve_native", source, ("-O1",)) == first
    second = native.build("halve_native", source, ("-O2",))
    assert second is not None and second != first
    assert native.cache_info().libraries == 2
    f = native.compile_function(_halve())
    assert float(f(3.0)) == 1.5


@needs_compiler
def test_cache_info_and_clear(cache, capsys):
    native.compile_function(_halve())
    (cache / "kernels").mkdir()  # a folder of the cache this one replaced
    (cache / "kernels" / "old.so").write_bytes(b"x" * 10)
    assert main(["cache", "info"]) == 0
    out = capsys.readouterr().out
    assert f"folder: {cache / 'native'}" in out and "libraries: 1," in out
    assert main(["cache", "clear"]) == 0
    assert "freed" in capsys.readouterr().out
    assert native.cache_info().libraries == 0 and not (cache / "kernels").exists()
    assert main(["cache", "info"]) == 0  # an absent folder is an empty cache
    assert "libraries: 0, 0.0 MiB" in capsys.readouterr().out


@needs_compiler
def test_cache_keeps_under_its_cap(cache, monkeypatch):
    old = native.build("halve_native", native.c_source(_halve()), ("-O1",))
    os.utime(old, (0, 0))  # least recently used
    monkeypatch.setattr(native, "MAX_CACHE_BYTES", old.stat().st_size + 1)
    new = native.build("halve_native", native.c_source(_halve()), ("-O2",))
    assert new.exists() and not old.exists()


@pytest.mark.parametrize(
    ("body", "reason"),
    [
        ('echo "source.c:1: error: boom" >&2; exit 1', "fake-cc failed: source.c:1: error: boom"),
        ("sleep 30; true", "fake-cc took more than 1 s"),  # sleep: a child of the driver
    ],
)
def test_a_failing_compiler_warns_once_and_falls_back(cache, monkeypatch, body, reason):
    compiler = cache / "fake-cc"
    compiler.write_text(
        f'#!/bin/sh\nif [ "$1" = --version ]; then echo "fake 1.0"; exit 0; fi\n{body}\n'
    )
    compiler.chmod(0o755)
    monkeypatch.setenv("CC", str(compiler))
    monkeypatch.setattr(native, "COMPILE_TIMEOUT_S", 1)
    monkeypatch.setattr(native, "_warned", False)
    start = time.monotonic()
    with pytest.warns(native.NativeCodeWarning) as caught:
        assert native.compile_function(_halve()) is None
        assert native.compile_function(_halve(), ("-O1",)) is None  # no second warning
    assert time.monotonic() - start < 20  # the timed-out group was killed, children too
    assert len(caught) == 1 and reason in str(caught[0].message)
    assert native.cache_info().libraries == 0


@needs_compiler
def test_compiled_window_loop_is_bitwise_the_casadi_evaluation():
    # The C loop over windows/samples/substeps against CasADi's mapaccum/map of the same
    # substep, both compiled and in CasADi's virtual machine: the same operations on the same
    # numbers, so equal to the last bit (no FMA contraction: -ffp-contract=off).
    from hframe_id.fitting import FitOptions, kernel
    from hframe_id.fitting import shooting as shooting_module
    from hframe_id.fitting.problem import build_problem
    from hframe_id.fitting.shooting import MultipleShooting
    from hframe_id.parameters import load_parameter_file
    from hframe_id.recordings.simulated import simulate_recording
    from hframe_id.simulation.open_loop import simulate

    truth = load_parameter_file(MODELS / "hframe-8-table4.2.yaml")
    u = np.zeros((400, 2))
    u[50:300] = (-4.0, 2.0)
    problem = build_problem([simulate_recording(truth, u, seed=4)], truth, FitOptions())
    p = problem.p_initial
    states = simulate(problem.model, p, problem.experiments[0].inputs, 1e-3, n_substeps=4)

    def evaluate(native_loop: bool):
        ms = MultipleShooting(problem).uniform()
        assert ms.native[True] is not None
        if not native_loop:
            ms.native = {True: None, False: None}
        nodes = states[ms.window_start] * 1.01  # off the trajectory: nonzero defects
        return ms.evaluate(nodes, np.zeros(len(problem.free)), problem.smoothing)

    reference = evaluate(True)
    mapped = [evaluate(False)]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(
            shooting_module, "compiled_substep", lambda m, f: kernel.substep_function(m, f)
        )
        patch.setattr(shooting_module, "compiled_state_substep", kernel.state_substep_function)
        mapped.append(evaluate(False))
    for other in mapped:
        for field in ("residual", "jac_node", "jac_theta", "x_end", "a_end", "b_end", "states"):
            np.testing.assert_array_equal(getattr(other, field), getattr(reference, field), field)


#: A compiled simulation and a small fit (two parameters, 0.4 s of data), printed as JSON.
SIMULATE_AND_FIT = """
import json, sys
import numpy as np
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.models import build_model
from hframe_id.parameters import load_parameter_file
from hframe_id.recordings.simulated import simulate_recording
from hframe_id.simulation.open_loop import simulate

truth = load_parameter_file(sys.argv[1])
u = np.zeros((400, 2))
u[50:300] = (-4.0, 2.0)
model = build_model(truth.variant)
states = simulate(model, model.parameter_vector(truth.values), u, 1e-3, compiled=True)
start = truth.replace_values(k_l=1.3 * truth.values["k_l"], B_M1=0.7 * truth.values["B_M1"])
options = FitOptions(verbose=0, free=("k_l", "B_M1"))
result = fit_recordings([simulate_recording(truth, u, seed=4)], start, options)
print(json.dumps({"end": states[-1].tolist(), "success": result.success,
                  "estimates": {k: e.estimate for k, e in result.estimates.items()}}))
"""


def _simulate_and_fit(env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", SIMULATE_AND_FIT, str(MODELS / "hframe-8-table4.2.yaml")],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )


@needs_compiler
def test_without_a_compiler_simulation_and_fit_work_with_one_warning(tmp_path):
    # PATH without any compiler (an empty folder), CC unset, an empty cache: nothing cached
    # can be loaded and nothing can be built.
    env = {k: v for k, v in os.environ.items() if k != "CC"}
    env.update(PATH=str(tmp_path), HFRAME_ID_CACHE=str(tmp_path / "cache"))
    done = _simulate_and_fit(env)
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, done.stderr
    assert "NativeCodeWarning: native code unavailable (no C compiler" in lines[0]
    without = json.loads(done.stdout)
    assert without["success"]
    assert not (tmp_path / "cache" / "native").exists()
    # The same run with the compiler: no warning, and the fit (bitwise the same window
    # integration) lands on the same numbers; the simulation to the VM's rounding (its
    # native code uses -freciprocal-math and an inline tanh).
    compiled = _simulate_and_fit(dict(os.environ))
    assert compiled.returncode == 0 and not compiled.stderr.strip(), compiled.stderr
    with_compiler = json.loads(compiled.stdout)
    assert with_compiler["estimates"] == without["estimates"]
    np.testing.assert_allclose(with_compiler["end"], without["end"], rtol=1e-9, atol=1e-12)
