"""A3C + ForeSIT in one file, PureJaxRL style: the whole algorithm, top to bottom.

"Learning for Visual Navigation by Imagining Success" (arXiv:2103.00446) on GridNav-v0.
This is what foresit_jax's `Trainer` computes for `a3c+foresit` (packed windows, the
replay gradient), without its speed machinery (split LSTM, fused layers, the f_w loop over
full lanes only) and without its other methods. tests/agent/test_example.py checks that its
loss, gradient and whole update on a window equal the Trainer's.

1. Networks: SAVN's encoder (one LSTM step; s_t is its hidden state), the policy head
   over [s_t : i_tau], the attention critic V(s*_t) (Eq. 3-4), f_w (Eq. 5).
2. Acting: every lane steps a window of NUM_STEPS; episodes follow one another and one
   cut at the window's edge continues in the next (its LSTM carry, s_0, i_tau, and the
   states it has seen, for the critic). At an episode's first step i_tau = f_w([s_0 : g])
   + N(0, sigma^2), sigma^2 = max(sigma2_max - rho, 0), rho the lane's success rate over
   its last episodes (Eq. 6-7).
3. The loss: re-run the network over the recorded inputs; each step attends over its own
   episode's states so far; the A3C loss with V(s*_t), a cut episode bootstrapped with
   V(s*_T) (Eq. 8-9).
4. The update: one Adam step; then Algorithm 1: an episode that succeeded adds
   (s_0, g, ŝ) to its lane's buffer (ŝ = the state its Done step attends to most); a
   full buffer trains f_w (shared by the lanes, one lane after another) and is emptied.

    python examples/a3c_foresit.py      # the README's quick settings; prints training SR
"""

from typing import Any, NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

import envs

CONFIG = {
    "NUM_LANES": 32,
    "NUM_STEPS": 16,
    "NUM_UPDATES": 3000,
    "LR": 1e-3,
    "MAX_GRAD_NORM": 50.0,
    "GAMMA": 0.99,
    "ENT_COEF": 0.01,
    "VF_COEF": 0.5,
    "HIDDEN": 128,
    "ATTENTION": 128,
    "VALUE_HIDDEN": 128,
    "IMAGINATION_LAYERS": (128, 64, 32, 64, 128, 128),
    "BUFFER_SIZE": 32,
    "IMAGINATION_EPOCHS": 5,
    "IMAGINATION_LR": 1e-3,
    "SIGMA2_MAX": 0.9,
    "SUCCESS_WINDOW": 100,
    "ROOM_TYPES": None,
    "SETUP": "savn",
}


# ----------------------------------------------------------------------------- 1. networks
class Encoder(nn.Module):
    """view [.., 3, W, C], target [.., D], previous action probabilities [.., A] -> s_t."""

    hidden: int

    def setup(self):
        self.view_conv = nn.Dense(64)  # a 1x1 convolution is a Dense over the channels
        self.target_embed = nn.Dense(64)
        self.action_embed = nn.Dense(10)
        self.pointwise_conv = nn.Dense(64)
        self.lstm = nn.OptimizedLSTMCell(self.hidden)

    def __call__(self, carry, obs, prev_probs):
        image = nn.relu(self.view_conv(obs["view"]))  # [.., 3, W, 64]
        vector = jnp.concatenate(
            [nn.relu(self.target_embed(obs["target"])), nn.relu(self.action_embed(prev_probs))], -1
        )  # [.., 74]
        tiled = jnp.broadcast_to(vector[..., None, None, :], image.shape[:-1] + vector.shape[-1:])
        x = nn.relu(self.pointwise_conv(jnp.concatenate([image, tiled], -1)))  # [.., 3, W, 64]
        return self.lstm(carry, x.reshape(x.shape[:-3] + (-1,)))  # (carry, s_t [.., H])


class PolicyHead(nn.Module):
    num_actions: int

    @nn.compact
    def __call__(self, s_t, imagined):  # one linear layer over [s_t : i_tau]
        x = jnp.concatenate([s_t, imagined], -1)
        return nn.Dense(self.num_actions, kernel_init=nn.initializers.orthogonal(0.01), name="actor")(x)


class ValueHead(nn.Module):
    hidden: int

    @nn.compact
    def __call__(self, x):
        return nn.Dense(1, name="out")(nn.relu(nn.Dense(self.hidden, name="hidden")(x)))[..., 0]


class AttentionCritic(nn.Module):
    """Eq. 3-4: alpha_t = softmax_j(q(s_t) . k(s_j) / sqrt(t + 1)) over the keys the mask
    allows (s_0..s_t of the step's episode), s*_t = sum_j alpha_tj v(s_j) + s_t,
    V = MLP(s*_t). states [B, T, H], keys [B, K, H], mask [B, T, K], positions [B, T]."""

    attention: int
    value_hidden: int

    @nn.compact
    def __call__(self, states, keys, mask, positions):
        query = nn.Dense(self.attention, name="query")(states)
        key = nn.Dense(self.attention, name="key")(keys)
        value = nn.Dense(states.shape[-1], name="value")(keys)
        scores = jnp.einsum("btq,bkq->btk", query, key) / jnp.sqrt(positions + 1.0)[..., None]
        alpha = jax.nn.softmax(jnp.where(mask, scores, jnp.finfo(scores.dtype).min), axis=-1)
        attended = jnp.einsum("btk,bkh->bth", alpha, value) + states
        return ValueHead(self.value_hidden, name="value_head")(attended), alpha  # [B, T], [B, T, K]


class ActorCritic(nn.Module):
    num_actions: int
    hidden: int
    attention: int
    value_hidden: int

    def setup(self):
        self.encoder = Encoder(self.hidden)
        self.policy = PolicyHead(self.num_actions)
        self.value_critic = AttentionCritic(self.attention, self.value_hidden)

    def encode(self, carry, obs, prev_probs):
        return self.encoder(carry, obs, prev_probs)

    def policy_logits(self, s_t, imagined):
        return self.policy(s_t, imagined)

    def critic(self, states, keys, mask, positions):
        return self.value_critic(states, keys, mask, positions)

    def __call__(self, carry, obs, prev_probs, imagined):  # creates every parameter (init)
        carry, s_t = self.encode(carry, obs, prev_probs)
        one = s_t[None, None]
        return self.policy_logits(s_t, imagined), self.critic(one, one, jnp.ones((1, 1, 1), bool), jnp.zeros((1, 1)))


class ImaginationNet(nn.Module):
    """f_w: [s_0 : g] -> the imagined sub-goal state, tanh layers with a bottleneck."""

    layers: tuple

    @nn.compact
    def __call__(self, s_0, goal):
        x = jnp.concatenate([s_0, goal], -1)
        for i, size in enumerate(self.layers):
            x = jnp.tanh(nn.Dense(size, name=f"layer_{i}")(x))
        return x


# ----------------------------------------------------------------------------- 2. acting
class Tracker(NamedTuple):  # a lane's last SUCCESS_WINDOW outcomes, for rho
    outcomes: jax.Array  # [B, W] 1.0 success, 0.0 failure
    next_index: jax.Array  # [B]
    count: jax.Array  # [B]


class Lanes(NamedTuple):  # what each lane carries from one window to the next, [B, ...]
    env_state: Any
    obs: Any  # the observation to act on next
    lstm: tuple  # (c, h) [B, H], zeros at an episode's start
    prev_probs: jax.Array  # [B, A] zeros at an episode's start
    imagined: jax.Array  # [B, H] the running episode's i_tau
    s_0: jax.Array  # [B, H] the running episode's first state
    episode_step: jax.Array  # [B] position of the next state in its episode (0: a new one)
    memory: jax.Array  # [B, M, H] the running episode's states so far (M = the time limit)
    tracker: Tracker


class Transition(NamedTuple):  # one window, time-major [T, B, ...]
    obs: Any
    prev_probs: jax.Array
    imagined: jax.Array
    action: jax.Array
    reward: jax.Array
    done: jax.Array
    success: jax.Array
    episode_step: jax.Array
    s_0: jax.Array


class Buffers(NamedTuple):  # per lane, up to BUFFER_SIZE items of successful episodes
    s_0: jax.Array  # [B, N, H]
    goal: jax.Array  # [B, N, D]
    subgoal: jax.Array  # [B, N, H]
    count: jax.Array  # [B]


def make_parts(config):
    env, env_params = envs.make("GridNav-v0", setup=config["SETUP"], room_types=config["ROOM_TYPES"])
    network = ActorCritic(env.num_actions, config["HIDDEN"], config["ATTENTION"], config["VALUE_HIDDEN"])
    return env, env_params, network, ImaginationNet(config["IMAGINATION_LAYERS"])


def act(config, env, env_params, network, f_w, params, w_params, lanes: Lanes, key):
    """Every lane steps NUM_STEPS steps; returns (lanes after, the window, s_T [B, H])."""
    num_lanes = lanes.episode_step.shape[0]
    memory_size = lanes.memory.shape[1]

    def step(lanes, key):
        k_imag, k_act, k_env = jax.random.split(key, 3)
        first = lanes.episode_step == 0
        lstm, s_t = network.apply(params, lanes.lstm, lanes.obs, lanes.prev_probs, method=ActorCritic.encode)
        s_0 = jnp.where(first[:, None], s_t, lanes.s_0)
        rho = lanes.tracker.outcomes.sum(-1) / jnp.maximum(lanes.tracker.count, 1)
        sigma2 = jnp.maximum(config["SIGMA2_MAX"] - rho, 0.0)  # Eq. 7
        fresh = f_w.apply(w_params, s_t, lanes.obs["target"])  # Eq. 6, from s_0 = this s_t
        fresh = fresh + jnp.sqrt(sigma2)[:, None] * jax.random.normal(k_imag, fresh.shape)
        imagined = jnp.where(first[:, None], fresh, lanes.imagined)
        logits = network.apply(params, s_t, imagined, method=ActorCritic.policy_logits)
        action = jnp.argmax(logits + jax.random.gumbel(k_act, logits.shape), -1).astype(jnp.int32)
        memory = lanes.memory.at[jnp.arange(num_lanes), jnp.minimum(lanes.episode_step, memory_size - 1)].set(s_t)
        obs, env_state, reward, terminated, truncated, info = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
            jax.random.split(k_env, num_lanes), lanes.env_state, action, env_params
        )
        done = terminated | truncated
        t = lanes.tracker  # record each finished episode's outcome
        outcomes = t.outcomes.at[jnp.arange(num_lanes), t.next_index].set(
            jnp.where(done, info["success"].astype(jnp.float32), t.outcomes[jnp.arange(num_lanes), t.next_index])
        )
        window = t.outcomes.shape[-1]
        tracker = Tracker(outcomes, (t.next_index + done) % window, jnp.minimum(t.count + done, window))
        seen = Transition(
            lanes.obs, lanes.prev_probs, imagined, action, reward, done, info["success"], lanes.episode_step, s_0
        )
        lanes = Lanes(
            env_state,
            obs,
            jax.tree.map(lambda x: jnp.where(done[:, None], 0.0, x), lstm),
            jnp.where(done[:, None], 0.0, jax.nn.softmax(logits)),
            imagined,
            s_0,
            jnp.where(done, 0, lanes.episode_step + 1),
            memory,
            tracker,
        )
        return lanes, seen

    lanes, traj = jax.lax.scan(step, lanes, jax.random.split(key, config["NUM_STEPS"]))
    _, s_next = network.apply(params, lanes.lstm, lanes.obs, lanes.prev_probs, method=ActorCritic.encode)
    return lanes, traj, s_next


# ----------------------------------------------------------------------------- 3. the loss
def attention_mask(steps, memory_size):
    """Which keys [memory ; window] each step may attend to: the states of its own episode
    up to itself. steps [B, T] positions in their episodes -> [B, T, memory_size + T]."""
    episode = jnp.cumsum(steps == 0, -1)  # 0: the episode carried in from earlier windows
    memory = (episode == 0)[..., None] & (jnp.arange(memory_size) < steps[:, :1, None])
    causal = jnp.tril(jnp.ones((steps.shape[-1],) * 2, bool))
    return jnp.concatenate([memory, causal & (episode[..., :, None] == episode[..., None, :])], -1)


def loss_fn(config, network, params, traj: Transition, start: Lanes, s_next, next_step):
    """The A3C loss of a window (Eq. 8-9); returns (loss, (alpha, keys))."""

    def step(carry, x):  # re-run the encoder and the policy over the recorded inputs
        obs, prev_probs, imagined, first = x
        carry = jax.tree.map(lambda c: jnp.where(first[:, None], 0.0, c), carry)
        carry, s_t = network.apply(params, carry, obs, prev_probs, method=ActorCritic.encode)
        return carry, (s_t, network.apply(params, s_t, imagined, method=ActorCritic.policy_logits))

    xs = (traj.obs, traj.prev_probs, traj.imagined, traj.episode_step == 0)
    _, (states, logits) = jax.lax.scan(step, start.lstm, xs)
    states = jnp.concatenate([states, s_next[None]]).swapaxes(0, 1)  # [B, T + 1, H], s_T last
    steps = jnp.concatenate([traj.episode_step, next_step[None]]).swapaxes(0, 1)  # [B, T + 1]
    keys = jnp.concatenate([start.memory, states], 1)  # earlier windows' states, then the window's
    values, alpha = network.apply(
        params,
        states,
        keys,
        attention_mask(steps, start.memory.shape[1]),
        steps.astype(jnp.float32),
        method=ActorCritic.critic,
    )
    value, bootstrap = values[:, :-1].T, values[:, -1]  # V(s*_t) [T, B], V(s*_T) [B]

    def discounted(R, x):  # R_t = r_t + gamma (1 - done_t) R_{t+1}; nothing follows Done or the limit
        reward, done = x
        R = reward + config["GAMMA"] * (1.0 - done) * R
        return R, R

    _, returns = jax.lax.scan(discounted, jax.lax.stop_gradient(bootstrap), (traj.reward, traj.done), reverse=True)
    advantage = jax.lax.stop_gradient(returns - value)  # GAE with lambda = 1, as SAVN
    log_pi = jax.nn.log_softmax(logits)
    log_prob = jnp.take_along_axis(log_pi, traj.action[..., None], -1)[..., 0]
    entropy = -(jnp.exp(log_pi) * log_pi).sum(-1)
    policy = jnp.mean(-log_prob * advantage) - config["ENT_COEF"] * jnp.mean(entropy)
    value_loss = jnp.mean(0.5 * (value - returns) ** 2)
    return policy + config["VF_COEF"] * value_loss, (alpha, keys)


# ----------------------------------------------------------------------------- 4. the update
def train_imagination(config, f_w, w_params, buffers: Buffers, items):
    """Algorithm 1 at each step of the window in time order: a lane whose episode ended
    successfully there adds (s_0, g, ŝ); then every full buffer, in lane order, trains the
    shared f_w (EPOCHS passes, one Adam step per item, a fresh optimiser) and is emptied."""
    optimizer = optax.adam(config["IMAGINATION_LR"])

    def smooth_l1(w, s_0, goal, subgoal):
        x = jnp.abs(f_w.apply(w, s_0, goal) - subgoal)
        return jnp.mean(jnp.where(x < 1.0, 0.5 * x**2, x - 0.5))

    def train_lane(w, lane):
        def item(carry, x):
            w, opt = carry
            updates, opt = optimizer.update(jax.grad(smooth_l1)(w, *x), opt, w)
            return (optax.apply_updates(w, updates), opt), None

        def epoch(carry, _):
            return jax.lax.scan(item, carry, lane)[0], None

        return jax.lax.scan(epoch, (w, optimizer.init(w)), None, config["IMAGINATION_EPOCHS"])[0][0]

    def at_step(carry, item):
        w, b = carry
        s_0, goal, subgoal, add = item  # [B, ...]
        add = add & (b.count < b.s_0.shape[1])
        put = lambda store, x: store.at[jnp.arange(add.shape[0]), b.count % store.shape[1]].set(  # noqa: E731
            jnp.where(add[:, None], x, store[jnp.arange(add.shape[0]), b.count % store.shape[1]])
        )
        b = Buffers(put(b.s_0, s_0), put(b.goal, goal), put(b.subgoal, subgoal), b.count + add)
        full = b.count == b.s_0.shape[1]
        w = jax.lax.fori_loop(
            0,
            add.shape[0],
            lambda i, w: jax.lax.cond(full[i], lambda: train_lane(w, (b.s_0[i], b.goal[i], b.subgoal[i])), lambda: w),
            w,
        )
        b = jax.tree.map(lambda x: jnp.where(full.reshape((-1,) + (1,) * (x.ndim - 1)), 0, x), b)
        return (w, b), None

    return jax.lax.scan(at_step, (w_params, buffers), items)[0]


class RunnerState(NamedTuple):
    params: Any
    opt_state: Any
    w_params: Any
    buffers: Buffers
    lanes: Lanes
    key: jax.Array


def make_train(config):
    env, env_params, network, f_w = make_parts(config)
    optimizer = optax.chain(optax.clip_by_global_norm(config["MAX_GRAD_NORM"]), optax.adam(config["LR"]))
    memory_size = int(env_params.max_steps.max())  # the longest training episode

    def init(key):
        k_obs, k_params, k_lanes, key = jax.random.split(key, 4)
        obs, _ = env.reset(k_obs, env_params)
        h, b = config["HIDDEN"], config["NUM_LANES"]
        zero = jnp.zeros((h,))
        k_net, k_imag = jax.random.split(k_params)
        params = network.init(k_net, (zero, zero), obs, jnp.zeros((env.num_actions,)), zero)
        w_params = f_w.init(k_imag, zero, obs["target"])
        obs, env_state = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_lanes, b), env_params)
        zeros = jnp.zeros((b, h))
        tracker = Tracker(jnp.zeros((b, config["SUCCESS_WINDOW"])), jnp.zeros(b, jnp.int32), jnp.zeros(b, jnp.int32))
        lanes = Lanes(
            env_state,
            obs,
            (zeros, zeros),
            jnp.zeros((b, env.num_actions)),
            zeros,
            zeros,
            jnp.zeros(b, jnp.int32),
            jnp.zeros((b, memory_size, h)),
            tracker,
        )
        n, d = config["BUFFER_SIZE"], obs["target"].shape[-1]
        buffers = Buffers(jnp.zeros((b, n, h)), jnp.zeros((b, n, d)), jnp.zeros((b, n, h)), jnp.zeros(b, jnp.int32))
        return RunnerState(params, optimizer.init(params), w_params, buffers, lanes, key)

    def loss_and_grad(params, w_params, lanes, key):
        """((loss, (lanes after, window, alpha, keys)), grads) of one window."""
        next_lanes, traj, s_next = act(config, env, env_params, network, f_w, params, w_params, lanes, key)
        loss = lambda p: loss_fn(config, network, p, traj, lanes, s_next, next_lanes.episode_step)  # noqa: E731
        (value, (alpha, keys)), grads = jax.value_and_grad(loss, has_aux=True)(params)
        return (value, (next_lanes, traj, alpha, keys)), grads

    def update(state: RunnerState, _):
        key, k_act, _ = jax.random.split(state.key, 3)
        (loss, (lanes, traj, alpha, keys)), grads = loss_and_grad(state.params, state.w_params, state.lanes, k_act)
        updates, opt_state = optimizer.update(grads, state.opt_state, state.params)
        params = optax.apply_updates(state.params, updates)
        index = jnp.argmax(alpha[:, :-1], -1)  # [B, T] the key each step attends to most
        subgoal = jax.lax.stop_gradient(jnp.take_along_axis(keys, index[..., None], 1)).swapaxes(0, 1)
        items = (traj.s_0, traj.obs["target"], subgoal, traj.success & traj.done)
        w_params, buffers = train_imagination(config, f_w, state.w_params, state.buffers, items)
        ended = traj.done.sum()
        metrics = {"loss": loss, "episodes": ended, "success_rate": traj.success.sum() / jnp.maximum(ended, 1)}
        return RunnerState(params, opt_state, w_params, buffers, lanes, key), metrics

    def train(key, num_updates=config["NUM_UPDATES"]):
        return jax.lax.scan(update, init(key), None, num_updates)

    return train, init, update, loss_and_grad


if __name__ == "__main__":
    train, init, update, _ = make_train(CONFIG)
    run = jax.jit(lambda state: jax.lax.scan(update, state, None, 100))
    state = init(jax.random.key(0))
    for chunk in range(CONFIG["NUM_UPDATES"] // 100):
        state, metrics = run(state)
        rate = float(metrics["success_rate"] @ metrics["episodes"] / metrics["episodes"].sum())
        print(
            f"updates {100 * (chunk + 1):5d}  training success rate {100 * rate:5.1f}%  loss {metrics['loss'].mean():.3f}"
        )
