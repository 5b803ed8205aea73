"""Moved to `experiments.errors` (a leaf that experiments/reporting imports too: the layers
import one way only, tests/test_layering.py); kept here for the imports of before."""

from experiments.errors import UserError, fail, os_message, run_cli  # noqa: F401
