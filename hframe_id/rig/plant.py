"""Plant files: the realistic sim rig's plant, richer than any model the fitter assumes.

A plant file (YAML, docs/realistic-rig.md) holds a base parameter set of any variant (embedded
as a whole parameter-file document, or the path of one relative to the plant file) plus the
effects the fitted models leave out, every value with its unit in its key::

    format_version: "1.0"
    kind: plant
    title: ...
    source: ...
    notes: ...                          # optional
    seed: 7                             # optional: the seed that drew it (realistic_plant)
    parameters: {format_version: ..., model: hframe-20, ..., parameters: {...}}
    position_dependent_stiffness: true  # section 4.6, needs l_3..l_8 in the parameters
    friction:
      stick_band_linear [m/s]: 0.000194
      stick_band_angular [rad/s]: 0.01
      static_to_coulomb_ratio [-]: 1.3
      stribeck_velocity_linear [m/s]: 0.005
      stribeck_velocity_angular [rad/s]: 0.25
      stick_time_constant [s]: 0.0002
    amplifier:
      current_limit [A]: 6.0            # null: no limit
    timing:
      actuation_delay [samples]: 1
      encoder_latency [samples]: 0
      laser_latency [samples]: 2

Loading is strict: an unknown, missing or out-of-range key is a ``ParameterFileError`` naming
the file and the field.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hframe_id.atomic import replace_atomically
from hframe_id.documents import load_yaml, read_text
from hframe_id.errors import HframeIdError, ModelError, ParameterFileError, shown
from hframe_id.models import Model, ModelOptions, build_model
from hframe_id.parameters import ParameterSet, load_parameter_file
from hframe_id.parameters.files import check_header, suggest, to_document
from hframe_id.parameters.reduce import reduce_to_hframe8
from hframe_id.simulation.realistic import PlantConstants, realistic_substeps

FORMAT_VERSION = "1.0"
KIND = "plant"
#: Attachment of a realistic-rig recording holding its whole plant file (the base parameter
#: set alone stays in ``PLANT_ATTACHMENT``, so that ``Recording.truth`` is the base set).
PLANT_FILE_ATTACHMENT = "plant.yaml"
#: Attachment holding the reference answer of an hframe-8 fit: the section-4.1 reduction.
REFERENCE_ATTACHMENT = "plant-reference-hframe-8.yaml"

_HEADER = ("format_version", "kind", "title", "source", "parameters")
_OPTIONAL = ("notes", "seed", "position_dependent_stiffness", "friction", "amplifier", "timing")
_FRICTION = {
    "stick_band_linear [m/s]": "stick_band_linear_m_per_s",
    "stick_band_angular [rad/s]": "stick_band_angular_rad_per_s",
    "static_to_coulomb_ratio [-]": "static_to_coulomb_ratio",
    "stribeck_velocity_linear [m/s]": "stribeck_velocity_linear_m_per_s",
    "stribeck_velocity_angular [rad/s]": "stribeck_velocity_angular_rad_per_s",
    "stick_time_constant [s]": "stick_time_constant_s",
}
_AMPLIFIER = {"current_limit [A]": "current_limit_a"}
_TIMING = {
    "actuation_delay [samples]": "actuation_delay_samples",
    "encoder_latency [samples]": "encoder_latency_samples",
    "laser_latency [samples]": "laser_latency_samples",
}


@dataclass(frozen=True)
class Plant:
    """A realistic sim-rig plant (SI).

    Attributes
    ----------
    parameters : base parameter set (any variant); a recording's ``truth``.
    constants : friction-law and amplifier constants (``simulation.realistic``).
    position_dependent_stiffness : belt stiffness k0 l0 / (l0 + dl) (section 4.6, eq. 4.33-4.38).
    actuation_delay_samples : whole samples between a command and the amplifier output.
    encoder_latency_samples, laser_latency_samples : whole samples a reading lags the plant.
    title, source, notes : header text.
    seed : the seed ``realistic_plant`` drew the plant with (None: hand-written).
    path : the file it was read from.
    """

    parameters: ParameterSet
    constants: PlantConstants
    position_dependent_stiffness: bool = False
    actuation_delay_samples: int = 0
    encoder_latency_samples: int = 0
    laser_latency_samples: int = 0
    title: str = "realistic plant"
    source: str = "hframe-id realistic rig (docs/realistic-rig.md)"
    notes: str = ""
    seed: int | None = None
    path: Path | None = field(default=None, compare=False)

    def __post_init__(self) -> None:
        where = self.where()
        c = self.constants
        positive = [
            ("friction", k, n) for k, n in _FRICTION.items() if k != "static_to_coulomb_ratio [-]"
        ]
        for section, key, name in [
            *positive,
            ("amplifier", "current_limit [A]", "current_limit_a"),
        ]:
            value = getattr(c, name)
            if not (_is_number(value) and value > 0 and not math.isnan(value)):
                raise ParameterFileError(
                    f"{where}: {section}.{key} must be > 0, got {shown(value)}"
                )
            if math.isinf(value) and section != "amplifier":
                raise ParameterFileError(
                    f"{where}: {section}.{key} must be finite, got {shown(value)}"
                )
        ratio = c.static_to_coulomb_ratio
        if not (_is_number(ratio) and math.isfinite(ratio) and ratio >= 1):
            raise ParameterFileError(
                f"{where}: friction.static_to_coulomb_ratio [-] must be >= 1 (F_s >= F_c), "
                f"got {shown(ratio)}"
            )
        for key, name in _TIMING.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 100:
                raise ParameterFileError(
                    f"{where}: timing.{key} must be a whole number of samples in 0..100, "
                    f"got {shown(value)}"
                )
        try:
            self.model.parameter_vector(self.parameters.values)
        except ModelError as err:
            raise ParameterFileError(
                f"{where}: position_dependent_stiffness: {err} (belt lengths, section 4.6)"
            ) from None

    def where(self) -> str:
        """Where the plant comes from, for messages: the file, else ``<variant plant>``."""
        return str(self.path) if self.path else f"<{self.parameters.variant} plant>"

    @property
    def variant(self) -> str:
        """Model variant of the plant's parameters."""
        return self.parameters.variant

    @property
    def model(self) -> Model:
        """The base variant, with section 4.6's stiffness if the plant has it."""
        try:
            options = ModelOptions(position_dependent_stiffness=self.position_dependent_stiffness)
            return build_model(self.variant, options)
        except ModelError as err:
            raise ParameterFileError(
                f"{self.where()}: position_dependent_stiffness: {err}"
            ) from None

    @property
    def p(self) -> np.ndarray:
        """Parameter vector of ``model`` (SI)."""
        return self.model.parameter_vector(self.parameters.values)

    def substeps(self, sample_period_s: float) -> int:
        """RK4 substeps per sample (``realistic_substeps``)."""
        return realistic_substeps(self.model, self.p, sample_period_s, self.constants)

    def reference(self) -> ParameterSet:
        """The answer a fit of the fitted model should be compared with: for an hframe-20 plant
        its section-4.1 reduction to hframe-8, otherwise the base set itself."""
        if self.variant == "hframe-20":
            return reduce_to_hframe8(self.parameters)
        return self.parameters

    def with_parameters(self, parameters: ParameterSet, **changes: Any) -> Plant:
        """A copy with another base set (and other fields changed), not tied to a file."""
        return replace(self, parameters=parameters, path=None, **changes)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _section(doc: Mapping, name: str, keys: dict[str, str], where: str) -> dict[str, Any]:
    raw = doc.get(name, {})
    if not isinstance(raw, Mapping):
        raise ParameterFileError(f"{where}: {name!r} must be a mapping of 'name [unit]': value")
    for key in raw:
        if key not in keys:
            raise ParameterFileError(
                f"{where}: unknown key {name}.{shown(key)}{suggest(str(key), list(keys))}"
            )
    missing = [key for key in keys if key not in raw]
    if missing:
        raise ParameterFileError(f"{where}: missing key {name}.{missing[0]}")
    return {keys[key]: value for key, value in raw.items()}


def _embedded_parameters(raw: Any, folder: Path, where: str) -> ParameterSet:
    if isinstance(raw, str):
        return load_parameter_file(folder / raw)
    if not isinstance(raw, Mapping):
        raise ParameterFileError(
            f"{where}: 'parameters' must be a parameter-file document or the path of one"
        )
    with tempfile.TemporaryDirectory() as tmp:
        file = Path(tmp) / "parameters.yaml"
        file.write_text(yaml.safe_dump(dict(raw), sort_keys=False))
        try:
            params = load_parameter_file(file)
        except HframeIdError as err:
            raise ParameterFileError(str(err).replace(str(file), f"{where}[parameters]")) from None
    params.path = None
    return params


def plant_from_document(
    doc: Any, where: str, folder: Path = Path("."), path: Path | None = None
) -> Plant:
    """Validate a plant document (parsed YAML).

    Parameters
    ----------
    doc : the parsed YAML.
    where : how errors name it (a file, or a recording's attachment).
    folder : where a ``parameters`` path is relative to.
    path : the file it came from, if any.
    """
    check_header(doc, tuple(_HEADER), tuple(_OPTIONAL), where)
    if str(doc["format_version"]).split(".")[0] != FORMAT_VERSION.split(".")[0]:
        raise ParameterFileError(
            f"{where}: unknown format_version {shown(doc['format_version'])}; this hframe-id reads "
            f"{FORMAT_VERSION.split('.')[0]}.x plant files"
        )
    if doc["kind"] != KIND:
        raise ParameterFileError(f"{where}: kind must be {KIND!r}, got {shown(doc['kind'])}")
    seed = doc.get("seed")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int)):
        raise ParameterFileError(f"{where}: seed must be an integer or null, got {shown(seed)}")
    stiffness = doc.get("position_dependent_stiffness", False)
    if not isinstance(stiffness, bool):
        raise ParameterFileError(
            f"{where}: position_dependent_stiffness must be true or false, got {shown(stiffness)}"
        )
    friction = _section(doc, "friction", _FRICTION, where)
    amplifier = _section(doc, "amplifier", _AMPLIFIER, where)
    if amplifier["current_limit_a"] is None:
        amplifier["current_limit_a"] = math.inf
    timing = _section(doc, "timing", _TIMING, where)
    return Plant(
        parameters=_embedded_parameters(doc["parameters"], folder, where),
        constants=PlantConstants(**friction, **amplifier),
        position_dependent_stiffness=stiffness,
        title=str(doc["title"]),
        source=str(doc["source"]),
        notes=str(doc.get("notes", "")),
        seed=seed,
        path=path,
        **timing,
    )


def load_plant_file(path: str | os.PathLike) -> Plant:
    """Load and validate a plant file (``ParameterFileError`` naming the file and field)."""
    path = Path(path)
    try:
        text = read_text(path, "plant file", ParameterFileError)
    except FileNotFoundError:
        raise ParameterFileError(f"{path}: no such plant file") from None
    except OSError as err:
        raise ParameterFileError(f"{path}: cannot read ({err.strerror})") from None
    doc = load_yaml(text, str(path), ParameterFileError)
    return plant_from_document(doc, str(path), path.parent, path)


def plant_document(plant: Plant) -> dict[str, Any]:
    """The YAML document of a plant (parameters embedded, so the file stands alone)."""
    c = plant.constants
    doc: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "kind": KIND,
        "title": plant.title,
        "source": plant.source,
    }
    if plant.notes:
        doc["notes"] = plant.notes
    if plant.seed is not None:
        doc["seed"] = plant.seed
    doc["parameters"] = to_document(plant.parameters)
    doc["position_dependent_stiffness"] = plant.position_dependent_stiffness
    doc["friction"] = {key: float(getattr(c, name)) for key, name in _FRICTION.items()}
    limit = c.current_limit_a
    doc["amplifier"] = {"current_limit [A]": None if math.isinf(limit) else float(limit)}
    doc["timing"] = {key: getattr(plant, name) for key, name in _TIMING.items()}
    return doc


def plant_text(plant: Plant) -> str:
    """A plant file's text (YAML)."""
    return yaml.safe_dump(plant_document(plant), sort_keys=False, allow_unicode=True, width=100)


def save_plant_file(plant: Plant, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write a plant file atomically; refuse to replace one unless ``overwrite``."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise ParameterFileError(f"{path}: exists already; refusing to overwrite it")
    path.parent.mkdir(parents=True, exist_ok=True)
    return replace_atomically(path, plant_text(plant))


def recording_plant(path: str | os.PathLike) -> Plant | None:
    """The plant a realistic-rig recording was made with (its ``plant.yaml``), else None."""
    from hframe_id.recordings.reader import read_log

    log = read_log(path)
    attachment = log.attachments.get(PLANT_FILE_ATTACHMENT)
    if attachment is None:
        return None
    where = f"{path}[{PLANT_FILE_ATTACHMENT}]"
    try:
        text = attachment.data.decode()
    except UnicodeDecodeError as err:
        raise ParameterFileError(f"{where}: unreadable ({err})") from None
    doc = load_yaml(text, where, ParameterFileError)
    return plant_from_document(doc, where, path=Path(where))
