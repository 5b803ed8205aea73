"""foresit_jax.org.ObjectGraph against a numpy transcription of ORG's GraphModel graph path
(models/graphmodel.py L75-86 of github.com/xiaobaishu0097/ECCV-VN), with the appearance
stand-in of foresit_jax.org."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from foresit_jax.org import ObjectGraph

N, E, ROWS, COLS, D = 6, 5, 3, 4, 6  # small in tests (22, 64, 3, 16 in the org setup)


def make_module(**kwargs):
    return ObjectGraph(num_categories=N, embed_size=E, view_rows=ROWS, view_cols=COLS, **kwargs)


def random_detections(rng, batch=(), visible_prob=0.6):
    """Detections shaped like GridNav.detections: zero rows (but is_target) when unseen."""
    visible = rng.random((*batch, N)) < visible_prob
    c0, c1 = np.sort(rng.random((2, *batch, N)), axis=0)
    r0, r1 = np.sort(rng.random((2, *batch, N)), axis=0)
    conf = rng.uniform(0.2, 1.0, (*batch, N))
    feats = np.stack([np.ones_like(c0), c0, c1, r0, r1, conf], -1) * visible[..., None]
    target = rng.integers(N, size=batch)
    is_target = (np.arange(N) == target[..., None]).astype(np.float64)
    dets = np.concatenate([feats, is_target[..., None]], -1).astype(np.float32)
    return dets, np.eye(D, dtype=np.float32)[target]


def init(module, seed=0):
    dets, target = random_detections(np.random.default_rng(seed))
    return module.init(jax.random.PRNGKey(seed), dets, target)


# ---------------------------------------------------------------- numpy reference
def np_object_graph(p, dets, scale_by_confidence=False):
    """ONE unbatched sample, float64, written as GraphModel.embedding writes it
    (torch Linear y = x W^T + b; flax kernels are W^T). Returns (A, graph, maps [N, R*C])."""
    p = jax.tree.map(lambda a: np.asarray(a, np.float64), p)
    relu = lambda x: np.maximum(x, 0.0)
    linear = lambda q, x: x @ q["kernel"] + q["bias"]
    dets = np.asarray(dets, np.float64)
    target_info = dets[:, 1:7]  # torch.cat((info, indicator), dim=1)        [N, 6]
    x = relu(linear(p["adjacency_0"], target_info))  # linear_1              [N, N]
    x = x.T  # target_info.t()
    for i in range(1, 5):  # linear_2..5
        x = relu(linear(p[f"adjacency_{i}"], x))
    a = x
    gate = dets[:, 0] * (dets[:, 5] if scale_by_confidence else 1.0)
    appear = gate[:, None] * p["appearance_embedding"]  # stand-in for target['appear'] [N, E]
    graph = (appear.T @ a).T  # torch.mm(target['appear'].t(), target_info).t()
    y = np.concatenate([graph, target_info], 1)  # [N, E + 6]
    maps = np.stack(  # one category at a time
        [relu(linear(p["map_out"], relu(linear(p["map_hidden"], y[k])))) for k in range(N)]
    )  # [N, R * C]
    return a, graph, maps


def np_features(maps):
    """[N, R*C] -> the module's output: [R, C, N] row-major flattened."""
    out = np.zeros((ROWS, COLS, N))
    for k in range(N):
        for r in range(ROWS):
            for c in range(COLS):
                out[r, c, k] = maps[k, r * COLS + c]
    return out.reshape(-1)


# ---------------------------------------------------------------- tests
def test_parameter_shapes():
    params = init(make_module())["params"]
    shapes = jax.tree.map(jnp.shape, params)
    assert shapes["adjacency_0"] == {"kernel": (6, N), "bias": (N,)}
    for i in range(1, 5):
        assert shapes[f"adjacency_{i}"] == {"kernel": (N, N), "bias": (N,)}
    assert "adjacency_5" not in shapes
    assert shapes["appearance_embedding"] == (N, E)
    assert shapes["map_hidden"] == {"kernel": (E + 6, 128), "bias": (128,)}
    assert shapes["map_out"] == {"kernel": (128, ROWS * COLS), "bias": (ROWS * COLS,)}
    # ORG's weights_init: zero biases.
    for name in ("adjacency_0", "map_hidden", "map_out"):
        np.testing.assert_array_equal(params[name]["bias"], 0.0)


def test_output_size_defaults():
    module = ObjectGraph()
    assert module.output_size == 22 * 3 * 16 == 1056
    dets = jnp.zeros((22, 7))
    out = jax.eval_shape(lambda: module.init_with_output(jax.random.PRNGKey(0), dets, jnp.zeros(22))[0])
    chex.assert_shape(out, (1056,))


@pytest.mark.parametrize("scale_by_confidence", [False, True])
def test_matches_numpy_reference(scale_by_confidence):
    module = make_module(scale_appearance_by_confidence=scale_by_confidence)
    variables = init(module)
    # Non-zero biases so every term of the reference is exercised.
    rng = np.random.default_rng(1)
    variables = jax.tree.map(lambda a: a + 0.1 * rng.normal(size=a.shape).astype(a.dtype), variables)
    p = variables["params"]
    for seed in range(3):
        dets, target = random_detections(np.random.default_rng(10 + seed))
        a, graph, maps = np_object_graph(p, dets, scale_by_confidence)
        got_a = module.apply(variables, dets, method=ObjectGraph.adjacency)
        got_graph = module.apply(variables, dets, method=ObjectGraph.graph_features)
        got_maps = module.apply(variables, dets, target, method=ObjectGraph.category_maps)
        out = module.apply(variables, dets, target)
        np.testing.assert_allclose(got_a, a, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose(got_graph, graph, rtol=1e-5, atol=1e-5)
        chex.assert_shape(got_maps, (ROWS, COLS, N))
        np.testing.assert_allclose(got_maps, np.moveaxis(maps.reshape(N, ROWS, COLS), 0, -1), rtol=1e-5, atol=1e-5)
        chex.assert_shape(out, (N * ROWS * COLS,))
        np.testing.assert_allclose(out, np_features(maps), rtol=1e-5, atol=1e-5)
        assert np.abs(a).sum() > 0 and np.abs(graph).sum() > 0 and np.abs(maps).sum() > 0


@pytest.mark.parametrize("jit", [False, True])
def test_batched_equals_unbatched(jit):
    module = make_module()
    variables = init(module)
    apply = lambda d, t: module.apply(variables, d, t)
    apply = jax.jit(apply) if jit else apply
    dets, target = random_detections(np.random.default_rng(3), batch=(2, 3))
    out = apply(dets, target)
    chex.assert_shape(out, (2, 3, N * ROWS * COLS))
    for i in range(2):
        for j in range(3):
            np.testing.assert_allclose(out[i, j], apply(dets[i, j], target[i, j]), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(jax.vmap(apply)(dets[0], target[0]), out[0], rtol=1e-5, atol=1e-6)


def test_invisible_category_contributes_nothing_to_appearance():
    module = make_module()
    variables = init(module)
    dets, target = random_detections(np.random.default_rng(4), visible_prob=1.0)
    hidden = 2
    dets[hidden, :6] = 0.0  # category 2 not in view (its detection row as GridNav writes it)

    appearance = module.apply(variables, dets, method=ObjectGraph.appearance)
    np.testing.assert_array_equal(appearance[hidden], 0.0)
    assert np.all(np.abs(np.delete(np.asarray(appearance), hidden, 0)).sum(-1) > 0)

    # Changing the unseen category's embedding changes nothing; a seen one's does.
    def out_with_embedding_row(k, delta):
        emb = variables["params"]["appearance_embedding"].at[k].add(delta)
        return module.apply({"params": {**variables["params"], "appearance_embedding": emb}}, dets, target)

    base = module.apply(variables, dets, target)
    np.testing.assert_array_equal(out_with_embedding_row(hidden, 3.0), base)
    assert not np.allclose(out_with_embedding_row((hidden + 1) % N, 3.0), base)

    def loss(emb):
        v = {"params": {**variables["params"], "appearance_embedding": emb}}
        return module.apply(v, dets, target).sum()

    grad = jax.grad(loss)(variables["params"]["appearance_embedding"])
    np.testing.assert_array_equal(grad[hidden], 0.0)
    assert np.abs(np.delete(np.asarray(grad), hidden, 0)).sum() > 0


def test_gradient_wrt_detections_is_nonzero():
    module = make_module()
    variables = init(module)
    dets, target = random_detections(np.random.default_rng(5))
    grad = jax.grad(lambda d: module.apply(variables, d, target).sum())(jnp.asarray(dets))
    chex.assert_shape(grad, (N, 7))
    assert np.all(np.isfinite(grad))
    assert np.abs(grad).sum() > 0
    assert np.abs(grad[:, 0]).sum() > 0  # through the visible gate (appearance)
    assert np.abs(grad[:, 1:7]).sum() > 0  # through the adjacency and the maps


def test_masking_a_category_changes_output():
    module = make_module()
    variables = init(module)
    dets, target = random_detections(np.random.default_rng(6), visible_prob=1.0)
    base = module.apply(variables, dets, target)
    for k in range(N):
        masked = dets.copy()
        masked[k] = 0.0
        out = module.apply(variables, masked, target)
        assert not np.allclose(out, base), f"zeroing category {k}'s detections changed nothing"


def test_target_argument_only_checked_for_batch_shape():
    module = make_module()
    variables = init(module)
    dets, target = random_detections(np.random.default_rng(7))
    out = module.apply(variables, dets, target)
    np.testing.assert_array_equal(module.apply(variables, dets, np.zeros_like(target)), out)
    with pytest.raises(AssertionError):
        module.apply(variables, dets[None], target)  # batch prefixes differ
    with pytest.raises(AssertionError):
        module.apply(variables, dets[:, :6], target)  # wrong feature count
