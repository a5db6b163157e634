"""A fit's versioned parameter file (``fitting.output``): its id, never an overwrite, and no
file for a failed fit."""

import hashlib
from datetime import UTC, datetime

from hframe_id.fitting.output import make_fit_id, unused_fit_id, write_parameter_file

WHEN = datetime(2026, 11, 26, 6, 30, 5, tzinfo=UTC)


def test_the_fit_id_is_variant_time_and_a_digest_of_the_data_in_any_order():
    data = hashlib.sha256(b"ab").hexdigest()[:6]
    assert make_fit_id("hframe-8", ["b", "a"], WHEN) == f"hframe-8-20261126T063005Z-{data}"
    assert make_fit_id("hframe-8", ["a", "b"], WHEN) == make_fit_id("hframe-8", ["b", "a"], WHEN)
    assert make_fit_id("hframe-8", ["a"], WHEN) != make_fit_id("hframe-8", ["a", "b"], WHEN)


def test_an_id_in_use_by_any_output_gets_the_next_number(tmp_path):
    assert unused_fit_id(tmp_path, "fit") == "fit"
    (tmp_path / "fit.yaml").write_text("")
    (tmp_path / "fit-2-plots").mkdir()
    (tmp_path / "fit-3-report.md").write_text("")
    assert unused_fit_id(tmp_path, "fit") == "fit-4"


def test_a_failed_fit_gets_an_id_and_no_parameter_file(small_result, tmp_path):
    data = tmp_path / "step.mcap"
    data.write_bytes(b"a recording")
    out = tmp_path / "fits"
    out.mkdir()
    failed = small_result(success=False, message="did not converge")
    fit_id, path = write_parameter_file(failed, [], [data], None, out, WHEN)
    digest = hashlib.sha256(hashlib.sha256(b"a recording").hexdigest().encode()).hexdigest()
    assert (fit_id, path) == (f"hframe-8-20261126T063005Z-{digest[:6]}", None)
    assert list(out.iterdir()) == []
