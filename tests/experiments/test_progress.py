"""experiments.running.progress: one progress bar for every program, a line per chunk without it."""

import re


from experiments import train as train_cli
from experiments.running import progress, sweeps


def test_progress_bar_is_shared_and_without_the_bar_logs_a_line_per_chunk(capsys):
    advance = progress.progress_bar(total=5, initial=1, enabled=False)
    advance(2, {"method": "a3c", "SR": "0.1"})
    advance.at(4)  # inside a chunk: no line
    advance(2, {"method": "a3c", "val SR": "12.5%"})
    advance(0, None)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    assert re.fullmatch(r"\[\d\d:\d\d:\d\d\] 3/5 updates, 0\.0 min: method a3c, SR 0\.1", lines[0]), lines[0]
    assert re.fullmatch(r"\[\d\d:\d\d:\d\d\] 5/5 updates, 0\.0 min: method a3c, val SR 12\.5%", lines[1]), lines[1]
    assert not hasattr(train_cli, "_progress")
    assert train_cli.progress_bar is sweeps.progress_bar is progress.progress_bar
    # Where a resumed run starts: no line, and not counted in the rate (tqdm's `initial`).
    for enabled in (True, False):
        capsys.readouterr()
        advance = progress.progress_bar(total=10, initial=0, enabled=enabled, tty=True)
        advance.skip(6)
        advance.skip(4)  # never back
        assert advance.position() == 6
        advance(2, {"method": "a3c"})
        assert advance.position() == 8
        advance(0, None)
    lines = capsys.readouterr().err.splitlines()  # without the bar: the chunk's line, none for the skip
    assert len(lines) == 1 and " 8/10 updates" in lines[0], lines
