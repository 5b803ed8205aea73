"""Benchmarks and developer tools, beside the installed packages (not installed with them).

Run from the repository's root: `python -m benchmarks.bench_train`, `bench_env`,
`bench_learning`, `bench_devices` (speed and learning at equal budgets), `search_learner`
(how the quick preset's learner was chosen, docs/learner.md) and `trace_update` (the files and
lowered programs of one update, docs/design.md). They use `envs`, `foresit_jax` and
`experiments` as any user's code does.
"""
