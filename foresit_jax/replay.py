"""The replay gradient: re-run the agent's modules over a window's recorded inputs.

Acting runs without gradients and records, at every step, what the encoder and the policy
saw (`StepInputs`: observation, previous action probabilities, i_tau). The loss then
recomputes s_t and the logits from those inputs as a differentiable function of the
parameters, as PureJaxRL's `ppo_rnn.py` does in its `_loss_fn`. The environment's outputs
carry no gradient, so this is the same function of the parameters as the acting pass,
and its gradient equals differentiating through the acting scan (`gradient=
'through_rollout'`, the reference; tests/test_replay.py checks both agree).

What makes it fast: the encoder up to the LSTM's input gates has no recurrence, so it
runs once over all T x B steps of the window (a few large matmuls instead of T small
ones), and only the LSTM's recurrent step (`foresit_jax.lstm`) is sequential. Nothing
is reused from acting but the inputs: the replay recomputes every value, so it is right
for any parameters that are fixed over the window (several epochs over one window
included). It is NOT right where the parameters change inside a window (MAML's adapted
parameters): such methods declare `gradients = ('through_rollout',)` and `Config`
refuses `gradient='replay'` for them.
"""

from __future__ import annotations

import jax

from foresit_jax.agent import Agent, Trajectory
from foresit_jax.lstm import LSTMCarry
from foresit_jax.networks import ActorCritic


def replayed(agent: Agent, params, traj: Trajectory, initial_carry: LSTMCarry) -> Trajectory:
    """`traj` (recorded with `record_inputs=True`) with its states `[T, B, H]` and logits
    `[T, B, A]` recomputed as a differentiable function of `params`, in one `apply`
    (`ActorCritic.replay`).

    initial_carry: the LSTM carry `(c, h)` `[B, H]` each before the window's first step
    (`ActorState.lstm` at the window's start). The carry is zeroed before every step that
    begins an episode (`traj.episode_step == 0`), as acting does.
    """
    if traj.inputs is None:
        raise ValueError("replay needs a trajectory recorded with record_inputs=True")
    seen = jax.lax.stop_gradient(traj.inputs)
    states, logits = agent.model.apply(params, initial_carry, seen.obs, seen.prev_action_probs, seen.encoder_imagined,
                                       seen.imagined, traj.episode_step, method=ActorCritic.replay)  # fmt: skip
    return traj._replace(states=states, logits=logits)
