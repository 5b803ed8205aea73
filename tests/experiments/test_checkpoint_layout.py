"""A checkpoint written before 0.4.0, whose lanes' state (`ActorState`) held its fields flat,
restores into today's records, where the agent's carry and imagination's are nested
(`experiments.running.checkpoint`, `FLAT_ACTOR_FIELDS`): a run resumed across the release
loses nothing."""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import numpy as np
import pytest
import train_helpers as H

from experiments.running import checkpoint


class FlatActorState(NamedTuple):  # ActorState as 0.3.x wrote it
    env_state: Any
    obs: Any
    lstm: Any
    prev_probs: Any
    imagined: Any
    s_0: Any
    episode_step: Any
    memory: Any
    tracker: Any


@pytest.mark.slow  # the tiny Trainer's init and two checkpoints: about 10 s on a quiet machine
def test_a_checkpoint_with_the_flat_lanes_of_0_3_restores_into_the_nested_ones(tmp_path):
    config = H.tiny_config("a3c+foresit", num_lanes=2)
    state = H.jitted_init(config)(jax.random.PRNGKey(0))
    # Distinct values in every field, so that a field read into another would show.
    leaves, treedef = jax.tree.flatten(state)
    state = jax.tree.unflatten(treedef, [np.asarray(x) + i if x.dtype != bool else x for i, x in enumerate(leaves)])
    flat = FlatActorState(**checkpoint._flat_actor(state.actor))
    old = state._replace(actor=flat)
    manager = checkpoint.checkpoint_manager(tmp_path / "checkpoints", 2)
    checkpoint.save(manager, 1, {"states": old})
    manager.wait_until_finished()
    restored = checkpoint.restore(manager, 1, {"states": state})["states"]
    assert type(restored.actor) is type(state.actor) and type(restored.actor.agent) is type(state.actor.agent)
    H.assert_trees_bitwise_equal(restored, state)
    # and today's layout restores as itself
    checkpoint.save(manager, 2, {"states": state})
    manager.wait_until_finished()
    H.assert_trees_bitwise_equal(checkpoint.restore(manager, 2, {"states": state})["states"], state)
