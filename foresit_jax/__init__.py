"""foresit_jax: the ForeSIT agent (foresight sub-goal imagination) and its baselines in JAX."""

from foresit_jax import config, distributions, imagination, losses, networks
from foresit_jax.config import METHODS, PLANNED_METHODS, Config, MethodFlags, method_flags
from foresit_jax.imagination import (
    ReplayBuffer,
    SuccessTracker,
    add_imagination_noise,
    buffer_add,
    buffer_clear,
    buffer_init,
    buffer_is_full,
    imagination_loss,
    make_imagination_optimizer,
    noise_variance,
    random_imagination,
    success_rate,
    tracker_init,
    tracker_update,
    train_full_buffers,
    train_on_buffer,
)
from foresit_jax.losses import (
    a3c_loss,
    advantages_and_returns,
    discounted_returns,
    episode_discounts,
    generalized_advantage_estimation,
    masked_mean,
    smooth_l1,
)
from foresit_jax.networks import (
    ActorCritic,
    Critic,
    CriticOutput,
    Encoder,
    ImaginationNet,
    PolicyHead,
    ValueHead,
    initial_carry,
    last_step_attention,
    last_valid_index,
    reset_carry,
    select_subgoal,
    unroll,
)

__all__ = [
    "config", "distributions", "imagination", "losses", "networks",
    "METHODS", "PLANNED_METHODS", "Config", "MethodFlags", "method_flags",
    "ReplayBuffer", "SuccessTracker", "add_imagination_noise", "buffer_add", "buffer_clear",
    "buffer_init", "buffer_is_full", "imagination_loss", "make_imagination_optimizer",
    "noise_variance", "random_imagination", "success_rate", "tracker_init", "tracker_update",
    "train_full_buffers", "train_on_buffer",
    "a3c_loss", "advantages_and_returns", "discounted_returns", "episode_discounts",
    "generalized_advantage_estimation", "masked_mean", "smooth_l1",
    "ActorCritic", "Critic", "CriticOutput", "Encoder", "ImaginationNet", "PolicyHead",
    "ValueHead", "initial_carry", "last_step_attention", "last_valid_index", "reset_carry",
    "select_subgoal", "unroll",
]
