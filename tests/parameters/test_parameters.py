"""Parameter files: exact round trip, and every bad input a typed error naming file, key, value."""

from pathlib import Path

import pytest
import yaml

from hframe_id.errors import ParameterFileError
from hframe_id.models import parameter_specs
from hframe_id.parameters import ParameterSet, load_parameter_file, save_parameter_file

MODELS = Path(__file__).resolve().parents[2] / "models"
SHIPPED = sorted(MODELS.glob("*.yaml"))
HFRAME8 = MODELS / "hframe-8-table4.1.yaml"


def test_the_five_published_sets_are_shipped():
    names = {path.name for path in SHIPPED}
    assert {
        "one-axis-table2.1.yaml",
        "one-axis-table2.3.yaml",
        "hframe-20-table3.1.yaml",
        "hframe-8-table4.1.yaml",
        "hframe-8-table4.2.yaml",
    } <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_shipped_files_round_trip_exactly(path, tmp_path):
    original = load_parameter_file(path)
    assert original.references and original.source.startswith(("Sollmann 2007", "Janot"))
    first = save_parameter_file(original, tmp_path / "a.yaml")
    again = load_parameter_file(first)
    assert again.values == original.values  # exact float equality
    for field in ("variant", "title", "source", "references", "notes"):
        assert getattr(again, field) == getattr(original, field)
    second = save_parameter_file(again, tmp_path / "b.yaml")
    assert first.read_bytes() == second.read_bytes()


def test_round_trip_is_exact_for_awkward_floats_and_optional_header(tmp_path):
    base = load_parameter_file(HFRAME8)
    values = dict(base.values)
    # values whose decimal form is long: 1/3, a reduced stiffness, a tiny inertia, l-lengths
    values.update(k_l=13167.019564918799, b_cart=1 / 3, J_M1=1.1200000000000001e-4, l_l0=1.9)
    params = ParameterSet(
        "hframe-8",
        values,
        "title: with a colon",
        "fit 'x' of \"y\"",
        references=["a", "b"],
        notes="line one\nline two",
        provenance={"id": "fit-1", "data": ["4V_xmotion.mcap"], "cost": 1.5e-3},
        uncertainty={"k_l": {"std": 12.0}},
    )
    path = save_parameter_file(params, tmp_path / "fit.yaml")
    loaded = load_parameter_file(path)
    assert loaded.values == values
    for field in ("title", "source", "references", "notes", "provenance", "uncertainty"):
        assert getattr(loaded, field) == getattr(params, field)


def test_save_refuses_to_overwrite(tmp_path):
    params = load_parameter_file(HFRAME8)
    path = save_parameter_file(params, tmp_path / "a.yaml")
    before = path.read_bytes()
    changed = params.replace_values(k_l=1.0)
    with pytest.raises(ParameterFileError, match="exists already"):
        save_parameter_file(changed, path)
    assert path.read_bytes() == before
    save_parameter_file(changed, path, overwrite=True)
    assert load_parameter_file(path).values["k_l"] == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.yaml"]  # no temporary files left


# --- bad input ---------------------------------------------------------------------------------


def _write(tmp_path, edit, source=HFRAME8, name="bad.yaml"):
    """A copy of a shipped file with ``edit(doc)`` applied to its YAML document."""
    doc = yaml.safe_load(source.read_text())
    edit(doc)
    path = tmp_path / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def _expect(path, *fragments, variant=None, one_line=True):
    """Loading fails with a ParameterFileError that names the file and every fragment."""
    with pytest.raises(ParameterFileError) as info:
        load_parameter_file(path, variant=variant)
    message = str(info.value)
    assert str(path) in message
    for fragment in fragments:
        assert fragment in message, (fragment, message)
    if one_line:
        assert "\n" not in message  # one line for the command line
    return message


def _set(key, value):
    def edit(doc):
        doc["parameters"][key] = value

    return edit


def test_unknown_parameter_key_suggests_the_nearest(tmp_path):
    def edit(doc):
        doc["parameters"]["k_ll [N/m]"] = doc["parameters"].pop("k_l [N/m]")

    # The value is not repeated for an unknown key: the key itself is what is wrong.
    _expect(_write(tmp_path, edit), "'k_ll [N/m]'", "did you mean 'k_l [N/m]'")


def test_parameter_with_wrong_unit_suggests_the_right_key(tmp_path):
    def edit(doc):
        doc["parameters"]["M_cart [g]"] = doc["parameters"].pop("M_cart [kg]")

    _expect(_write(tmp_path, edit), "'M_cart [g]'", "did you mean 'M_cart [kg]'")


def test_missing_parameter(tmp_path):
    def edit(doc):
        del doc["parameters"]["k_b [N/m]"]

    _expect(_write(tmp_path, edit), "missing parameter", "'k_b [N/m]'")


@pytest.mark.parametrize(
    ("key", "value", "shown"),
    [
        ("k_l [N/m]", float("nan"), "nan"),
        ("k_l [N/m]", float("inf"), "inf"),
        ("J_M1 [kg m^2]", float("-inf"), "-inf"),
        ("M_cart [kg]", 0.0, "0.0"),
        ("M_cart [kg]", -1.0412, "-1.0412"),
        ("k_b [N/m]", 0, "0"),
        ("b_bridge [N s/m]", -1.0, "-1.0"),
        ("r [m]", "0.0194 m", "'0.0194 m'"),
        ("K_t [N m/A]", True, "True"),
        ("R [ohm]", None, "None"),
    ],
)
def test_non_finite_non_positive_or_non_numeric_values(tmp_path, key, value, shown):
    _expect(_write(tmp_path, _set(key, value)), key, shown)


@pytest.mark.parametrize("key", ["tau_cM1 [N m]", "F_c_bridge [N]"])
def test_negative_coulomb_friction(tmp_path, key):
    message = _expect(_write(tmp_path, _set(key, -0.05)), key, "-0.05", ">= 0")
    assert "> 0," not in message


@pytest.mark.parametrize("key", ["tau_cM1 [N m]", "b_cart [N s/m]", "B_M2 [N m s/rad]"])
def test_zero_friction_is_allowed(tmp_path, key):
    """Friction, Coulomb and viscous, is nonnegative: zero is physical (a linear model's
    Coulomb terms, a well-lubricated rig)."""
    params = load_parameter_file(_write(tmp_path, _set(key, 0.0)))
    assert params.values[key.split(" ")[0]] == 0.0


def test_wrong_variant_for_the_caller(tmp_path):
    _expect(HFRAME8, "'hframe-8'", "'hframe-20' is needed", variant="hframe-20")


def test_unknown_model_variant_suggests_the_nearest(tmp_path):
    def edit(doc):
        doc["model"] = "hframe-9"

    _expect(_write(tmp_path, edit), "model", "'hframe-9'", "did you mean 'hframe-8'")


def test_parameters_of_another_variant(tmp_path):
    """An hframe-8 key in a file that says hframe-20 is unknown for that model."""

    def edit(doc):
        doc["model"] = "hframe-20"

    _expect(_write(tmp_path, edit), "unknown parameter key", "for model hframe-20")


@pytest.mark.parametrize("version", ["2.0", "0.9", 3])
def test_unknown_format_version(tmp_path, version):
    def edit(doc):
        doc["format_version"] = version

    _expect(_write(tmp_path, edit), "format_version", repr(version))


def test_malformed_format_version(tmp_path):
    def edit(doc):
        doc["format_version"] = "one"

    _expect(_write(tmp_path, edit), "format_version", "'one'")


def test_minor_format_versions_of_major_1_are_read(tmp_path):
    def edit(doc):
        doc["format_version"] = "1.3"

    assert load_parameter_file(_write(tmp_path, edit)).variant == "hframe-8"


@pytest.mark.parametrize(
    "text",
    [
        "format_version: '1.0'\nparameters: [unclosed\n",
        "a: b: c\n",
        "\tformat_version: 1\n",
    ],
)
def test_not_yaml(tmp_path, text):
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    _expect(path, "not valid YAML", one_line=False)


def test_not_yaml_error_is_one_line(tmp_path):
    path = tmp_path / "broken.yaml"
    path.write_text("a: b: c\n")
    _expect(path, "not valid YAML")


@pytest.mark.parametrize("text", ["", "- 1\n- 2\n", "just a string\n"])
def test_yaml_that_is_not_a_mapping(tmp_path, text):
    path = tmp_path / "list.yaml"
    path.write_text(text)
    _expect(path, "expected a YAML mapping")


def test_unknown_header_key_suggests_the_nearest(tmp_path):
    def edit(doc):
        doc["titel"] = doc.pop("title")

    _expect(_write(tmp_path, edit), "unknown header key", "'titel'", "did you mean 'title'")


@pytest.mark.parametrize("key", ["format_version", "model", "title", "source", "parameters"])
def test_missing_header_key(tmp_path, key):
    def edit(doc):
        del doc[key]

    _expect(_write(tmp_path, edit), "missing header key", repr(key))


def test_parameters_must_be_a_mapping(tmp_path):
    def edit(doc):
        doc["parameters"] = [1, 2]

    _expect(_write(tmp_path, edit), "'parameters' must be a mapping")


def test_missing_file(tmp_path):
    _expect(tmp_path / "nope.yaml", "no such parameter file")


def test_parameter_set_validates_values_in_code():
    base = load_parameter_file(HFRAME8)
    with pytest.raises(ParameterFileError, match="k_l \\[N/m\\] must be > 0, got -1.0"):
        base.replace_values(k_l=-1.0)
    with pytest.raises(ParameterFileError, match="unknown parameter 'k_ll'.*did you mean 'k_l'"):
        ParameterSet("hframe-8", {**base.values, "k_ll": 1.0}, "t", "s")


@pytest.mark.parametrize("variant", ["one-axis", "hframe-20", "hframe-8"])
def test_every_key_has_a_unit_and_a_description(variant):
    for spec in parameter_specs(variant):
        assert spec.key == f"{spec.name} [{spec.unit}]"
        assert spec.unit and spec.description
