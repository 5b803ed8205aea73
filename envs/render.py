"""Pictures of GridNav: a scene seen from above, and the agent's first-person view (PNG).

    rgb = render_topdown(params, scene_index, state=state, trajectory=positions, path="scene.png")
    rgb = render_view(obs, env.categories, path="view.png")

Both return the picture as ``uint8 [H, W, 3]`` and also write it as a PNG when ``path``
is given.  Matplotlib is used through ``Figure`` and the Agg canvas directly (no pyplot,
no global backend switch), so rendering is safe in scripts, tests and threads.

Coordinates: positions are ``(row, col)``; a scene is drawn with ``imshow(origin="upper")``
so cell ``(r, c)`` is centred at ``x = c, y = r`` (row 0 at the top).  Heading 0 points
north (row - 1) and headings turn clockwise in 45 degree steps, so the arrow of heading
``h`` points along ``catalog.HEADING_DELTAS[h]`` = ``(d_row, d_col)``, drawn as
``(dx, dy) = (d_col, d_row)``.

The agent is drawn in a colour used for nothing else (``AGENT_RGB``), on top of
everything, so a picture rendered with ``decorations=False`` (no axes, no margins,
``cell_px`` pixels per cell) can be checked: the agent's pixels lie in the cell
``[r * cell_px, (r + 1) * cell_px) x [c * cell_px, (c + 1) * cell_px)``; see
``agent_pixel``.
"""

from __future__ import annotations

import os

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch, Polygon, Rectangle

from envs import catalog as C

AGENT_RGB = (255, 0, 255)  # magenta: used for the agent and nothing else
TARGET_RGB = (230, 20, 20)
TRAJECTORY_RGB = (20, 90, 230)
CELL_RGB = {  # catalog.CELL_* -> colour
    C.CELL_FLOOR: (236, 233, 222),
    C.CELL_WALL: (70, 70, 76),
    C.CELL_FURNITURE: (168, 128, 88),
    C.CELL_OBJECT: (236, 233, 222),  # floor under a floor object (the marker shows the object)
}
SEM_RGB = {  # catalog.SEM_* -> colour of a view pixel (categories use category_colors)
    C.SEM_NOTHING: (0, 0, 0),
    C.SEM_WALL: (120, 120, 128),
    C.SEM_FLOOR: (236, 233, 222),
    C.SEM_FURNITURE: (168, 128, 88),
}
STRUCTURAL_NAMES = ("nothing", "wall", "floor", "furniture")
BAND_MARKERS = {C.BAND_FLOOR: "o", C.BAND_MID: "s", C.BAND_HIGH: "D"}
BAND_NAMES = {C.BAND_FLOOR: "on the floor", C.BAND_MID: "on furniture", C.BAND_HIGH: "high on a wall"}
DPI = 100


def furniture_colors() -> np.ndarray:
    """float [len(FURNITURE_KINDS), 3] in [0, 1]: shades of brown, one per furniture kind
    (layouts with priors), around the plain furniture colour."""
    base = np.array(_rgb01(SEM_RGB[C.SEM_FURNITURE]))
    steps = np.linspace(-0.28, 0.28, len(C.FURNITURE_KINDS))
    return np.clip(base[None, :] + steps[:, None] * np.array([1.0, 0.9, 0.7])[None, :], 0.0, 1.0)


def category_colors(num_categories: int) -> np.ndarray:
    """float [n, 3] in [0, 1]: one distinct colour per object category (tab20, then tab20b)."""
    table = list(matplotlib.colormaps["tab20"].colors) + list(matplotlib.colormaps["tab20b"].colors)
    return np.array([table[i % len(table)][:3] for i in range(num_categories)], np.float64)


def infer_categories(num_categories: int) -> tuple[str, ...]:
    """The category names of the setup with ``num_categories`` categories."""
    for setup in C.SETUPS:
        if len(C.categories(setup)) == num_categories:
            return C.categories(setup)
    return tuple(f"category {i}" for i in range(num_categories))


def agent_pixel(agent_pos, cell_px: int) -> tuple[float, float]:
    """(y, x) pixel of the centre of the agent's cell in a ``decorations=False`` rendering."""
    row, col = (int(v) for v in np.asarray(agent_pos))
    return (row + 0.5) * cell_px, (col + 0.5) * cell_px


def heading_arrow(
    agent_pos, heading, length: float = 0.46, back: float = 0.26, half_width: float = 0.26, notch: float = 0.06
) -> np.ndarray:
    """float [4, 2] (x, y) corners of the agent's dart (an arrowhead), tip first, in data coordinates.

    The tip lies ``length`` cells from the cell centre along the heading, the two back
    corners ``back`` cells behind the centre and ``half_width`` to each side, and the notch
    between them ``notch`` cells behind the centre.  The tip is the dart's point farthest
    from the centre.
    """
    row, col = (float(v) for v in np.asarray(agent_pos))
    d_row, d_col = (float(v) for v in C.HEADING_DELTAS[int(heading) % C.NUM_HEADINGS])
    norm = np.hypot(d_row, d_col)
    forward = np.array([d_col, d_row]) / norm  # (dx, dy); y grows downwards (origin="upper")
    side = np.array([-forward[1], forward[0]])
    centre = np.array([col, row])
    base = centre - back * forward
    tip, notch_point = centre + length * forward, centre - notch * forward
    return np.stack([tip, base + half_width * side, notch_point, base - half_width * side])


def _rgb01(rgb) -> tuple[float, float, float]:
    return tuple(v / 255.0 for v in rgb)


def _new_figure(width_px: int, height_px: int) -> tuple[Figure, FigureCanvasAgg]:
    fig = Figure(figsize=(width_px / DPI, height_px / DPI), dpi=DPI)
    return fig, FigureCanvasAgg(fig)


def _finish(fig: Figure, canvas: FigureCanvasAgg, path) -> np.ndarray:
    canvas.draw()
    rgb = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    if path is not None:
        path = os.fspath(path)
        if os.path.dirname(path):
            os.makedirs(os.path.dirname(path), exist_ok=True)
        fig.savefig(path, dpi=DPI)
    return rgb


def render_topdown(
    params,
    scene_index: int,
    state=None,
    trajectory=None,
    target=None,
    path=None,
    *,
    categories=None,
    decorations: bool = True,
    crop: bool = True,
    labels: bool = True,
    cell_px: int = 28,
    title: str | None = None,
) -> np.ndarray:
    """The scene ``scene_index`` of ``params.bank`` seen from above.

    Args:
      params: EnvParams (only ``params.bank`` is read).
      scene_index: index into the bank (not the AI2-THOR number).
      state: an unbatched EnvState, or None; draws the agent as an arrow (its heading).
        Its target is highlighted unless ``target`` is given.
      trajectory: int [T, 2] (row, col) positions, drawn as a polyline with its start marked.
      target: category index to highlight (every instance), or None.
      path: write the picture there as PNG (folders are created).
      categories: category names (default: the setup with as many categories as the bank).
      decorations: title, axes, ticks and a legend around the grid.  Without them the grid
        fills the picture exactly, ``cell_px`` pixels per cell (for tests; see agent_pixel).
      crop: with decorations, show only the room and its walls (axes keep grid numbers).
      labels: write each object's category name beside it.
      cell_px: pixels per cell.
      title: replaces the default title.
    Returns:
      uint8 [H, W, 3] RGB picture.
    """
    bank = params.bank
    cell_type = np.asarray(bank.cell_type[scene_index])  # [G, G]
    obj_cat = np.asarray(bank.obj_cat[scene_index])
    obj_band = np.asarray(bank.obj_band[scene_index])
    rows, cols = cell_type.shape
    num_categories = int(np.asarray(bank.target_vectors).shape[0])
    categories = infer_categories(num_categories) if categories is None else tuple(categories)
    colors = category_colors(num_categories)
    if target is None and state is not None:
        target = int(np.asarray(state.target))

    # The rows and columns shown: the whole grid, or (crop) the room and its walls.
    r0, r1, c0, c1 = 0, rows, 0, cols
    if decorations and crop:
        inside = np.argwhere(cell_type != C.CELL_WALL)
        if len(inside):
            (r0, c0), (r1, c1) = np.maximum(inside.min(0) - 1, 0), np.minimum(inside.max(0) + 2, [rows, cols])
    grid_w, grid_h = (c1 - c0) * cell_px, (r1 - r0) * cell_px
    if decorations:
        left, bottom, legend_px, top = 50, 45, 170, 50
        # At least 520 pixels wide, so that the title (centred on the figure) fits.
        fig, canvas = _new_figure(max(left + grid_w + 15 + legend_px, 520), bottom + grid_h + top)
        width, height = fig.bbox.width, fig.bbox.height
        ax = fig.add_axes([left / width, bottom / height, grid_w / width, grid_h / height])
    else:
        fig, canvas = _new_figure(grid_w, grid_h)
        ax = fig.add_axes([0.0, 0.0, 1.0, 1.0])
        ax.set_axis_off()

    image = np.zeros((rows, cols, 3), np.uint8)
    for kind, rgb in CELL_RGB.items():
        image[cell_type == kind] = rgb
    kinds = (
        None
        if bank.furniture_sem is None
        else np.asarray(bank.furniture_sem[scene_index]) - (C.NUM_STRUCTURAL + num_categories)
    )
    if kinds is not None:  # layouts with priors: each furniture kind its own shade, named once per piece
        shades = np.round(255 * furniture_colors()).astype(np.uint8)
        image[kinds >= 0] = shades[kinds[kinds >= 0]]
    ax.imshow(image, origin="upper", interpolation="nearest", zorder=0)
    if kinds is not None and labels:
        for r, c in np.argwhere(kinds >= 0):
            k = kinds[r, c]
            if (r > 0 and kinds[r - 1, c] == k) or (c > 0 and kinds[r, c - 1] == k):
                continue  # named at the piece's first cell
            ax.text(
                c - 0.45,
                r - 0.45,
                C.FURNITURE_KINDS[k],
                ha="left",
                va="top",
                fontsize=max(4.0, 0.17 * cell_px),
                style="italic",
                color="#3a2a1a",
                zorder=2,
            )
    ax.set_xlim(c0 - 0.5, c1 - 0.5)
    ax.set_ylim(r1 - 0.5, r0 - 0.5)  # row 0 at the top
    if decorations:  # thin lines between cells, a tick on every cell
        ax.set_xticks(range(c0, c1), minor=False)
        ax.set_yticks(range(r0, r1), minor=False)
        ax.set_xticks(np.arange(c0, c1 + 1) - 0.5, minor=True)
        ax.set_yticks(np.arange(r0, r1 + 1) - 0.5, minor=True)
        ax.grid(which="minor", color="black", linewidth=0.3, alpha=0.25)
        ax.tick_params(which="minor", length=0)

    # Objects: colour per category, marker per height band.
    marker_size = 0.55 * cell_px * 72 / DPI
    for r, c in np.argwhere(obj_cat >= 0):
        cat, band = int(obj_cat[r, c]), int(obj_band[r, c])
        if target is not None and cat == int(target):
            ax.add_patch(
                Rectangle((c - 0.5, r - 0.5), 1, 1, fill=False, edgecolor=_rgb01(TARGET_RGB), linewidth=2.5, zorder=3)
            )
        ax.plot(
            [c],
            [r],
            marker=BAND_MARKERS.get(band, "o"),
            markersize=marker_size,
            color=colors[cat],
            markeredgecolor="black",
            markeredgewidth=0.6,
            linestyle="none",
            zorder=4,
        )
        if labels:
            above = c % 2 == 0  # neighbours in a row alternate above/below: labels do not overlap
            ax.annotate(
                categories[cat],
                (c, r),
                xytext=(0, (1 if above else -1) * (0.45 * cell_px * 72 / DPI + 1)),
                textcoords="offset points",
                ha="center",
                va="bottom" if above else "top",
                fontsize=max(5.0, 0.22 * cell_px),
                zorder=5,
                fontweight="bold" if target is not None and cat == int(target) else "normal",
                color=_rgb01(TARGET_RGB) if target is not None and cat == int(target) else "black",
                bbox=dict(boxstyle="round,pad=0.1", facecolor="white", alpha=0.7, linewidth=0),
            )

    if trajectory is not None:
        traj = np.asarray(trajectory, np.float64).reshape(-1, 2)
        if len(traj):
            ax.plot(traj[:, 1], traj[:, 0], color=_rgb01(TRAJECTORY_RGB), linewidth=2.0, alpha=0.85, zorder=6)
            ax.plot(
                [traj[0, 1]],
                [traj[0, 0]],
                marker="o",
                markersize=0.3 * cell_px * 72 / DPI,
                color=_rgb01(TRAJECTORY_RGB),
                linestyle="none",
                zorder=6,
            )

    if state is not None:
        corners = heading_arrow(np.asarray(state.agent_pos), int(np.asarray(state.heading)))
        ax.add_patch(
            Polygon(corners, closed=True, facecolor=_rgb01(AGENT_RGB), edgecolor="none", antialiased=False, zorder=10)
        )

    if decorations:
        number = int(np.asarray(bank.numbers[scene_index]))
        if title is None:
            title = scene_name(number, np.asarray(bank.room_types[scene_index]))
            if target is not None:
                title += f", target {categories[int(target)]}"
            if state is not None:
                r, c = (int(v) for v in np.asarray(state.agent_pos))
                horizon = "level" if int(np.asarray(state.horizon)) == 0 else "30° down"
                title += f"\nagent at (row {r}, col {c}), heading {int(np.asarray(state.heading))}, {horizon}"
        fig.suptitle(title, fontsize=9, y=1 - 4 / height, va="top")
        ax.set_xlabel("col", fontsize=8)
        ax.set_ylabel("row", fontsize=8)
        ax.tick_params(labelsize=6)
        present = sorted({int(v) for v in obj_cat[obj_cat >= 0]})
        handles = [
            Patch(facecolor=_rgb01(CELL_RGB[k]), edgecolor="black", label=n)
            for k, n in ((C.CELL_WALL, "wall"), (C.CELL_FURNITURE, "furniture"), (C.CELL_FLOOR, "floor"))
        ]
        handles += [
            Line2D(
                [],
                [],
                marker=BAND_MARKERS.get(int(obj_band[obj_cat == k][0]), "o"),
                color=colors[k],
                markeredgecolor="black",
                linestyle="none",
                label=categories[k],
            )
            for k in present
        ]
        handles += [
            Line2D([], [], marker=m, color="white", markeredgecolor="black", linestyle="none", label=BAND_NAMES[b])
            for b, m in BAND_MARKERS.items()
        ]
        if target is not None:
            handles.append(Patch(facecolor="none", edgecolor=_rgb01(TARGET_RGB), linewidth=2, label="target"))
        if trajectory is not None:
            handles.append(Line2D([], [], color=_rgb01(TRAJECTORY_RGB), linewidth=2, label="trajectory"))
        if state is not None:
            handles.append(Line2D([], [], marker=">", color=_rgb01(AGENT_RGB), linestyle="none", label="agent"))
        fig.legend(
            handles=handles,
            loc="upper left",
            fontsize=7,
            frameon=False,
            bbox_to_anchor=((left + grid_w + 10) / width, 1 - top / height),
        )
    return _finish(fig, canvas, path)


def scene_name(number: int, room_types) -> str:
    """ "FloorPlan201 (living room)" or "House3004 (kitchen, bedroom, bathroom)"."""
    rooms = ", ".join(C.ROOM_TYPES[int(t)].replace("_", " ") for t in room_types if t >= 0)
    return f"{'House' if C.is_house(number) else 'FloorPlan'}{number} ({rooms})"


def _sem_depth(obs_or_view, max_depth):
    """(sem int [3, W], depth float [3, W] in cells or None, label of the depth numbers)."""
    if isinstance(obs_or_view, dict):
        obs_or_view = obs_or_view["view"]
    if isinstance(obs_or_view, (tuple, list)):
        sem, depth = (np.asarray(a) for a in obs_or_view)
        return sem.astype(np.int64), depth.astype(np.float64), True
    view = np.asarray(obs_or_view)
    if view.ndim != 3:
        raise ValueError(
            f"expected a view [3, W, n_semantic + 1], an observation dict or (sem, depth); got shape {view.shape}"
        )
    depth = view[..., -1].astype(np.float64)  # depth / max_depth
    if max_depth is not None:
        return np.argmax(view[..., :-1], -1), depth * max_depth, True
    return np.argmax(view[..., :-1], -1), depth, False


def view_image(sem, depth, num_categories: int) -> np.ndarray:
    """float [3, W, 3] RGB in [0, 1]: each pixel's semantic colour, darker with depth.

    sem: int [3, W] (catalog.SEM_*, NUM_STRUCTURAL + category, or a furniture kind's class
    after the categories: catalog.furniture_sem); depth: float [3, W]
    (any unit; the shading is relative to the largest depth in the view).
    """
    sem = np.asarray(sem)
    depth = np.asarray(depth, np.float64)
    structural = np.array([_rgb01(SEM_RGB[k]) for k in range(C.NUM_STRUCTURAL)])
    palette = np.concatenate([structural, category_colors(num_categories), furniture_colors()])
    rgb = palette[np.clip(sem, 0, len(palette) - 1)]
    far = max(float(depth.max()), 1e-6)
    shade = 1.0 - 0.6 * np.clip(depth / far, 0.0, 1.0)
    return rgb * shade[..., None]


def render_view(
    obs_or_view_sem_depth,
    categories,
    path=None,
    *,
    max_depth: float | None = None,
    title: str | None = None,
    pixel_px: int = 40,
) -> np.ndarray:
    """The first-person view (3 rows x W columns) as a colour picture with a legend.

    Args:
      obs_or_view_sem_depth: an unbatched observation dict, its "view" [3, W, n + 1]
        (one-hot classes, then depth / env.max_depth), or a pair (sem [3, W], depth [3, W]
        in cells) as from env.view(state, params).
      categories: the setup's category names (env.categories).
      path: write the picture there as PNG.
      max_depth: env.max_depth, to print an observation's depths in metres (a pair's
        depths are in cells already).
      title: a title above the view.
      pixel_px: screen pixels per view pixel.
    Returns:
      uint8 [H, W, 3] RGB picture.
    """
    categories = tuple(categories)
    sem, depth, in_cells = _sem_depth(obs_or_view_sem_depth, max_depth)
    rows, width = sem.shape
    image = view_image(sem, depth, len(categories))
    shown = depth * C.CELL_SIZE_M if in_cells else depth
    unit = "m" if in_cells else "fraction of max depth"
    left, bottom, top, legend_px = 60, 45, 35, 130
    view_w, view_h = width * pixel_px, rows * pixel_px
    fig, canvas = _new_figure(left + view_w + 15 + legend_px, bottom + view_h + top)
    fig_w, fig_h = fig.bbox.width, fig.bbox.height
    ax = fig.add_axes([left / fig_w, bottom / fig_h, view_w / fig_w, view_h / fig_h])
    ax.imshow(image, origin="upper", interpolation="nearest")
    for r in range(rows):
        for c in range(width):
            dark = image[r, c].mean() < 0.45
            ax.text(
                c, r, f"{shown[r, c]:.2g}", ha="center", va="center", fontsize=6, color="white" if dark else "black"
            )
    ax.set_xticks(range(width))
    ax.set_yticks(range(rows))
    ax.set_yticklabels(["top", "middle", "bottom"] if rows == 3 else range(rows))
    ax.tick_params(labelsize=7)
    ax.set_xlabel(f"view column, left to right (numbers: depth in {unit})", fontsize=8)
    ax.set_title(title or "first-person view (colour: semantic class, darker: farther)", fontsize=9)
    names = list(STRUCTURAL_NAMES) + list(categories) + list(C.FURNITURE_KINDS)
    palette = view_image(np.arange(len(names))[None], np.zeros((1, len(names))), len(categories))[0]
    present = sorted({int(v) for v in sem.reshape(-1)})
    handles = [Patch(facecolor=palette[k], edgecolor="black", label=names[k]) for k in present if k < len(names)]
    fig.legend(
        handles=handles,
        loc="upper left",
        fontsize=7,
        frameon=False,
        bbox_to_anchor=((left + view_w + 10) / fig_w, 1 - top / fig_h),
    )
    return _finish(fig, canvas, path)


__all__ = [
    "AGENT_RGB",
    "agent_pixel",
    "category_colors",
    "heading_arrow",
    "render_topdown",
    "render_view",
    "view_image",
]
