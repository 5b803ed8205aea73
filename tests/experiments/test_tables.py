"""experiments.reporting.tables, the one table writer, and the reports that use it."""

import pytest

from experiments.reporting import report, tables


def test_markdown_table_of_a_hand_written_table():
    rows = [["a3c", "12.50", 250], ["a3c+foresit", "n/a", 7]]
    assert tables.markdown_table(rows, ["method", "SR", "episodes"]) == (
        "| method | SR | episodes |\n|---|---|---|\n| a3c | 12.50 | 250 |\n| a3c+foresit | n/a | 7 |"
    )
    assert tables.markdown_table(rows, ["method", "SR", "episodes"], align="<>>") == (
        "| method      |    SR | episodes |\n"
        "|-------------|-------|----------|\n"
        "| a3c         | 12.50 |      250 |\n"
        "| a3c+foresit |   n/a |        7 |"
    )
    assert tables.markdown_table([], ["x"]) == "| x |\n|---|"
    with pytest.raises(ValueError, match="2 cells for 3 columns"):
        tables.markdown_table([["a", "b"]], ["x", "y", "z"])
    with pytest.raises(ValueError, match="align"):
        tables.markdown_table(rows, ["method", "SR", "episodes"], align="<>")


def test_reports_use_the_one_table_writer():
    results = {"overall": {"SPL": 10.0, "SR": 20.0, "SPL>=5": float("nan"), "SR>=5": None, "episodes": 4}}
    assert tables.results_markdown(results, "T", level=2) == (
        "## T\n\n| rooms | SPL | SR | SPL>=5 | SR>=5 | episodes |\n|---|---|---|---|---|---|\n"
        "| overall | 10.00 | 20.00 | n/a | n/a | 4 |\n"
    )
    rows = report.table(
        {
            "a3c": [{"overall": {"SPL": 1.0, "SR": 2.0, "SPL>=5": 3.0, "SR>=5": 4.0}}] * 2,
            "b": [{"overall": {"SPL": 1.0, "SR": 10.0, "SPL>=5": None, "SR>=5": 4.0}}],
        }
    )
    assert report.table_markdown(rows, "T1") == (
        "# T1\n\n| Method | SPL | SR | SPL>=5 | SR>=5 |\n|---|---|---|---|---|\n"
        "| a3c | 1.00 ± 0.00 [1.0, 1.0] | 2.00 ± 0.00 [2.0, 2.0] | 3.00 ± 0.00 [3.0, 3.0] | 4.00 ± 0.00 [4.0, 4.0] |\n"
        "| b | 1.00 | 10.00 | n/a | 4.00 |\n"
        "(mean ± sample std [95% confidence interval, Student t] over seeds)\n"
    )
