"""models/emps_axis_directional.py, the EMPS axis with direction-dependent friction: it is
models/emps_axis.py when both directions have the same friction, and a fit on a simulated
recording of a directional plant recovers the asymmetry (docs/real-data.md)."""

from pathlib import Path

import numpy as np
import pytest

from hframe_id.fitting import FitOptions, fit_recordings
from hframe_id.models import build_model, load_model_file
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.recordings import read_recording
from hframe_id.recordings.recording import Recording
from hframe_id.resources import datasets_dir
from hframe_id.simulation.integrators import stable_substeps
from hframe_id.simulation.open_loop import outputs_of, simulate
from hframe_id.validation.benchmark_filters import (
    BORDER_SAMPLES,
    filtered_motion,
    matlab_decimate,
)

MODELS = Path(__file__).resolve().parents[2] / "models"
SYMMETRIC = "emps-axis"
DIRECTIONAL = "emps-axis-directional"
SAMPLE_PERIOD_S = 1e-3
GTAU = 35.15065188  # N/V, DATA_EMPS.mat
#: A plant more asymmetric than the benchmark's (Janot's asymmetric IDIM: F_v 166.7 / 240.4
#: N s/m, F_c 20.14 / 20.63 N), with an offset, so that every parameter is tested.
TRUTH = {
    "M": 95.0,
    "F_v_pos": 170.0,
    "F_v_neg": 240.0,
    "F_c_pos": 18.0,
    "F_c_neg": 24.0,
    "F_0": -3.0,
    "gtau": GTAU,
}
#: Position noise std [m]: the real fit's residual rms at 50 ms horizons is 1-2 um.
NOISE_STD_M = 1e-6


@pytest.fixture(scope="module", autouse=True)
def models():
    load_model_file(MODELS / "emps_axis.py")
    load_model_file(MODELS / "emps_axis_directional.py")


def voltage_steps(seed: int, n: int, hold: int = 300) -> np.ndarray:
    """(n, 1) controller output [V]: levels of either sign, 0.8-3 V in magnitude (0.1-0.4 m/s
    sliding, like the benchmark's plateaus), every fourth level a rest, held ``hold`` samples
    (seeded); the first 100 samples at rest."""
    rng = np.random.default_rng(seed)
    levels = rng.uniform(0.8, 3.0, n // hold + 1) * rng.choice([-1.0, 1.0], n // hold + 1)
    levels[::4] = 0.0
    u = np.repeat(levels, hold)[:n]
    u[:100] = 0.0
    return u[:, None]


def test_equal_directions_simulate_as_the_symmetric_axis():
    """F_v_pos = F_v_neg = F_v and F_c_pos = F_c_neg = F_c: w+ (F_v v + F_c s) +
    w- (F_v v + F_c s) with w+ + w- = 1 is emps_axis.py's F_v v + F_c s but for the order of
    the floating-point operations (relative 1e-16 per step); over 3 s of steps through both
    directions and rest, with the same RK4 substeps, the states agree to 1e-9 of their range
    (measured: 5e-16 on the position, 1.4e-16 on the velocity)."""
    idim = load_parameter_file(MODELS / "emps-idim-ls.yaml").values
    symmetric, directional = build_model(SYMMETRIC), build_model(DIRECTIONAL)
    p_sym = symmetric.parameter_vector(idim)
    p_dir = directional.parameter_vector(
        {
            "M": idim["M"],
            "F_v_pos": idim["F_v"],
            "F_v_neg": idim["F_v"],
            "F_c_pos": idim["F_c"],
            "F_c_neg": idim["F_c"],
            "F_0": idim["F_0"],
            "gtau": idim["gtau"],
        }
    )
    u = voltage_steps(1, 3000)
    substeps = stable_substeps(symmetric, p_sym, SAMPLE_PERIOD_S)
    expected = simulate(symmetric, p_sym, u, SAMPLE_PERIOD_S, n_substeps=substeps)
    actual = simulate(directional, p_dir, u, SAMPLE_PERIOD_S, n_substeps=substeps)
    scale = np.abs(expected).max(axis=0)
    assert np.all(scale > 0.05)  # it moved: > 5 cm, > 5 cm/s
    assert np.all(np.abs(actual - expected).max(axis=0) <= 1e-9 * scale)


def test_the_friction_switches_with_the_direction():
    """Sliding well beyond v_s = 1 mm/s (tanh(50) = 1 to rounding), the friction force is
    F_v_pos v + F_c_pos forwards and F_v_neg v - F_c_neg backwards; at rest it is 0."""
    model = build_model(DIRECTIONAL)
    p = model.parameter_vector(TRUTH)
    for v, friction in ((0.05, 170.0 * 0.05 + 18.0), (-0.05, 240.0 * -0.05 - 24.0), (0.0, 0.0)):
        xdot = np.asarray(model.dynamics([0.0, v], [0.0], p, model.options.smoothing)).ravel()
        # M a = -F_0 - friction at zero voltage
        assert xdot[1] * TRUTH["M"] == pytest.approx(3.0 - friction, rel=1e-12, abs=1e-12)


def directional_recording(seed: int, n: int) -> Recording:
    """A recording of the directional plant at ``TRUTH`` under ``voltage_steps(seed, n)``,
    its position with white noise ``NOISE_STD_M`` (seeded)."""
    model = build_model(DIRECTIONAL)
    p = model.parameter_vector(TRUTH)
    u = voltage_steps(seed, n)
    states = simulate(model, p, u, SAMPLE_PERIOD_S)[:n]
    clean = outputs_of(model, states, u, p)
    noisy = clean + np.random.default_rng(1000 + seed).standard_normal(clean.shape) * NOISE_STD_M
    return Recording(
        variant=DIRECTIONAL,
        sample_period_s=SAMPLE_PERIOD_S,
        time_s=np.arange(n) * SAMPLE_PERIOD_S,
        inputs=u,
        input_names=("vir",),
        outputs=noisy,
        output_names=("qm",),
        valid=np.ones(noisy.shape, dtype=bool),
        units={"vir": "V", "qm": "m"},
        rig={"noise_std_qm": NOISE_STD_M},
    )


def test_a_fit_recovers_asymmetric_friction():
    """From a symmetric start (the IDIM-LS set's friction in both directions, F_0 = 0, M 5 %
    low), the model's own fit settings (50-sample horizons, ``continuity: none``) recover the
    directional plant's parameters from 6 s of noisy steps.

    Measured errors: M -0.03 %, F_v_pos / F_v_neg -0.08 / -0.15 %, F_c_pos / F_c_neg
    +0.24 / +0.09 %, F_0 -0.03 N; standard errors 0.005 %, 0.03 %, 0.2 %, 0.04 N. The limits
    (0.5 % on M and F_v, 2 % on F_c, 0.3 N on F_0) hold 3-10 x the measured errors, are far
    above the solver's step tolerance (1e-6 relative), and far below the asymmetry to be
    found (F_v 41 %, F_c 33 %): a fit that missed the direction (both directions at their
    mean) fails them by 8 x or more."""
    recording = directional_recording(7, 6000)
    start = ParameterSet(
        DIRECTIONAL,
        {
            "M": 90.0,
            "F_v_pos": 203.5,
            "F_v_neg": 203.5,
            "F_c_pos": 20.4,
            "F_c_neg": 20.4,
            "F_0": 0.0,
            "gtau": GTAU,
        },
        "symmetric start",
        "IDIM-LS friction in both directions",
    )
    result = fit_recordings([recording], start, FitOptions(verbose=0, noise="sensor"))
    assert result.success, result.message
    limits = {"M": 0.005, "F_v_pos": 0.005, "F_v_neg": 0.005, "F_c_pos": 0.02, "F_c_neg": 0.02}
    for name, limit in limits.items():
        estimate = result.estimates[name].estimate
        assert abs(estimate - TRUTH[name]) <= limit * TRUTH[name], (name, estimate)
    assert abs(result.estimates["F_0"].estimate - TRUTH["F_0"]) <= 0.3


def test_the_shipped_set_is_the_descriptions_asymmetric_idim_ls():
    """Script_IDIM_LS_Asym_Fric.m on the shipped recording: least squares on the decimated
    observation matrix [qdd, qd O+, sign(qd) O+, qd O-, sign(qd) O-], O+/- = (1 +/- sign qd) / 2,
    without an offset column, gives models/emps-directional-idim.yaml (the values printed in
    EMPS_Description.pdf, section 4.2, to their 4 decimals: 5e-5) and the printed relative
    error 3.1117 %."""
    recording = read_recording(datasets_dir() / "real" / "emps-estimation.mcap")
    q_f, dq_f, ddq_f = filtered_motion(recording.outputs, recording.sample_period_s)
    force = recording.rig["gtau"] * recording.inputs[:, 0]
    dq, sign = dq_f[:, 0], np.sign(dq_f[:, 0])
    plus, minus = (1 + sign) / 2, (1 - sign) / 2
    columns = [ddq_f[:, 0], dq * plus, sign * plus, dq * minus, sign * minus]
    x = np.column_stack([matlab_decimate(c[BORDER_SAMPLES:], 10) for c in columns])
    y = matlab_decimate(force[BORDER_SAMPLES:], 10)
    estimate, *_ = np.linalg.lstsq(x, y, rcond=None)
    shipped = load_parameter_file(MODELS / "emps-directional-idim.yaml").values
    # Janot's F_c^- multiplies sign(qd) O- = -O-: a magnitude, as F_c_neg here.
    names = ("M", "F_v_pos", "F_c_pos", "F_v_neg", "F_c_neg")
    for value, name in zip(estimate, names, strict=True):
        assert value == pytest.approx(shipped[name], abs=5e-5), name
    assert shipped["F_0"] == 0.0  # the asymmetric model has no offset term
    error = 100 * np.linalg.norm(y - x @ estimate) / np.linalg.norm(y)
    assert round(error, 4) == 3.1117
