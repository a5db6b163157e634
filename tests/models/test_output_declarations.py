"""Outputs that are not coordinates (``Output``, docs/custom-models.md): one symbolic output map
in the graph of the dynamics, the coordinate outputs of every other model unchanged, and bad
output declarations refused in one line naming the file and the output."""

from __future__ import annotations

from pathlib import Path

import casadi as ca
import numpy as np
import pandas as pd
import pytest

from hframe_id.analysis.linear import linearize
from hframe_id.cli import main
from hframe_id.fitting.dataset import output_kinds, state_outputs
from hframe_id.models import VARIANTS, build_model, load_model_file
from hframe_id.parameters import ParameterSet, save_parameter_file
from tests.models.refusals import refused_model_file

SERVO = Path(__file__).resolve().parents[2] / "models" / "dc_servo.py"
VALUES = {"J": 2.6e-5, "B": 1.4e-5, "tau_c": 3.0e-3, "K": 0.03, "R": 2.0, "g": 1.8}
#: A data sheet's values of the servo.
CATALOGUE = {"J": 2.0e-5, "B": 1.0e-5, "tau_c": 2.0e-3, "K": 0.03, "R": 2.0, "g": 2.0}


@pytest.fixture(scope="module")
def servo():
    load_model_file(SERVO)
    return build_model("dc-servo")


def test_outputs_are_the_declared_functions_of_state_inputs_and_parameters(servo):
    assert [s.label for s in servo.outputs] == ["omega [rad/s]", "current [A]"]
    p = servo.parameter_vector(VALUES)
    x, v = np.array([0.3, 120.0]), 5.0
    y = np.array(servo.output_map(x, v, p)).ravel()
    # The tachometer reads theta'; the shunt (g V - K theta') / R.
    assert y == pytest.approx([120.0, (1.8 * 5.0 - 0.03 * 120.0) / 2.0], rel=1e-15)
    # The current depends on the input and the parameters: no state-only output function.
    assert servo.output is None
    assert list(state_outputs(servo)) == [1, -1]
    assert output_kinds(servo) == ("rate", "other")


def test_the_output_map_is_in_the_graph_of_the_dynamics(servo):
    # Exact derivatives: d current / d theta' = -K / R, d / dV = g / R, d / dR = -I / R.
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    p = ca.SX.sym("p", len(servo.parameters))
    y = servo.output_map(x, u, p)
    jac = ca.Function("j", [x, u, p], [ca.jacobian(y, ca.vertcat(x, u, p))])
    values = servo.parameter_vector(VALUES)
    d = np.array(jac([0.3, 120.0], 5.0, values))
    current = (1.8 * 5.0 - 0.03 * 120.0) / 2.0
    names = list(servo.parameter_names)
    assert d[1, 1] == pytest.approx(-0.03 / 2.0, rel=1e-15)
    assert d[1, 2] == pytest.approx(1.8 / 2.0, rel=1e-15)
    assert d[1, 3 + names.index("R")] == pytest.approx(-current / 2.0, rel=1e-15)
    assert d[0].tolist() == [0.0, 1.0] + [0.0] * (1 + len(names))


def test_linearize_gives_the_current_its_feedthrough(servo):
    lin = linearize(ParameterSet("dc-servo", CATALOGUE, "catalogue", "data sheet"))
    # Catalogue: K 0.03, R 2, g 2: C = [[0, 1], [0, -K / R]], D = [[0], [g / R]].
    np.testing.assert_allclose(lin.C, [[0.0, 1.0], [0.0, -0.015]], rtol=1e-15)
    np.testing.assert_allclose(lin.D, [[0.0], [1.0]], rtol=1e-15)


def test_simulate_writes_each_output_from_the_output_map(servo, tmp_path):
    out = tmp_path / "step.csv"
    catalogue = save_parameter_file(
        ParameterSet("dc-servo", CATALOGUE, "catalogue", "data sheet"), tmp_path / "servo.yaml"
    )
    argv = [
        "simulate",
        "--model-file",
        str(SERVO),
        "--params",
        str(catalogue),
    ]
    assert main([*argv, "--step", "1,5.0", "--duration", "0.5", "--out", str(out)]) == 0
    table = pd.read_csv(out)
    speed = table["state theta_dot [rad/s]"]
    assert table["output omega [rad/s]"].tolist() == speed.tolist()
    # Catalogue: g 2, K 0.03, R 2; the final row holds the last input (5 V).
    np.testing.assert_allclose(table["output current [A]"], (2.0 * 5.0 - 0.03 * speed) / 2.0)
    # Settled, the current's torque K I balances the friction B w + tau_c (1e-5, 2e-3).
    assert 0.03 * table["output current [A]"].iloc[-1] == pytest.approx(
        1e-5 * speed.iloc[-1] + 2e-3, rel=1e-3
    )


@pytest.mark.parametrize("variant", VARIANTS)
def test_the_thesis_models_output_their_coordinates_as_before(variant):
    model = build_model(variant)
    coordinates = [c.name for c in model.coordinates]
    index = state_outputs(model)
    assert [coordinates[i] for i in index] == [s.name for s in model.outputs]
    x = np.arange(1.0, model.n_states + 1)
    p = np.ones(len(model.parameters))
    u = np.zeros(model.n_inputs)
    assert np.array(model.output(x)).ravel().tolist() == x[index].tolist()
    assert np.array(model.output_map(x, u, p)).ravel().tolist() == x[index].tolist()


BAD = [
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd, u, p: ca.vertcat(qd["theta"], '
        'qd["theta"]), noise_std=0.5)',
        "output 'omega': function must return one value, got a 2x1 expression",
    ),
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd, u, p: qd["w"], noise_std=0.5)',
        "output 'omega': uses undeclared rate 'w'; declared: theta",
    ),
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd, u, p: qd["theta"] * '
        'float("nan"))',
        "output 'omega': is not finite (nan)",
    ),
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd, u, p: p["R"] / 0.0)',
        "output 'omega': is not finite (inf)",
    ),
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd, u, p: "fast")',
        "output 'omega': function must return one expression or number, got str",
    ),
    (
        'Output("omega", "rad/s", "tachometer speed", lambda q, qd: qd["theta"])',
        "output 'omega': function failed: TypeError",
    ),
    ('"theta_dot"', "output 'theta_dot' is not a coordinate (theta); declare any other"),
    (
        'Output("omega", "rad/s", "tachometer speed", speed, noise_std=-1.0)',
        "output 'omega': noise_std must be > 0 and finite, got -1.0",
    ),
    (
        'Output("omega", "", "tachometer speed", speed)',
        "output 'omega' has no unit",
    ),
    (
        'Output("theta", "rad", "angle again", speed)',
        "output 'theta' has the name of a coordinate",
    ),
    (
        'Output("omega", "rad/s", "tachometer", speed), Output("omega", "rad/s", "again", speed)',
        "output 'omega' is declared twice",
    ),
]


@pytest.mark.parametrize(("outputs", "message"), BAD, ids=[m.split(":")[-1][:30] for _, m in BAD])
def test_a_bad_output_is_one_line_naming_the_file_and_the_output(
    tmp_path, capsys, outputs, message
):
    text = SERVO.read_text().replace('name="dc-servo"', f'name="bad-{tmp_path.name[-6:]}"')
    text = "import casadi as ca\n" + text
    start = text.index("    outputs=[")
    end = text.index("    ],\n", start) + len("    ],\n")
    path = tmp_path / "bad_servo.py"
    path.write_text(f"{text[:start]}    outputs=[{outputs}],\n{text[end:]}")
    refused_model_file(path, message, capsys)
