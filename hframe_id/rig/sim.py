"""The ``sim`` rig: any model and parameter file as the plant, measured by the thesis's sensors.

The plant is stepped once per sample by the same fixed-step RK4 (same substeps, same Coulomb
smoothing) as ``hframe_id.simulation.open_loop.simulate``, and measured by the same sensor
models, drawing random numbers in the same order as ``hframe_id.recordings.simulated``: a run
with a given seed and inputs equals ``simulate_recording`` with that seed and inputs (to float
round-off). Paced in real time by default (``read()`` returns at the sample's wall time, like
hardware); ``paced=False`` runs as fast as it can (making datasets).

Given a ``Plant`` (``hframe_id.rig.plant``, docs/realistic-rig.md) instead of a parameter set,
the rig is the realistic one: the plant's own dynamics (stick-slip with a Stribeck curve,
current-limited amplifier, position-dependent belt stiffness), its actuation delay and its
sensor latencies; it then equals ``hframe_id.rig.realistic.record_realistic``.
"""

from __future__ import annotations

import time
from collections import deque
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
from hframe_id.rig.plant import PLANT_FILE_ATTACHMENT, REFERENCE_ATTACHMENT, Plant, plant_text
from hframe_id.simulation.integrators import rk4_step, stable_substeps
from hframe_id.simulation.realistic import realistic_step

#: Limit switch positions [m] of the simulated rigs (the thesis gives no travel; these keep
#: every shipped experiment clear of them with margin).
DEFAULT_TRAVEL_M = {"x": (-0.25, 0.25), "y": (-0.25, 0.25)}


class SimRig(Rig):
    """A simulated rig.

    Parameters
    ----------
    params : plant parameters (any model variant, the model's own smooth friction), or a
        realistic ``Plant``.
    sensors : sensor models (default: the thesis's rig, section 1.1).
    seed : seeds the encoder power-up phases and the laser noise.
    sample_period_s : sample period [s].
    paced : pace samples in real time (True) or run unpaced (False).
    travel_m : per axis, (min, max) limit switch positions [m].
    n_substeps : RK4 substeps per sample (default: ``stable_substeps``).
    """

    def __init__(
        self,
        params: ParameterSet | Plant,
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
        self.plant = params if isinstance(params, Plant) else None
        self.params = params.parameters if isinstance(params, Plant) else params
        self.sensors = sensors or SensorModel()
        self.seed = int(seed)
        self.paced = bool(paced)
        if self.plant is None:
            self.model = build_model(self.params.variant)
            self._p = self.model.parameter_vector(self.params.values)
            self._s = ca.DM(self.model.options.smoothing)
            n = n_substeps or stable_substeps(self.model, self._p, sample_period_s)
            self._step = rk4_step(self.model, int(n), float(sample_period_s))
        else:
            self.model, self._p = self.plant.model, self.plant.p
            self._s = ca.DM(self.plant.constants.vector())
            n = n_substeps or self.plant.substeps(sample_period_s)
            self._step = realistic_step(self.model, int(n), float(sample_period_s))
        params = self.params
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
                **(self._plant_metadata() if self.plant else {}),
            },
        )
        self.stats = LinkStats()
        self._started = False

    def start(self) -> None:
        """Start sampling from rest: state zero, outputs at 0 V, the noise generator reseeded."""
        self._rng = np.random.default_rng(self.seed)
        self._readout = SensorReadout(self.sensors, self.info.outputs, self._rng)
        self._x = np.zeros(self.model.n_states)
        self._applied = np.zeros(self.model.n_inputs)
        delay, (encoder_lag, laser_lag) = self._delays()
        self._pending = deque([self._applied] * delay)
        self._outputs = deque(maxlen=max(encoder_lag, laser_lag) + 1)
        self._output_now = self._applied
        self._command_sequence: int | None = None
        self._k = 0
        self._t0 = time.perf_counter()
        self._started = True

    def read(self) -> RigSample:
        """The next sample: the plant advanced one period (paced to real time if ``paced``)."""
        if not self._started:
            raise RigFault("sim rig: read() before start()")
        k = self._k
        if k > 0:
            self._pending.append(self._applied)
            self._output_now = self._pending.popleft()
            self._x = np.asarray(self._step(self._x, self._output_now, self._p, self._s)).ravel()
        if self.paced:
            delay = self._t0 + k * self.info.sample_period_s - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
        y = np.asarray(self.model.output_map(self._x, self._output_now, self._p)).ravel()
        counts, laser, valid = self._readout.read(self._lagged(y))
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
            applied_v=tuple(float(v) for v in self._output_now),
            command_sequence=self._command_sequence,
            watchdog=False,
            received_s=time.perf_counter(),
        )

    def set_voltages(self, sequence: int, volts: Sequence[float]) -> None:
        """Command ``volts`` [V] (one per input, through the DAC) from sample ``sequence`` on."""
        volts = np.asarray(volts, dtype=float)
        if volts.shape != (self.model.n_inputs,):
            raise OptionError(
                f"{self.info.variant} takes {self.model.n_inputs} voltage(s), got {volts.shape}"
            )
        self._applied = self.sensors.dac(volts)
        self._command_sequence = int(sequence)

    def stop(self) -> None:
        """Set the outputs to 0 V and stop sampling."""
        if self._started:
            self._applied = np.zeros(self.model.n_inputs)
        self._started = False

    def attachments(self) -> list[Attachment]:
        """The plant parameter file (and, for a realistic plant, its plant file and reference)."""
        text = yaml.safe_dump(
            to_document(self.params), sort_keys=False, allow_unicode=True, width=100
        )
        files = [Attachment(PLANT_ATTACHMENT, "application/yaml", text.encode())]
        if self.plant is not None:
            files.append(
                Attachment(
                    PLANT_FILE_ATTACHMENT, "application/yaml", plant_text(self.plant).encode()
                )
            )
            reference = yaml.safe_dump(
                to_document(self.plant.reference()), sort_keys=False, allow_unicode=True, width=100
            )
            files.append(Attachment(REFERENCE_ATTACHMENT, "application/yaml", reference.encode()))
        return files

    def _delays(self) -> tuple[int, tuple[int, int]]:
        """Actuation delay and (encoder, laser) latency [samples]; 0 for a parameter set."""
        if self.plant is None:
            return 0, (0, 0)
        plant = self.plant
        return plant.actuation_delay_samples, (
            plant.encoder_latency_samples,
            plant.laser_latency_samples,
        )

    def _lagged(self, y: np.ndarray) -> np.ndarray:
        """The outputs the sensors see now: each channel its latency old (rest before t_0)."""
        _, (encoder_lag, laser_lag) = self._delays()
        if not self._outputs:
            self._outputs.extend([y] * self._outputs.maxlen)
        self._outputs.append(y)
        seen = y.copy()
        readout = self._readout
        seen[readout.encoder_columns] = self._outputs[-1 - encoder_lag][readout.encoder_columns]
        seen[readout.laser_columns] = self._outputs[-1 - laser_lag][readout.laser_columns]
        return seen

    def _plant_metadata(self) -> dict:
        plant = self.plant
        meta: dict = {"plant": plant.path.name if plant.path else plant.title}
        if plant.seed is not None:
            meta["plant_seed"] = plant.seed
        return meta

    @property
    def state(self) -> np.ndarray:
        """The plant state now (for tests and the serial emulator)."""
        return self._x.copy()
