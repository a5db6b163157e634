"""Native compilation of the simulators: the inline tanh, the cache, the fallback."""

import casadi as ca
import numpy as np
import pytest

from hframe_id import native
from hframe_id.simulation.compiled import compile_function, evaluate, maybe_compile

pytestmark = pytest.mark.skipif(not native.compiler_available(), reason="needs a C compiler")


def test_inline_tanh_is_accurate_to_a_few_ulp():
    # 4 ulp: the Taylor branch (|x| < 0.25) and (1 - e) / (1 + e) with a 1-ulp exp each add a
    # few roundings; glibc's tanh is itself not correctly rounded. Measured maximum: 3 ulp.
    rng = np.random.default_rng(0)
    points = np.concatenate([
        rng.uniform(-1, 1, 20000), rng.uniform(-0.3, 0.3, 20000),
        np.sign(rng.normal(size=20000)) * 10 ** rng.uniform(-320, 2.5, 20000),
        rng.uniform(-25, 25, 20000), [0.25, -0.25, 19.0625, 19.06, 0.2499999999],
    ])  # fmt: skip
    x = ca.SX.sym("x")
    tanh = compile_function(ca.Function("tanh_check", [x], [ca.tanh(x)]).map(points.size))
    (values,) = evaluate(tanh, [points])
    reference = np.tanh(points)
    ulp = np.abs(values.ravel() - reference) / np.spacing(np.abs(reference))
    assert ulp.max() <= 4.0
    special = np.array([0.0, -0.0, np.inf, -np.inf, np.nan, 1e-310])
    small = compile_function(ca.Function("tanh_special", [x], [ca.tanh(x)]).map(special.size))
    (out,) = evaluate(small, [special])
    out = out.ravel()
    assert out[0] == 0.0 and np.signbit(out[1])
    assert out[2] == 1.0 and out[3] == -1.0 and np.isnan(out[4]) and out[5] == 1e-310


def test_native_code_leaves_subnormals_alone():
    # -ffast-math would link crtfastmath.o and set flush-to-zero for the whole process.
    x = ca.SX.sym("x")
    f = compile_function(ca.Function("halve", [x], [x / 2]))
    assert float(f(4e-308)) == 2e-308
    assert np.float64(5e-324) * 1.0 == 5e-324 and np.float64(1e-308) / 4 > 0


def test_evaluate_checks_sizes():
    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [2 * x])
    np.testing.assert_array_equal(evaluate(f, [np.arange(3.0)])[0].ravel(), [0, 2, 4])
    with pytest.raises(ValueError, match="needs 3 numbers"):
        evaluate(f, [np.arange(4.0)])


def test_missing_compiler_falls_back_to_the_virtual_machine(monkeypatch, tmp_path):
    monkeypatch.setenv("HFRAME_ID_CACHE", str(tmp_path))
    monkeypatch.setattr(native, "compiler", lambda: None)
    monkeypatch.setattr(native, "_warned", False)
    x = ca.SX.sym("x")
    f = ca.Function("g", [x], [x**2])
    with pytest.warns(native.NativeCodeWarning, match="virtual machine"):
        g = maybe_compile(f, True)
    assert g is f
    assert not any(tmp_path.iterdir())
