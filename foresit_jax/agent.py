"""Deprecated: the `Agent` class, kept for one release (0.3.0), and the acting records'
old home.

Acting is now plain functions over a record: `foresit_jax.networks.build(config)` gives the
`Networks` (the modules and the Config) and `foresit_jax.rollout` acts with them (`start`,
`act`, `act_window`, `rollout`); the window's critic (`Agent.critic`, removed) is
`foresit_jax.train.window_critic`.
`Agent(config)` still works and warns; its methods call those functions. CHANGELOG.md says
what moved where.
"""

from __future__ import annotations

import warnings

from foresit_jax import rollout as _rollout
from foresit_jax.networks import build
from foresit_jax.rollout import (  # noqa: F401 (the records' old home: re-exported)
    ActOptions, ActorState, AgentParams, BoundEnv, EpisodeStats, StepInputs, Trajectory, WindowEnd, ended_episodes,
    episode_stats,
)


class Agent:
    """Deprecated (0.2 -> 0.3): `nets = networks.build(config)` and the functions of
    `foresit_jax.rollout` (`rollout.act(nets, ...)` for `agent.act(...)`)."""

    def __init__(self, config):
        warnings.warn(
            "foresit_jax.agent.Agent is deprecated and goes in 0.3: use nets = foresit_jax.networks.build(config) "
            "and the functions of foresit_jax.rollout (rollout.act(nets, ...), rollout.rollout(nets, ...)); "
            "see CHANGELOG.md",
            FutureWarning,
            stacklevel=2,
        )
        self.networks = build(config)
        self.config, self.model, self.imagination_net = config, self.networks.model, self.networks.imagination_net
        self.method, self.imagination_variant = config.pieces, config.pieces.imagination_variant

    def init(self, key, obs):
        return self.networks.init(key, obs)

    def imagine(self, w_params, s_0, goal):
        return self.networks.imagine(w_params, s_0, goal)

    def start(self, key, env, num_lanes, memory_size=0, tracker=None, reset_keys=None):
        return _rollout.start(self.networks, key, env, num_lanes, memory_size, tracker, reset_keys)

    def act(self, acting, env, actor, key, num_steps, options=ActOptions()):
        return _rollout.act(self.networks, acting, env, actor, key, num_steps, options)

    def rollout(self, acting, env, key, num_steps, greedy=False, record_inputs=False, num_lanes=None,
                reset_keys=None):  # fmt: skip
        options = ActOptions(greedy=greedy, whole_episodes=True, record_inputs=record_inputs)
        return _rollout.rollout(self.networks, acting, env, key, num_steps, options, num_lanes, reset_keys)
