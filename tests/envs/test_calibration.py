"""Calibration of the test split: the task is hard for a random policy, has long
trajectories in about half of the episodes, and is longer in bigger rooms."""

import jax
import numpy as np
import pytest

from envs import catalog as C


@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit", "priors_kit"])
def test_optimal_lengths_of_start_states(request, kit_name):
    """4096 resets: 40-80% of the episodes need >= 5 actions; the mean optimal length rises
    bathroom < bedroom < kitchen < living room."""
    kit = request.getfixturevalue(kit_name)
    _, states = kit.reset_batch(jax.random.split(jax.random.key(0), 4096))
    length, room = states.optimal_length, states.room_type
    long_fraction = np.mean(length >= 5)
    assert 0.4 <= long_fraction <= 0.8, long_fraction
    mean = {r: length[room == r].mean() for r in range(4)}
    assert all((room == r).sum() > 500 for r in range(4))
    assert mean[C.BATHROOM] < mean[C.BEDROOM] < mean[C.KITCHEN] < mean[C.LIVING_ROOM], mean
    assert length.min() >= 2


@pytest.mark.parametrize("kit_name", ["savn_kit", "org_kit", "priors_kit"])
def test_uniform_random_policy_rarely_succeeds(request, kit_name):
    """2048 episodes of a uniformly random policy (first episode of each lane): SR <= 10%."""
    kit = request.getfixturevalue(kit_name)
    success, _, _, alive = kit.first_episodes(jax.random.split(jax.random.key(1), 2048), np.zeros(2048, bool))
    assert alive.sum() <= 2  # all but (almost) none chose Done within the 80 steps
    sr = success.mean()
    assert 0.0 < sr <= 0.10, sr
