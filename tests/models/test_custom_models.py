"""User models declared by their energies (docs/custom-models.md): one declaration is enough
for every command, bad model files fail with one line naming the file and the item."""

from __future__ import annotations

import importlib.util
import json
import textwrap

import numpy as np
import pandas as pd
import pytest

from hframe_id.cli import main
from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.models import build_model, load_model_file
from hframe_id.parameters import ParameterSet, save_parameter_file
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import simulate
from tests.models.refusals import refused_model_file

#: A fourth variant: a cart on a spring, driven through a voltage-controlled force, with an
#: offset force (a signed parameter) and viscous plus Coulomb friction.
SPRING_CART = """
from hframe_id.models import ParameterSpec, Signal, declare


def equations(q, qdot, u, p):
    return {
        "kinetic": 0.5 * p["m"] * qdot["z"] ** 2,
        "potential": 0.5 * p["k"] * q["z"] ** 2,
        "forces": {"z": p["g"] * u["v"] - p["f0"]},
        "friction": {"z": ("c", "fc")},
    }


MODEL = declare(
    name="spring-cart-test",
    description="cart on a spring (test model)",
    coordinates=[Signal("z", "m", "cart position")],
    inputs=[Signal("v", "V", "drive voltage")],
    outputs=["z"],
    parameters=[
        ParameterSpec("m", "kg", "mass"),
        ParameterSpec("k", "N/m", "spring stiffness"),
        ParameterSpec("c", "N s/m", "viscous friction"),
        ParameterSpec("fc", "N", "Coulomb friction", "nonnegative"),
        ParameterSpec("f0", "N", "offset force", "real"),
        ParameterSpec("g", "N/V", "drive gain"),
    ],
    equations=equations,
    fixed=("g",),
)
"""
TRUTH = {"m": 2.0, "k": 800.0, "c": 6.0, "fc": 0.5, "f0": -0.8, "g": 5.0}


def _write(tmp_path, text, name="my_model.py"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


@pytest.fixture(scope="module")
def spring_cart(tmp_path_factory):
    """The model file, a parameter set of the truth, and one recording made with it."""
    folder = tmp_path_factory.mktemp("spring_cart")
    path = _write(folder, SPRING_CART)
    load_model_file(path)
    params = ParameterSet("spring-cart-test", dict(TRUTH), "truth", "test")
    params_path = save_parameter_file(params, folder / "truth.yaml")
    model = build_model("spring-cart-test")
    dt, n = 1e-3, 3000
    rng = np.random.default_rng(7)
    t = np.arange(n) * dt
    u = (2.0 * np.sign(np.sin(2 * np.pi * 1.5 * t)) + 0.5 * rng.standard_normal(n))[:, None]
    states = simulate(model, model.parameter_vector(TRUTH), u, dt)
    noise_std = 2e-6
    z = states[:n, 0] + noise_std * rng.standard_normal(n)  # states at t_0 .. t_{n-1}
    recording = Recording(
        variant="spring-cart-test",
        sample_period_s=dt,
        time_s=t,
        inputs=u,
        input_names=("v",),
        outputs=z[:, None],
        output_names=("z",),
        valid=np.ones((n, 1), dtype=bool),
        units={"v": "V", "z": "m"},
        rig={"noise_std_z": noise_std},
    )
    return path, params_path, recording


def test_a_fourth_variant_by_one_declaration_fits_from_a_wrong_start(spring_cart):
    _, _, recording = spring_cart
    start = ParameterSet(
        "spring-cart-test",
        {**TRUTH, "m": 2.6, "k": 640.0, "c": 4.5, "fc": 0.7, "f0": -0.5},
        "start",
        "test",
    )
    result = fit_recordings([recording], start, FitOptions(verbose=0))
    assert result.success, result.message
    for name in ("m", "k", "c", "fc", "f0"):
        est = result.estimates[name]
        # Matched data at 2 um noise: the estimate is within its own 95 % interval of the truth
        # (an interval test, not a fixed tolerance), and within 2 % (offset: 0.02 N).
        low, high = est.ci95
        assert low <= TRUTH[name] <= high, (name, est)
        limit = 0.02 if name == "f0" else 0.02 * TRUTH[name]
        assert abs(est.estimate - TRUTH[name]) < limit, (name, est.estimate)
    # The signed offset has a symmetric interval in SI, not a log-scale one.
    est = result.estimates["f0"]
    assert est.ci95[1] - est.estimate == pytest.approx(est.estimate - est.ci95[0])


def test_every_command_takes_the_model_file(spring_cart, tmp_path, capsys):
    model_file, params_path, _ = spring_cart
    common = ["--model-file", str(model_file)]
    assert main(["params", "show", *common, str(params_path)]) == 0
    assert "spring-cart-test" in capsys.readouterr().out
    assert main(["linearize", *common, str(params_path)]) == 0
    out = capsys.readouterr().out
    # Poles of m s^2 + c s + k: -c / 2m +/- i sqrt(k/m - (c/2m)^2).
    assert f"{-TRUTH['c'] / (2 * TRUTH['m']):.4f}" in out
    target = tmp_path / "ss.json"
    assert (
        main(["export", *common, "--format", "statespace", "--out", str(target), str(params_path)])
        == 0
    )
    exported = json.loads(target.read_text())
    assert np.allclose(
        exported["A"], [[0, 1], [-TRUTH["k"] / TRUTH["m"], -TRUTH["c"] / TRUTH["m"]]]
    )
    out_csv = tmp_path / "step.csv"
    for friction in ("smooth", "stick-slip"):
        argv = [
            "simulate",
            *common,
            "--params",
            str(params_path),
            "--step",
            "1,2.0",
            "--duration",
            "2.0",
            "--friction",
            friction,
            "--out",
            str(out_csv),
            "--overwrite",
        ]
        assert main(argv) == 0, friction
        table = pd.read_csv(out_csv)
        # A 2 V step: force g 2 V - f0 = 10.8 N against the spring, settling at (10.8 - fc) / k
        # or closer to rest than (10.8 + fc) / k (Coulomb friction holds it in that band).
        settled = table["state z [m]"].iloc[-1]
        force = TRUTH["g"] * 2.0 - TRUTH["f0"]
        assert (
            (force - TRUTH["fc"]) / TRUTH["k"] - 1e-6
            <= settled
            <= (force + TRUTH["fc"]) / TRUTH["k"] + 1e-6
        )
    capsys.readouterr()
    assert main(["models", *common, "--json"]) == 0
    listed = {m["variant"] for m in json.loads(capsys.readouterr().out)}
    assert "spring-cart-test" in listed


def test_a_parameter_file_names_its_model_file(spring_cart):
    """Saved sets of a user model carry ``model_file``, so readers find the model."""
    _, params_path, _ = spring_cart
    assert "model_file: my_model.py" in params_path.read_text()


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            SPRING_CART.replace('"potential": 0.5 * p["k"] * q["z"] ** 2,\n', ""),
            "no 'potential' energy",
        ),
        (
            SPRING_CART.replace('p["g"] * u["v"]', 'p["gain"] * u["v"]'),
            "undeclared parameter 'gain'",
        ),
        (
            SPRING_CART.replace('ParameterSpec("k", "N/m"', 'ParameterSpec("k", ""'),
            "'k' has no unit",
        ),
        (
            SPRING_CART.replace(
                'coordinates=[Signal("z", "m", "cart position")]',
                'coordinates=[Signal("z", "m", "cart position"), Signal("w", "m", "other")]',
            ),
            "coordinate 'w' has no equation of motion",
        ),
        (SPRING_CART.replace("MODEL = declare(", "OTHER = declare("), "defines no MODEL"),
        (
            SPRING_CART.replace("def equations(q, qdot, u, p):", "def equations(q, qdot, u, p)"),
            "SyntaxError",
        ),
        (
            SPRING_CART.replace('"forces": {"z":', '"forces": {"zz":'),
            "force on undeclared coordinate 'zz'",
        ),
        (
            SPRING_CART.replace('("c", "fc")', '("c", "fc", "fc")'),
            "must be (viscous, coulomb) or (viscous, coulomb, static, stribeck velocity)",
        ),
        (
            SPRING_CART.replace('("c", "fc")', '("c", "fc", "fs", "v_st")'),
            "uses undeclared parameter 'fs'",
        ),
    ],
    ids=[
        "missing-energy",
        "undeclared-symbol",
        "unitless",
        "no-equation",
        "no-model",
        "syntax",
        "bad-force",
        "friction-names",
        "undeclared-static",
    ],
)
def test_bad_model_files_fail_with_one_line(tmp_path, capsys, text, message):
    path = _write(tmp_path, text.replace("spring-cart-test", f"bad-{tmp_path.name[-6:]}"), "bad.py")
    refused_model_file(path, message, capsys)


def test_a_missing_model_file_is_one_line(capsys):
    assert main(["models", "--model-file", "no/such/model.py"]) == 2
    assert "model.py: no such file" in capsys.readouterr().err


def test_a_folder_as_model_file_is_named_as_one(tmp_path, capsys):
    """A folder (or a pipe) given as a model file was said not to exist."""
    (tmp_path / "dir.py").mkdir()
    assert main(["models", "--model-file", str(tmp_path / "dir.py")]) == 2
    assert "dir.py: is a directory, not a file" in capsys.readouterr().err


def test_a_package_registers_models_through_the_entry_point_group(monkeypatch, tmp_path):
    """A plug-in's entry point (group ``hframe_id.models``) loads a declaration; its variant is
    then known by name without --model-file."""
    from hframe_id.models import declaration, registry

    path = _write(tmp_path, SPRING_CART.replace("spring-cart-test", "plug-in-cart"), "plugin.py")
    spec = importlib.util.spec_from_file_location("plugin_cart", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)

    class EntryPoint:
        name, value = "plug-in-cart", "plugin_cart:MODEL"

        def load(self):
            return module.MODEL

    seen = []
    monkeypatch.setattr(
        registry, "entry_points", lambda group: seen.append(group) or [EntryPoint()]
    )
    registry._load_entry_points.cache_clear()
    try:
        assert declaration("plug-in-cart").source == str(path)
        assert seen == [registry.ENTRY_POINT_GROUP]
        assert build_model("plug-in-cart").n_states == 2
    finally:
        registry._load_entry_points.cache_clear()
