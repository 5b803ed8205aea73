"""envs.spaces mirror gymnax's space classes (attribute names, methods) and convert to them
with to_gymnax, tested against a stand-in module with gymnax's constructors (gymnax is not
a dependency)."""

import types

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import envs
from envs import spaces


def fake_gymnax_spaces():
    """A module with gymnax.environments.spaces' constructors (Discrete(n), Box(low, high,
    shape, dtype), Dict(spaces)) and nothing else."""

    class Discrete:
        def __init__(self, num_categories, *, dtype=jnp.int32):
            self.n, self.shape, self.dtype = num_categories, (), dtype

    class Box:
        def __init__(self, low, high, shape, dtype=jnp.float32):
            self.low, self.high, self.shape, self.dtype = low, high, shape, dtype

    class Dict:
        def __init__(self, spaces):
            self.spaces, self.num_spaces = spaces, len(spaces)

    return types.SimpleNamespace(Discrete=Discrete, Box=Box, Dict=Dict)


def test_gymnax_attribute_names():
    d = spaces.Discrete(6)
    assert (d.n, d.shape, d.dtype) == (6, (), jnp.int32)
    b = spaces.Box(0.0, 1.0, [3, 2])
    assert (b.low, b.high, b.shape, b.dtype) == (0.0, 1.0, (3, 2), jnp.float32)
    t = spaces.Dict({"a": b, "b": d})
    assert t.num_spaces == 2 and t.spaces["a"] is b and t["b"] is d
    for space in (d, b, t):
        assert isinstance(space, spaces.Space)
        assert callable(space.sample) and callable(space.contains)
    with pytest.raises(ValueError):
        spaces.Discrete(-1)


def test_sample_and_contains_under_jit():
    t = spaces.Dict({"box": spaces.Box(-1.0, jnp.array([1.0, 2.0]), (2,)), "n": spaces.Discrete(4)})
    samples = jax.jit(jax.vmap(t.sample))(jax.random.split(jax.random.key(0), 100))
    assert samples["box"].shape == (100, 2) and samples["n"].dtype == jnp.int32
    assert bool(jax.vmap(t.contains)(samples).all())
    assert not bool(t.contains({"box": jnp.array([0.0, 3.0]), "n": 0}))
    assert not bool(t.contains({"box": jnp.zeros(2)}))  # a key missing
    # gymnax's Dict.contains reads attributes: an object with those attributes works too.
    assert bool(t.contains(types.SimpleNamespace(box=jnp.zeros(2), n=jnp.int32(3))))


def test_to_gymnax_converts_the_env_spaces():
    fake = fake_gymnax_spaces()
    env = envs.GridNav("org", view_width=4)
    obs = spaces.to_gymnax(env.observation_space(), fake)
    act = spaces.to_gymnax(env.action_space(), fake)
    assert isinstance(obs, fake.Dict) and isinstance(act, fake.Discrete) and act.n == 6
    assert list(obs.spaces) == ["view", "target", "detections"]
    for name, ours in env.observation_space().spaces.items():
        theirs = obs.spaces[name]
        assert isinstance(theirs, fake.Box)
        assert (theirs.shape, theirs.dtype, theirs.low, theirs.high) == (ours.shape, ours.dtype, ours.low, ours.high)
    with pytest.raises(TypeError):
        spaces.to_gymnax(object(), fake)


def test_to_gymnax_with_the_real_gymnax_when_installed():
    """gymnax is optional: without it to_gymnax raises ImportError; with it, gymnax's isinstance
    checks pass on the converted spaces."""
    env = envs.GridNav(view_width=4)
    try:
        from gymnax.environments import spaces as gymnax_spaces
    except ImportError:
        with pytest.raises(ImportError):
            spaces.to_gymnax(env.action_space())
        return
    obs = spaces.to_gymnax(env.observation_space())
    assert isinstance(obs, gymnax_spaces.Dict) and isinstance(obs.spaces["view"], gymnax_spaces.Box)
    assert isinstance(spaces.to_gymnax(env.action_space()), gymnax_spaces.Discrete)


def test_flat_size():
    t = spaces.Dict({"a": spaces.Box(0, 1, (3, 4)), "b": spaces.Discrete(5), "c": spaces.Box(0, 1, (2,))})
    assert spaces.flat_size(t) == 12 + 1 + 2
    assert np.prod(spaces.Box(0, 1, ()).shape) == 1 and spaces.flat_size(spaces.Box(0, 1, ())) == 1
