"""Pure functions the studies use over the library: the probes of i_tau (`probes`) and the
C-VAE comparison (`cvae`), kept out of foresit_jax, whose face is the agent. No CLI, files
or logging here: the programs (experiments.probe, experiments.failures,
experiments.cvae_compare) and the layers above (running/, reporting/) do those; this
package imports nothing else of experiments (tests/structure/test_layering.py)."""
