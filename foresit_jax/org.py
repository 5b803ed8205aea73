"""ORG's object-relation graph (Du et al., ECCV 2020) for the `org` setup's detector features.

`ObjectGraph` is the module plugged into `networks.Encoder(object_graph=...)`: called as
`object_graph(obs["detections"] [..., N, 7], obs["target"] [..., D])`, it returns
features `[..., F]`, F = num_categories * view_rows * view_cols (22 * 3 * 16 = 1056 with
the defaults), which the Encoder concatenates to its flattened grid before the LSTM.
Any leading batch dims; pure (flax linen `init`/`apply`).

What ORG's published GraphModel does
------------------------------------
Reference: github.com/xiaobaishu0097/ECCV-VN, `models/graphmodel.py` (class GraphModel)
and `agents/navigation_agent.py` (how the detector features are formed). Single sample,
N = `args.num_category` (default 22, `utils/command_parser.py` L69-74).

Inputs (`navigation_agent.py` L46-60): a precomputed Faster R-CNN detection row per
target category, `[N, 517]` (read from an hdf5 file per scene, not in the repo), split as
  appear    = [:, :512]   the detector's 512-d RoI appearance feature,
  info      = [:, 512:]   5 values: bounding box (4) and confidence (1),
  indicator = [N, 1]      one-hot of the target category (L48-49).
The target reaches the GraphModel only through `indicator` (no word embedding).

`GraphModel.embedding` (graphmodel.py L74-99):
  L75     x = [info : indicator]                                     [N, 6]
  L76     x = ReLU(Linear(6 -> N)(x))           (linear_1, L28)      [N, N]
  L77     x = x^T                                                    [N, N]
  L78-81  x = ReLU(Linear(N -> N)(x)), four times (linear_2..5, L29-32): the learned
          adjacency A = x. The first layer acts on each category's 6 values; after the
          transpose the four N -> N layers mix over the categories.
  L82     graph = (appear^T . A)^T = A^T . appear                    [N, 512]
          i.e. graph[k] = sum_j A[j, k] appear[j].
  L83     y = [graph : info : indicator]                             [N, 518]
  L85     y = ReLU(Linear(128 -> 49)(ReLU(Linear(518 -> 128)(y))))   [N, 49]
          (graph_detection_feature, L22-26 a Sequential Linear/ReLU/Linear; the last
          ReLU is the F.relu at L85)
  L86     maps = y.reshape(1, N, 7, 7): one 7x7 map per category, as N channels
  L88-89  action = ReLU(Linear(6 -> 10)(previous action probs)), tiled 7x7
  L91-92  image = ReLU(1x1 conv 512 -> 64)(ResNet-18 [512, 7, 7]), dropout 0.25
  L94-97  ReLU(1x1 conv (64 + N + 10) -> 64)([image : maps : action]) (pointwise, L36-38),
          dropout, flatten 7*7*64 -> the LSTM (2 layers, 512 hidden, L43).
Initialisation (L49, `utils/model_util.py` L42-57 `weights_init`): every Linear and Conv
has Glorot-uniform weights and zero biases (conv1 then scaled by the ReLU gain, L50-51).
There is no dropout in the graph path.

What this module does, and where it differs (and why)
-----------------------------------------------------
Our detections (`envs/gridnav.py` `GridNav.detections`) are, per category,
`[visible, col_min, col_max, row_min, row_max, confidence, is_target]`, box in fractions
of the 3 x W view, confidence = 1 / (1 + 0.25 depth) of the nearest visible cell, all
zero (except is_target) when the category is not in view.

  * Adjacency input: `[info : indicator] = detections[..., 1:7]` (box 4, confidence 1,
    target indicator 1): the same six values in the same roles as ORG's L75. The visible
    flag (column 0) is not part of it, as in ORG; it gates the appearance (below). The box
    is in normalised view coordinates (ORG's hdf5 normalisation is not published).
  * Adjacency: exactly ORG's: Dense(6 -> N) + ReLU, swap the last two axes, then
    `adjacency_layers - 1` (= 4) Dense(N -> N) + ReLU. graph = A^T . appearance
    (`einsum('...jk,...je->...ke')`), i.e. graph[k] = sum_j A[j, k] appearance[j].
  * APPEARANCE STAND-IN (the one real departure). The grid has no detector CNN, so there
    is no 512-d RoI feature. Instead:
        appearance[j] = visible[j] * embedding[j]       (embedding: learned [N, E], E=64)
    optionally times confidence[j] (`scale_appearance_by_confidence`, default off: ORG's
    appearance does not depend on confidence, which reaches the graph through the info
    columns). It carries only what a detector reports, the identity of a category in
    view: an unseen category's row is zero and contributes nothing to A^T . appearance;
    nothing about unseen objects, the scene or the target leaks in. Unlike ORG's fixed
    detector features the embedding is trained with the agent. Init N(0, 1).
  * Per-category maps: ORG maps each category to 7x7 = 49 values (its ResNet grid); ours
    to view_rows x view_cols values (3 x 16 = 48, the view's own grid): Dense(E + 6 ->
    `map_hidden` = 128) + ReLU, Dense(128 -> rows * cols) + ReLU, as L83-86.
  * Where the maps go: ORG stacks them as N channels beside the 64 image channels and the
    10 action channels into the 1x1 pointwise conv (L94-95). Our Encoder's hook
    concatenates features AFTER its pointwise conv and flatten, so `__call__` returns the
    maps flattened channels-last (layout `[rows, cols, N]` row-major, like the Encoder's
    grid), F = N * rows * cols, which go to the LSTM directly. `category_maps` returns
    them unflattened `[..., rows, cols, N]` should the Encoder ever feed them into its
    pointwise conv as ORG does. (Our Encoder also tiles a target embedding, which ORG's
    GraphModel has not; its LSTM has 1 layer where ORG's has 2.)
  * `target` is accepted for the hook's signature and checked for the batch shape only:
    the target enters, as in ORG, through the is_target column.
  * Batched over any leading dims (ORG runs batch 1); the transpose is a swap of the
    last two axes. Dense kernels Glorot-uniform, biases zero, as ORG's `weights_init`.
"""

from __future__ import annotations

import chex
import flax.linen as nn
import jax.numpy as jnp

from foresit_jax.layers import Dense

NUM_DETECTION_FEATURES = 7  # visible, col min/max, row min/max, confidence, is target
VISIBLE, CONFIDENCE = 0, 5  # columns of a detection row
INFO = slice(1, 7)  # [box (4) : confidence : is_target], ORG's [info : indicator]

_glorot = nn.initializers.glorot_uniform()


class ObjectGraph(nn.Module):
    """ORG's object-relation graph over per-category detections (see the module docstring).

    `__call__(detections [..., N, 7], target [..., D]) -> [..., N * view_rows * view_cols]`
    (the per-category maps, flattened channels-last from `[..., view_rows, view_cols, N]`).
    Methods (use with `apply(..., method=...)`): `adjacency(detections) -> [..., N, N]`,
    `appearance(detections) -> [..., N, E]`, `graph_features(detections) -> [..., N, E]`
    (A^T . appearance), `category_maps(detections, target) -> [..., rows, cols, N]`.
    """

    num_categories: int = 22
    embed_size: int = 64  # E, stands in for the detector's 512-d appearance feature
    view_rows: int = 3
    view_cols: int = 16
    adjacency_layers: int = 5  # Dense(6 -> N) then 4 x Dense(N -> N), as GraphModel
    map_hidden: int = 128
    scale_appearance_by_confidence: bool = False

    def setup(self):
        if self.adjacency_layers < 1:
            raise ValueError(f"adjacency_layers must be >= 1, got {self.adjacency_layers}")
        n = self.num_categories
        self.adjacency_dense = [
            Dense(n, kernel_init=_glorot, name=f"adjacency_{i}") for i in range(self.adjacency_layers)
        ]
        self.appearance_embedding = self.param(
            "appearance_embedding", nn.initializers.normal(1.0), (n, self.embed_size)
        )  # [N, E]
        self.map_hidden_dense = Dense(self.map_hidden, kernel_init=_glorot, name="map_hidden")
        self.map_out_dense = Dense(self.view_rows * self.view_cols, kernel_init=_glorot, name="map_out")

    @property
    def output_size(self) -> int:
        """F = num_categories * view_rows * view_cols."""
        return self.num_categories * self.view_rows * self.view_cols

    def _check(self, detections: chex.Array) -> None:
        chex.assert_axis_dimension(detections, -1, NUM_DETECTION_FEATURES)
        chex.assert_axis_dimension(detections, -2, self.num_categories)

    def adjacency(self, detections: chex.Array) -> chex.Array:
        """Learned adjacency A `[..., N, N]` from `[box : confidence : is_target]` (L75-81)."""
        self._check(detections)
        x = nn.relu(self.adjacency_dense[0](detections[..., INFO]))  # [..., N(i), N(j)]
        x = jnp.swapaxes(x, -1, -2)  # [..., N(j), N(i)]
        for dense in self.adjacency_dense[1:]:
            x = nn.relu(dense(x))  # mixes over the categories i -> k
        return x  # [..., N(j), N(k)]

    def appearance(self, detections: chex.Array) -> chex.Array:
        """Stand-in for the detector's appearance features, `[..., N, E]`: the learned
        category embedding gated by the visible flag (times confidence if so configured)."""
        self._check(detections)
        gate = detections[..., VISIBLE]  # [..., N]
        if self.scale_appearance_by_confidence:
            gate = gate * detections[..., CONFIDENCE]
        return gate[..., None] * self.appearance_embedding.astype(detections.dtype)  # [..., N, E]

    def graph_features(self, detections: chex.Array) -> chex.Array:
        """A^T . appearance `[..., N, E]`: row k = sum_j A[j, k] appearance[j] (L82)."""
        a = self.adjacency(detections)  # [..., N, N]
        return jnp.einsum("...jk,...je->...ke", a, self.appearance(detections))

    def category_maps(self, detections: chex.Array, target: chex.Array) -> chex.Array:
        """One view-sized map per category, `[..., view_rows, view_cols, N]` (L83-86)."""
        self._check(detections)
        chex.assert_equal_shape_prefix([detections, target], detections.ndim - 2)
        x = jnp.concatenate([self.graph_features(detections), detections[..., INFO]], axis=-1)  # [..., N, E+6]
        x = nn.relu(self.map_hidden_dense(x))  # [..., N, 128]
        x = nn.relu(self.map_out_dense(x))  # [..., N, rows * cols]
        x = x.reshape(*x.shape[:-1], self.view_rows, self.view_cols)  # [..., N, rows, cols]
        return jnp.moveaxis(x, -3, -1)  # [..., rows, cols, N]

    def __call__(self, detections: chex.Array, target: chex.Array) -> chex.Array:
        maps = self.category_maps(detections, target)  # [..., rows, cols, N]
        return maps.reshape(*maps.shape[:-3], self.output_size)  # [..., N * rows * cols]


__all__ = ["ObjectGraph", "NUM_DETECTION_FEATURES"]
