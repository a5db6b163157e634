"""The DC servo of ``models/dc_servo.py`` with outputs that are not coordinates: model files
declaring a chosen set of its outputs, and recordings simulated with known parameters (the
shared material of the output tests in this folder)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from hframe_id.models import build_model, load_model_file
from hframe_id.parameters import ParameterSet
from hframe_id.recordings.recording import Recording
from hframe_id.simulation.open_loop import outputs_of, simulate

MODEL_FILE = Path(__file__).resolve().parents[2] / "models" / "dc_servo.py"
#: The plant: 1.3 x the catalogue's inertia, 1.4 x its viscous and 1.5 x its Coulomb friction,
#: a gain 10 % low (K and R are the catalogue's: a fit holds them).
TRUTH = {"J": 2.6e-5, "B": 1.4e-5, "tau_c": 3.0e-3, "K": 0.03, "R": 2.0, "g": 1.8}
#: The data sheet's values (a catalogue), the start of the fits.
CATALOGUE = {"J": 2.0e-5, "B": 1.0e-5, "tau_c": 2.0e-3, "K": 0.03, "R": 2.0, "g": 2.0}
#: Sensor noise std: a 4096-count encoder's quantization [rad], a tachometer [rad/s] (0.15 %
#: of the ~330 rad/s top speed), a current shunt [A].
NOISE = {"theta": 2 * np.pi / 4096 / np.sqrt(12), "omega": 0.5, "current": 0.01}
UNITS = {"V": "V", "theta": "rad", "omega": "rad/s", "current": "A"}
SAMPLE_PERIOD_S = 1e-3
#: Outputs of the variants the tests declare, as written in a model file's ``outputs=[...]``.
OUTPUTS = {
    "speed": 'Output("omega", "rad/s", "tachometer speed", speed, noise_std=0.5)',
    "angle-speed": '"theta", Output("omega", "rad/s", "tachometer speed", speed, noise_std=0.5)',
}


#: Model files written and loaded in this process, by variant: the registry takes a model
#: name from one file only.
_LOADED: dict[str, tuple[str, Path]] = {}


def servo_model_file(folder: Path, variant: str) -> tuple[str, Path]:
    """(model name, path) of ``models/dc_servo.py`` itself (``"shipped"``) or of a copy in
    ``folder`` declaring the outputs ``OUTPUTS[variant]``, loaded (once per process: later
    calls return the first copy)."""
    if variant in _LOADED:
        return _LOADED[variant]
    if variant == "shipped":
        name, path = "dc-servo", MODEL_FILE
    else:
        name = f"dc-servo-{variant}"
        text = MODEL_FILE.read_text().replace('name="dc-servo"', f'name="{name}"')
        outputs = f"outputs=[{OUTPUTS[variant]}],"
        text = re.sub(r"outputs=\[.*?\n    \],", outputs, text, flags=re.S)
        path = folder / f"{name.replace('-', '_')}.py"
        path.write_text(text)
    load_model_file(path)
    _LOADED[variant] = name, path
    return name, path


def voltage_steps(seed: int, n: int, hold: int = 200, preroll: int = 100) -> np.ndarray:
    """(n,) amplifier input [V]: rest for ``preroll`` samples, then levels uniform in
    [-8, 8] V held ``hold`` samples each (seeded)."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-8.0, 8.0, size=n // hold + 1), hold)[:n]
    u[:preroll] = 0.0
    return u


def servo_run(name: str, seed: int, n: int = 2000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u (n,) [V], states (n, 2), true outputs (n, n_y)) of model ``name`` at ``TRUTH``
    under ``voltage_steps(seed, n)``, from rest."""
    model = build_model(name)
    p = model.parameter_vector(TRUTH)
    u = voltage_steps(seed, n)
    states = simulate(model, p, u[:, None], SAMPLE_PERIOD_S)[:n]
    return u, states, outputs_of(model, states, u[:, None], p)


def servo_recording(name: str, seed: int, n: int = 2000, rig: dict | None = None) -> Recording:
    """A recording of model ``name``'s outputs at ``TRUTH`` with white noise ``NOISE``
    (seeded by ``seed``); ``rig`` metadata as given, by default the encoder's noise for the
    angle (a coordinate: the rig's sensor), none for the other outputs (the model's
    declared sensor noise weights them)."""
    model = build_model(name)
    u, _, clean = servo_run(name, seed, n)
    names = tuple(s.name for s in model.outputs)
    rng = np.random.default_rng(1000 + seed)
    noisy = clean + rng.standard_normal(clean.shape) * np.array([NOISE[k] for k in names])
    return Recording(
        variant=name,
        sample_period_s=SAMPLE_PERIOD_S,
        time_s=np.arange(n) * SAMPLE_PERIOD_S,
        inputs=u[:, None],
        input_names=("V",),
        outputs=noisy,
        output_names=names,
        valid=np.ones(noisy.shape, dtype=bool),
        units={k: UNITS[k] for k in ("V", *names)},
        rig={"noise_std_theta": NOISE["theta"]} if rig is None else rig,
    )


def start(name: str, **values: float) -> ParameterSet:
    """The catalogue as a parameter set of model ``name``, with ``values`` replaced."""
    return ParameterSet(name, {**CATALOGUE, **values}, "catalogue", "data sheet")
