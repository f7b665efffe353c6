"""The report's placing of E2 against the paper: computed from the figures, never typed."""

from __future__ import annotations

from skeye.validate.report import where_it_lands


def test_below_between_and_above_the_papers_figures() -> None:
    below = where_it_lands(0.0124, 0.064)
    assert "standard deviation (1.24 cm) lies below the paper's simulation" in below
    assert "maximum (6.40 cm) lies below the paper's simulation" in below
    between = where_it_lands(0.030, 0.20)
    assert between.count("between the paper's simulation and its real flight") == 2
    above = where_it_lands(0.05, 0.30)
    assert above.count("above the paper's real flight") == 2
    assert "simulation 2.49 cm, real flight 3.8 cm" in above
    assert "simulation 13.27 cm, real flight 23.0 cm" in above
