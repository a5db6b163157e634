"""The ``sim`` rig: any model and parameter file as the plant, measured by the thesis's sensors.

The plant is stepped once per sample by the same fixed-step RK4 (same substeps, same Coulomb
smoothing) as ``hframe_id.simulation.open_loop.simulate``, and measured by the same sensor
models, drawing random numbers in the same order as ``hframe_id.recordings.simulated``: a run
with a given seed and inputs equals ``simulate_recording`` with that seed and inputs (to float
round-off). Paced in real time by default (``read()`` returns at the sample's wall time, like
hardware); ``paced=False`` runs as fast as it can (making datasets).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import casadi as ca
import numpy as np
import yaml

from hframe_id.errors import OptionError, RigFault
from hframe_id.models import build_model
from hframe_id.parameters import ParameterSet
from hframe_id.parameters.files import to_document
from hframe_id.recordings.log_format import PLANT_ATTACHMENT
from hframe_id.recordings.sensors import SensorModel, SensorReadout
from hframe_id.recordings.writer import Attachment
from hframe_id.rig.interface import LinkStats, Rig, RigInfo, RigSample
from hframe_id.simulation.integrators import rk4_step, stable_substeps

#: Limit switch positions [m] of the simulated rigs (the thesis gives no travel; these keep
#: every shipped experiment clear of them with margin).
DEFAULT_TRAVEL_M = {"x": (-0.25, 0.25), "y": (-0.25, 0.25)}


class SimRig(Rig):
    """A simulated rig.

    Parameters
    ----------
    params : plant parameters (any model variant).
    sensors : sensor models (default: the thesis's rig, section 1.1).
    seed : seeds the encoder power-up phases and the laser noise.
    sample_period_s : sample period [s].
    paced : pace samples in real time (True) or run unpaced (False).
    travel_m : per axis, (min, max) limit switch positions [m].
    n_substeps : RK4 substeps per sample (default: ``stable_substeps``).
    """

    def __init__(
        self,
        params: ParameterSet,
        *,
        sensors: SensorModel | None = None,
        seed: int = 0,
        sample_period_s: float = 1e-3,
        paced: bool = True,
        travel_m: dict[str, tuple[float, float]] | None = None,
        n_substeps: int | None = None,
    ) -> None:
        if not sample_period_s > 0:
            raise OptionError(f"sample period must be > 0 s, got {sample_period_s}")
        self.params = params
        self.sensors = sensors or SensorModel()
        self.seed = int(seed)
        self.paced = bool(paced)
        self.model = build_model(params.variant)
        self._p = self.model.parameter_vector(params.values)
        self._s = ca.DM(self.model.options.smoothing)
        n = n_substeps or stable_substeps(self.model, self._p, sample_period_s)
        self._step = rk4_step(self.model, int(n), float(sample_period_s))
        outputs = tuple(s.name for s in self.model.outputs)
        axes = [a for a in ("x", "y") if a in outputs]
        travel = travel_m if travel_m is not None else {a: DEFAULT_TRAVEL_M[a] for a in axes}
        for axis, (low, high) in travel.items():
            if axis not in axes or not low < high:
                raise OptionError(f"travel of axis {axis!r} must be (min < max) on {axes}")
        self._axis_columns = {a: outputs.index(a) for a in travel}
        gains = tuple(float(params.values[f"g_{i}"]) for i in range(1, self.model.n_inputs + 1))
        self.info = RigInfo(
            variant=params.variant,
            backend="sim",
            sample_period_s=float(sample_period_s),
            inputs=tuple(s.name for s in self.model.inputs),
            outputs=outputs,
            sensors=self.sensors,
            pulley_radius_m=float(params.values["r"]),
            amplifier_gains=gains,
            travel_m=dict(travel),
            serial_number=f"sim-{params.variant}",
            firmware="hframe-id sim",
            extra={
                "seed": self.seed,
                "paced": self.paced,
                "plant_parameters": params.path.name if params.path else params.title,
                "rk4_substeps": int(n),
            },
        )
        self.stats = LinkStats()
        self._started = False

    def start(self) -> None:
        self._rng = np.random.default_rng(self.seed)
        self._readout = SensorReadout(self.sensors, self.info.outputs, self._rng)
        self._x = np.zeros(self.model.n_states)
        self._applied = np.zeros(self.model.n_inputs)
        self._command_sequence: int | None = None
        self._k = 0
        self._t0 = time.perf_counter()
        self._started = True

    def read(self) -> RigSample:
        if not self._started:
            raise RigFault("sim rig: read() before start()")
        k = self._k
        if k > 0:
            self._x = np.asarray(self._step(self._x, self._applied, self._p, self._s)).ravel()
        if self.paced:
            delay = self._t0 + k * self.info.sample_period_s - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        y = np.asarray(self.model.output(self._x)).ravel()
        counts, laser, valid = self._readout.read(y)
        limits = {}
        for axis, column in self._axis_columns.items():
            low, high = self.info.travel_m[axis]
            limits[f"{axis}_min"] = bool(y[column] <= low)
            limits[f"{axis}_max"] = bool(y[column] >= high)
        self._k += 1
        return RigSample(
            sequence=k,
            device_time_us=k * self.info.period_us,
            encoder_counts=tuple(int(c) for c in counts),
            laser_m=tuple(float(v) for v in laser),
            laser_valid=tuple(bool(v) for v in valid),
            limits={name: limits[name] for name in self.info.limit_switches},
            applied_v=tuple(float(v) for v in self._applied),
            command_sequence=self._command_sequence,
            watchdog=False,
            received_s=time.perf_counter(),
        )

    def set_voltages(self, sequence: int, volts: Sequence[float]) -> None:
        volts = np.asarray(volts, dtype=float)
        if volts.shape != (self.model.n_inputs,):
            raise OptionError(
                f"{self.info.variant} takes {self.model.n_inputs} voltage(s), got {volts.shape}"
            )
        self._applied = self.sensors.dac(volts)
        self._command_sequence = int(sequence)

    def stop(self) -> None:
        if self._started:
            self._applied = np.zeros(self.model.n_inputs)
        self._started = False

    def attachments(self) -> list[Attachment]:
        text = yaml.safe_dump(
            to_document(self.params), sort_keys=False, allow_unicode=True, width=100
        )
        return [Attachment(PLANT_ATTACHMENT, "application/yaml", text.encode())]

    @property
    def state(self) -> np.ndarray:
        """The plant state now (for tests and the serial emulator)."""
        return self._x.copy()
