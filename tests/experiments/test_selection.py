"""experiments.running.selection: which model is kept, and which keys validation and test use."""

import numpy as np

from experiments.running import selection


def test_the_best_validation_sr_is_kept_and_the_later_model_on_ties():
    best = selection.Selection()
    kept = [
        best.offer(sr, update, f"params@{update}")
        for update, sr in ((1, 10.0), (2, 30.0), (3, 20.0), (4, 30.0), (5, 29.9))
    ]
    assert kept == [True, True, False, True, False]
    assert (best.sr, best.update, best.params) == (30.0, 4, "params@4")
    # A first validation at SR 0 is kept (nothing before it), as train's resume replays it.
    zero = selection.Selection()
    assert zero.offer(0.0, 7) and zero.update == 7


def test_validation_test_and_training_keys_are_distinct():
    seeds = range(100)
    keys = [
        np.asarray(k).tobytes()
        for s in seeds
        for k in (selection.run_key(s), selection.validation_key(s), selection.test_key(s))
    ]
    assert len(set(keys)) == len(keys)  # no run validates or tests on another's (or its own training) draws
