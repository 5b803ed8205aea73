"""The progress bar of training and sweeps (tqdm, advanced once per chunk on the host)."""

from __future__ import annotations


def progress_bar(total: int, initial: int, enabled: bool):
    """A tqdm bar over `total` updates starting at `initial`; returns `advance(n, postfix)`:
    call it with (n, {name: value}) after each chunk and with (0, None) to close the bar."""
    from tqdm import tqdm

    bar = tqdm(total=total, initial=initial, unit="upd", disable=not enabled, dynamic_ncols=True,
               bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} updates [{elapsed}<{remaining}{postfix}]")  # fmt: skip

    def advance(n: int, postfix: dict | None) -> None:
        if postfix is None:
            bar.close()
            return
        bar.set_postfix(postfix, refresh=False)
        bar.update(n)

    return advance
