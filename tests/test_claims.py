"""The rule that ties the docs' words to their intervals (docs/results.md, "How results
are worded"), held by a test: in every sentence of the README and the docs that quotes a
difference with its interval, an equivalence word needs the interval inside the margin,
and "helps" or "costs" needs it clear of 0."""

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CLAIM_FILES = ("README.md", "docs/results.md", "docs/mechanism.md", "docs/priors.md", "docs/houses.md",
               "docs/deviations.md", "docs/foresight.md", "docs/ceiling.md", "docs/usage.md")  # fmt: skip

MARGIN = 3.8  # SR points: the paper's effect, the margin declared for "level" unless a sentence names another
# Equivalence: the interval inside [-margin, +margin]. Only verdict uses: "end level", "level
# with", not "an optimisation level".
EQUIVALENCE = re.compile(r"\b(?:(?:are|is|end|ends|ended|stay|stays|arms?) level|level with|equivalent|on par|"
                         r"indistinguishable|no difference|costs? nothing|gains? nothing)\b", re.I)  # fmt: skip
# A direction: the interval clear of 0.
DIRECTION = re.compile(r"\b(?:helps|hurts|costs|gains|lowers|raises)\b(?! nothing)", re.I)
INTERVAL = re.compile(r"([+-]?\d+(?:\.\d+)?)\s*\[([+-]?\d+(?:\.\d+)?),\s*([+-]?\d+(?:\.\d+)?)\]")
NAMED_MARGIN = re.compile(r"margin (?:of )?±?\s*(\d+(?:\.\d+)?)")


def sentences(text: str):
    """Prose sentences of a Markdown text (table rows and code left out), lines of a
    paragraph or bullet joined."""
    text = re.sub(r"```.*?```", "", text, flags=re.S)
    blocks, current = [], []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith(("|", "#")) or re.match(r"^([-*]|\d+\.) ", stripped):
            if current:
                blocks.append(" ".join(current))
            current = [] if not stripped or stripped.startswith(("|", "#")) else [stripped]
        else:
            current.append(stripped)
    if current:
        blocks.append(" ".join(current))
    for block in blocks:
        yield from re.split(r"(?<!e\.g)(?<!i\.e)(?<!vs)\.\s+(?=[A-Z*(`])|;\s+|:\s+(?=[A-Z])", block)


def violations(sentence: str) -> list[str]:
    """What in `sentence` breaks the rule: each verdict word is judged by the interval that
    follows it most closely in the sentence (else the one before it)."""
    intervals = [(m.start(), float(m.group(2)), float(m.group(3))) for m in INTERVAL.finditer(sentence)]
    if not intervals:
        return []
    named = NAMED_MARGIN.search(sentence)
    margin = float(named.group(1)) if named else MARGIN
    out = []
    for pattern, kind in ((EQUIVALENCE, "equivalence"), (DIRECTION, "direction")):
        for word in pattern.finditer(sentence):
            after = [iv for iv in intervals if iv[0] > word.start()]
            _, low, high = after[0] if after else intervals[-1]
            if kind == "equivalence" and not (-margin <= low and high <= margin):
                out.append(f"{word.group(0)!r} with [{low}, {high}] outside ±{margin}")
            if kind == "direction" and low <= 0 <= high:
                out.append(f"{word.group(0)!r} with [{low}, {high}], which holds 0")
    return out


def test_the_rule_reads_verdicts_and_leaves_other_uses_alone():
    assert violations("The arms end level: +0.9 [-0.9, +2.6] SR.") == []
    assert violations("The arms end level: +0.6 [-3.3, +4.5] SPL.")
    assert violations("The arms end level within a margin of 5: +0.6 [-3.3, +4.5] SPL.") == []
    assert violations("The critic costs -4.3 [-10.9, +2.3] SR.")
    assert violations("The critic costs -5.6 [-7.5, -3.7] SPL.") == []
    assert violations("At the default optimisation level the run gives +1.0 [-5.0, +7.0].") == []
    assert violations("An arm that matches the base: +1.0 [-5.0, +7.0].") == []
    assert violations("Shuffled i_tau costs nothing (+0.4 [-2.4, +3.1]).") == []
    assert violations("The critic costs nothing: -0.7 [-5.5, +4.2].")
    assert list(sentences("One. Two is level: +1 [-1, +2]; three costs\n-5 [-7, -3].\n\n| a | level [-9, 9] |")) == [
        "One", "Two is level: +1 [-1, +2]", "three costs -5 [-7, -3]."]


@pytest.mark.parametrize("name", CLAIM_FILES)
def test_every_claim_sentence_follows_the_rule(name):
    path = REPO / name
    if not path.exists():
        pytest.skip(f"{name} is not there")
    bad = [f"{v}: {s.strip()[:160]}" for s in sentences(path.read_text()) for v in violations(s)]
    assert not bad, f"{name}: words stronger than their intervals (docs/results.md's rule):\n" + "\n".join(bad)


def test_the_readme_is_a_page_a_newcomer_reads_in_two_minutes():
    """At most 110 lines and 1,000 words (issue 61): everything else lives in docs/."""
    text = (REPO / "README.md").read_text()
    assert len(text.splitlines()) <= 110 and len(text.split()) <= 1000, (len(text.splitlines()), len(text.split()))
