"""experiments.reporting.report: a sweep's pairs, seed by seed and per path-length bucket,
against hand computations."""

import numpy as np

from experiments.reporting import report


def test_sweep_pairs_every_method_with_the_first_seed_by_seed():
    result = lambda sr, spl: {"overall": {"SR": sr, "SPL": spl}}  # noqa: E731
    md = report.paired_markdown(
        {
            "a3c": [result(1.0, 0.0), result(2.0, 0.0), result(3.0, 0.0)],
            "b": [result(2.0, 1.0), result(4.0, 1.0), result(5.0, 1.0)],
        }
    )
    # SR differences 1, 2, 2: mean 5/3, t = 5 with 2 dof, p = 1 - 5 / sqrt(27) = 0.038,
    # interval 5/3 -+ 4.303 / 3; SPL differences all 1: no spread, no p.
    assert (
        "| b - a3c | +1.67 [+0.2, +3.1] | 0.038 | holds | +1.00 [+1.0, +1.0] | n/a | cannot tell at this budget |" in md
    )


def test_a_sweeps_table_pairs_each_path_length_bucket_over_seeds():
    """table1.md's section by L^g, against a hand computation: per bucket the mean ± std
    of each method, the mean seed-by-seed difference with its Student-t interval (scipy),
    the test episodes of the first method's seeds; an empty bucket (null) is n/a."""
    from scipy import stats as scipy_stats

    sr = {"a3c": [[60.0, 20.0], [50.0, 30.0], [70.0, 10.0]], "a3c+critic": [[55.0, 30.0], [51.0, 33.0], [60.0, 18.0]]}

    def seed(rates):
        by_length = {
            "1-4": {"SR": rates[0], "SPL": rates[0] / 2, "episodes": 40},
            ">=5": {"SR": rates[1], "SPL": rates[1] / 4, "episodes": 60},
            ">=20": {"SR": None, "SPL": None, "episodes": 0},
        }
        return {"selected": {"by_length": by_length}}

    results = {m: [seed(r) for r in per_seed] for m, per_seed in sr.items()}
    md = report.by_length_markdown(results)
    row = {
        line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
        for line in md.split("### a3c+critic - a3c")[1].splitlines()
        if line.startswith("| ")
    }
    for i, bucket in enumerate(("1-4", ">=5")):
        d = np.array(sr["a3c+critic"])[:, i] - np.array(sr["a3c"])[:, i]
        half = scipy_stats.t.ppf(0.975, 2) * d.std(ddof=1) / np.sqrt(3)
        assert row[bucket][:2] == [
            "120" if i == 0 else "180",
            f"{d.mean():+.1f} [{d.mean() - half:+.1f}, {d.mean() + half:+.1f}]",
        ]
        x = np.array(sr["a3c"])[:, i]
        assert f"| {bucket} | {x.mean():.1f} ± {x.std(ddof=1):.1f} / {x.mean() / (2 if i == 0 else 4):.1f}" in md
    assert row[">=20"][:2] == ["0", "n/a"] and "| >=20 | n/a / n/a | n/a / n/a |" in md
    assert report.by_length_markdown({"a3c": results["a3c"]}) == ""  # nothing to pair
