"""The jackknife coverage study's counting (the fits themselves are the study's run)."""

import pytest

from studies.jackknife_coverage import holds, main


def test_holds_counts_intervals_over_seeds_and_parameters():
    seeds = [
        {"k_l": (1.0, 0.9, 1.1), "J_M1": (2.0, 1.0, 3.0)},
        {"k_l": (1.2, 1.15, 1.25), "J_M1": (2.5, 2.4, 2.6)},
    ]
    # k_l = 1.0 is in the first seed's interval only, J_M1 = 2.5 in both: 3 of 4.
    assert holds(seeds, {"k_l": 1.0, "J_M1": 2.5}) == pytest.approx(0.75)


def test_the_command_line_documents_itself(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--help"])
    assert stop.value.code == 0 and "--noise-seeds" in capsys.readouterr().out
