"""Boolean grid helpers of the layout generators (numpy): connectivity and neighbourhoods."""

from __future__ import annotations

from collections import deque

import numpy as np

from envs import catalog as C


def walkable_connected(cell_type: np.ndarray) -> bool:
    """Whether the floor cells of ``cell_type`` form one 4-connected region (and exist)."""
    free = np.argwhere(cell_type == C.CELL_FLOOR)
    if len(free) == 0:
        return False
    seen = np.zeros(cell_type.shape, bool)
    queue = deque([tuple(free[0])])
    seen[tuple(free[0])] = True
    count = 1
    while queue:
        r, c = queue.popleft()
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            nr, nc = r + dr, c + dc
            if cell_type[nr, nc] == C.CELL_FLOOR and not seen[nr, nc]:
                seen[nr, nc] = True
                count += 1
                queue.append((nr, nc))
    return count == len(free)


def next_to(mask: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Cells of ``mask`` with a 4-neighbour in the boolean grid ``other``."""
    near = np.zeros_like(mask)
    near[1:, :] |= other[:-1, :]
    near[:-1, :] |= other[1:, :]
    near[:, 1:] |= other[:, :-1]
    near[:, :-1] |= other[:, 1:]
    return mask & near


def within(mask: np.ndarray, radius: int) -> np.ndarray:
    """Cells within Chebyshev distance ``radius`` of a cell of ``mask`` (its own included)."""
    out = mask.copy()
    for _ in range(radius):
        grown = out.copy()
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                src = out[max(-dr, 0) : out.shape[0] - max(dr, 0), max(-dc, 0) : out.shape[1] - max(dc, 0)]
                grown[max(dr, 0) : out.shape[0] - max(-dr, 0), max(dc, 0) : out.shape[1] - max(-dc, 0)] |= src
        out = grown
    return out
