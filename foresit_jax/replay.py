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
from foresit_jax.lstm import LSTMCarry, lstm_step, reset_carry, with_transposed_recurrent_kernel
from foresit_jax.networks import ActorCritic


def replay(agent: Agent, params, traj: Trajectory, initial_carry: LSTMCarry):
    """(states `[T, B, H]`, logits `[T, B, A]`) of a window recorded with
    `record_inputs=True`, recomputed as a differentiable function of `params`.

    initial_carry: the LSTM carry `(c, h)` `[B, H]` each before the window's first step
    (`ActorState.lstm` at the window's start). The carry is zeroed before every step that
    begins an episode (`traj.episode_step == 0`), as acting does.
    """
    if traj.inputs is None:
        raise ValueError("replay needs a trajectory recorded with record_inputs=True")
    inputs = jax.lax.stop_gradient(traj.inputs)
    num_steps, num_lanes = traj.actions.shape
    size = num_steps * num_lanes

    def flat(x):  # [T, B, ...] -> [T * B, ...]
        return x.reshape((size,) + x.shape[2:])

    kernels = agent.lstm_kernels(params)
    encoder_imagined = None if inputs.encoder_imagined is None else flat(inputs.encoder_imagined)
    gates = agent.input_gates(
        params, jax.tree.map(flat, inputs.obs), flat(inputs.prev_action_probs), kernels, encoder_imagined
    )  # fmt: skip
    gates = gates.reshape(num_steps, num_lanes, -1)  # [T, B, 4H]: one matmul over the whole segment
    kernels = with_transposed_recurrent_kernel(kernels)
    first = traj.episode_step == 0  # [T, B]

    def step(carry, xs):
        input_gates, imagined, first_t = xs
        carry, s_t = lstm_step(kernels, reset_carry(first_t, carry), input_gates)
        logits = agent.model.apply(params, s_t, imagined, method=ActorCritic.policy_logits)
        return carry, (s_t, logits)

    _, (states, logits) = jax.lax.scan(step, initial_carry, (gates, inputs.imagined, first))
    return states, logits


def replayed(agent: Agent, params, traj: Trajectory, initial_carry: LSTMCarry) -> Trajectory:
    """`traj` with states and logits recomputed by `replay` (differentiable in params)."""
    states, logits = replay(agent, params, traj, initial_carry)
    return traj._replace(states=states, logits=logits)

