"""The studies as data: each study's plan, runner, archives, data test and doc sections
(`STUDIES`, from which docs/studies.md's table is generated), and the comparisons whose
figures and words the docs quote (`Comparison`), each read from its archive and judged by
the project's one rule (`experiments.reporting.verdicts.verdict`).

Nothing here writes: the pages' blocks (`experiments.reporting.pages`, one module a page)
are made from these, `experiments.regenerate` puts them between the docs' markers, and a
default-tier test (tests/experiments/test_regenerate.py) fails when the docs drift from the
archives. An archive is read in place (`Archives`: the JSON members of a
docs/data/*.tar.xz, each read once), never unpacked; an arm of it is a `Ref`, and two arms
paired over their seeds a `Pair`.
"""

from __future__ import annotations

import dataclasses
import json
import tarfile
from pathlib import Path
from typing import Any, Optional, Sequence, Union

import numpy as np

from experiments import rundir
from experiments.reporting import report, tuning
from experiments.reporting.verdicts import verdict

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "docs" / "data"
# The paper's gain (Table 1): the margin every "level" of the studies here is declared against.
PAPER_MARGIN = 3.8


@dataclasses.dataclass(frozen=True)
class Study:
    """One study's home (a row of docs/studies.md). Paths are the repository's; an archive
    not made yet is named in words (no '/')."""

    name: str
    question: str
    plan: Optional[str]
    runner: str  # "commands" (written in its doc section or plan) or a script's path
    archives: tuple[str, ...]
    data_test: str
    sections: tuple[str, ...]  # "doc.md#anchor"


STUDIES: tuple[Study, ...] = (
    Study(
        "fair",
        "Does ForeSIT beat its base when each arm has its own validated settings?",
        None,
        "commands",
        tuple(
            f"docs/data/{n}"
            for n in (
                "fair_lr3e-4.tar.xz",
                "fair_tune.tar.xz",
                "fair_3x.tar.xz",
                "fair_tune_3x.tar.xz",
                "fair_tune_org.tar.xz",
                "fair_bases.tar.xz",
                "fair_fw.tar.xz",
                "fair_noise.tar.xz",
                "fair_probe_lr3e-4.json",
                "fair_probe_noise.json",
            )
        ),
        "tests/studies/test_fair_study_data.py",
        (
            "docs/fair.md#fairness-each-arm-at-its-own-validated-learning-rate-5-seeds-2026-11-27",
            "docs/fair.md#fairness-the-three-arms-at-3e-4-for-3x-the-budget-5-seeds-2026-11-27",
        ),
    ),
    Study(
        "replication_3x",
        "Does the 3x answer hold on fresh seeds (issue 69)?",
        "docs/plans/replication_3x.md",
        "commands",
        ("docs/data/replication_3x.tar.xz",),
        "tests/studies/test_replication_data.py",
        ("docs/replication.md#replication-the-3x-pair-on-fresh-seeds-seeds-5-9-2026-11-29",),
    ),
    Study(
        "reference_ppo",
        "Where does a plain PPO land on the same episodes?",
        None,
        "benchmarks/reference_ppo.py",
        ("docs/data/reference_ppo_epyc.json", "docs/data/reference_ppo_h200.json"),
        "tests/studies/test_reference_ppo_data.py",
        ("docs/reference_ppo.md#a-reference-row-purejaxrls-ppo-on-the-same-episodes-5-seeds-2026-11-28",),
    ),
    Study(
        "priors",
        "The paper's question in rooms that keep real homes' regularities",
        None,
        "scripts/priors_study_gpu.sh",
        tuple(
            f"docs/data/{n}"
            for n in (
                "priors_savn.tar.xz",
                "priors_org.tar.xz",
                "priors_org_control.tar.xz",
                "priors_probe_savn.json",
                "priors_probe_org.json",
            )
        ),
        "tests/studies/test_priors_data.py",
        ("docs/priors.md#the-papers-question-there-5-seeds-2026-11-27",),
    ),
    Study(
        "houses",
        "Does imagination help on long paths in houses?",
        None,
        "commands",
        ("docs/data/house_study.tar.xz",),
        "tests/studies/test_house_study_data.py",
        ("docs/houses.md#does-imagination-help-on-long-paths-in-houses-the-mechanism-study-repeated",),
    ),
    Study(
        "foresight",
        "Can a first view tell where an unseen target is?",
        None,
        "commands",
        ("docs/data/foresight_today.json", "docs/data/foresight_priors.json", "docs/data/foresight_levers.json"),
        "tests/studies/test_foresight_data.py",
        ("docs/foresight.md#the-method",),
    ),
    Study(
        "ceiling",
        "What would a perfect imagination of success give, through the head?",
        None,
        "commands",
        tuple(
            f"docs/data/{n}"
            for n in (
                "ceiling_savn.tar.xz",
                "ceiling_savn_epyc.tar.xz",
                "ceiling_savn_noiseoff.tar.xz",
                "ceiling_priors.tar.xz",
                "ceiling_priors_epyc.tar.xz",
                "ceiling_priors_noiseoff.tar.xz",
                "ceiling_range4.tar.xz",
                "ceiling_range4_noiseoff.tar.xz",
                "ceiling_probe_savn.json",
                "ceiling_probe_range4.json",
            )
        ),
        "tests/studies/test_ceiling_data.py",
        ("docs/ceiling.md#the-oracle-imagination-privileged",),
    ),
    Study(
        "channels",
        "Through which channel can the goal view help (issue 68)?",
        "docs/plans/ceiling_channels.md",
        "commands",
        tuple(
            f"docs/data/{n}"
            for n in (
                "channels_stage1.tar.xz",
                "channels_stage2.tar.xz",
                "channels_stage3.tar.xz",
                "channels_rooms.tar.xz",
            )
        ),
        "tests/studies/test_channels_data.py",
        ("docs/ceiling.md#channels-that-can-carry-it-compasses-first-issue-68-docsplansceiling_channelsmd",),
    ),
    Study(
        "targets",
        "Which form of imagining success helps as a training target (issue 79)?",
        "docs/plans/imagination_targets.md",
        "commands",
        (
            "docs/data/targets_pilot.tar.xz",
            "docs/data/targets_stage1.tar.xz",
            "docs/data/targets_stage2.tar.xz",
            "docs/data/targets_stage2_content.tar.xz",
            "docs/data/targets_stage2_rooms.tar.xz",
            "docs/data/targets_stage2_9000.tar.xz",
        ),
        "tests/studies/test_targets_data.py",
        (
            "docs/targets.md#the-pilot-each-targets-weight-seeds-10-12-1500-updates-2026-12-02",
            "docs/targets.md#stage-1-the-three-targets-beside-the-base-seeds-0-4-3000-updates-2026-12-02",
            "docs/targets.md#stage-2-the-compass-target-on-fresh-seeds-5-9-3000-updates-2026-12-02",
            "docs/targets.md#stage-2-the-content-control-seeds-5-9-3000-updates-2026-12-02",
            "docs/targets.md#stage-2-the-compass-pair-in-todays-rooms-seeds-5-9-3000-updates-2026-12-02",
            "docs/targets.md#stage-2-the-compass-pair-at-9000-updates-seeds-5-9-2026-12-02",
        ),
    ),
)


def _code(items) -> str:
    return ", ".join(f"`{x}`" if "/" in x else x for x in items)


def studies_table() -> str:
    """docs/studies.md's table, one row a study."""
    header = (
        "| study | question | plan | runner | archives | data test | doc section |\n|---|---|---|---|---|---|---|\n"
    )
    rows = []
    for s in STUDIES:
        runner = "commands" if s.runner == "commands" else f"`{s.runner}`"
        plan = f"`{s.plan}`" if s.plan else ""
        cells = [s.name, s.question, plan, runner, _code(s.archives), f"`{s.data_test}`", _code(s.sections)]
        rows.append("| " + " | ".join(cells).replace("|  |", "| |") + " |")
    return header + "\n".join(rows) + "\n"


# ---------------------------------------------------------------------- reading archives
class Archives:
    """docs/data's files, read in place, each once: an archive's JSON members (every one but
    the arms' progress files: `member`), among them its arms' per-seed results (`results`: an
    arm's `rundir.RESULTS_FILE` under `rundir.METHODS`, or another results file it keeps
    there, such as an extended run's `rundir.kept_results`), and docs/data's JSON files
    (`json`; a probe's `probe`). An archive is decompressed once and a member parsed when
    first asked for."""

    def __init__(self, data: Path = DATA):
        self.data = data
        self._names: dict[str, list[str]] = {}  # archive -> its JSON members, in the archive's order
        self._raw: dict[str, dict[str, bytes]] = {}  # archive -> {member: its bytes, until parsed}
        self._parsed: dict[str, dict[str, Any]] = {}
        self._files: dict[str, Any] = {}

    def _members(self, archive: str) -> list[str]:
        if archive not in self._names:
            with tarfile.open(self.data / archive) as tar:
                raw = {
                    m.name: tar.extractfile(m).read()
                    for m in tar.getmembers()
                    if m.isfile() and m.name.endswith(".json") and not m.name.endswith("/progress.json")
                }
            self._names[archive], self._raw[archive], self._parsed[archive] = list(raw), raw, {}
        return self._names[archive]

    def names(self, archive: str) -> list[str]:
        """The JSON members of docs/data/`archive` (their paths inside it; progress files left out)."""
        return list(self._members(archive))

    def member(self, archive: str, name: str) -> Any:
        """The JSON member `name` (its path inside the archive) of docs/data/`archive`."""
        if name not in self._members(archive):
            raise KeyError(f"{archive} holds no {name!r}")
        parsed = self._parsed[archive]
        if name not in parsed:
            parsed[name] = json.loads(self._raw[archive].pop(name))
        return parsed[name]

    def _arm_files(self, archive: str, file: str) -> dict[str, str]:
        """{arm: its member} of the arms of `archive` that keep `file`, in the archive's order."""
        arms: dict[str, str] = {}
        for name in self._members(archive):
            parts = name.split("/")
            if parts[-1] == file and len(parts) >= 3 and parts[-3] == rundir.METHODS:
                arms[parts[-2]] = name
        return arms

    def arms(self, archive: str, file: str = rundir.RESULTS_FILE) -> list[str]:
        """The arms of docs/data/`archive` that hold results (`file`), in the archive's order."""
        return list(self._arm_files(archive, file))

    def results(self, archive: str, arm: str, file: str = rundir.RESULTS_FILE) -> list[dict]:
        """The per-seed results (the file's "results") of `arm` in docs/data/`archive`:
        results.json's, or those of another results `file` the arm keeps."""
        arms = self._arm_files(archive, file)
        if arm not in arms:
            raise KeyError(f"{archive} holds no arm {arm!r} with {file}; it holds {sorted(arms)}")
        return self.member(archive, arms[arm])["results"]

    def sweep(self, archive: str, arms: Optional[Sequence[str]] = None) -> dict[str, list[dict]]:
        """{arm: per-seed results} of `arms` (default: every arm) of docs/data/`archive`."""
        return {arm: self.results(archive, arm) for arm in (self.arms(archive) if arms is None else arms)}

    def json(self, name: str) -> Any:
        """docs/data/`name`, a JSON file (a probe's, the PPO reference's, the foresight tool's)."""
        if name not in self._files:
            self._files[name] = json.loads((self.data / name).read_text())
        return self._files[name]

    def probe(self, name: str) -> dict[str, list[dict]]:
        """{arm: per-seed probe} of an `experiments.probe` output kept as docs/data/`name`."""
        return self.json(name)["methods"]


def same_seeds(a: list[dict], b: list[dict], what: str) -> None:
    """Refuse to pair per-seed results `a` and `b` run on other seeds (`what`: the pair, in words)."""
    if [r["seed"] for r in a] != [r["seed"] for r in b]:
        raise ValueError(f"{what}: not run on the same seeds")


# The validation SR of each seed's selected model (`tuning.selection_sr`), as a metric.
VALIDATION = "validation SR"


def values(per_seed: list[dict], metric: str) -> np.ndarray:
    """One value a seed: `report.values`'s columns, or the validation SR of the selected model."""
    return tuning.selection_sr(per_seed) if metric == VALIDATION else report.values(per_seed, metric)


@dataclasses.dataclass(frozen=True)
class Chosen:
    """An arm chosen on validation among candidates (`experiments.tune`'s rule,
    `tuning.choose`: the highest mean validation SR of the selected models)."""

    candidates: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class Unchosen:
    """Of two candidates, the one validation did not choose (`Chosen`'s other)."""

    candidates: tuple[str, str]


Arm = Union[str, Chosen]


def resolve(archives: Archives, archive: str, arm: Union[Arm, Unchosen]) -> str:
    if isinstance(arm, str):
        return arm
    chosen = tuning.choose({c: archives.results(archive, c) for c in arm.candidates})
    if isinstance(arm, Unchosen):
        return next(c for c in arm.candidates if c != chosen)
    return chosen


@dataclasses.dataclass(frozen=True)
class Ref:
    """An arm of an archive; `file`: its results.json, or another results file it keeps (an
    extended run's results at its first budget, `rundir.kept_results`)."""

    archive: str
    arm: Union[Arm, Unchosen]
    file: str = rundir.RESULTS_FILE

    def name(self, archives: Archives) -> str:
        return resolve(archives, self.archive, self.arm)

    def results(self, archives: Archives) -> list[dict]:
        return archives.results(self.archive, self.name(archives), self.file)


@dataclasses.dataclass(frozen=True)
class Pair:
    """B - A, paired over the seeds the two arms share (they must be the same); the two may
    be of two archives run on the same seeds."""

    a: Ref
    b: Ref
    label: Optional[str] = None  # default: "B - A" with the arms' names

    def name(self, archives: Archives) -> str:
        return self.label or f"{self.b.name(archives)} - {self.a.name(archives)}"

    def sides(self, archives: Archives, metric: str) -> tuple[np.ndarray, np.ndarray]:
        ra, rb = self.a.results(archives), self.b.results(archives)
        same_seeds(ra, rb, f"{self.name(archives)} ({self.a.archive}, {self.b.archive})")
        return values(ra, metric), values(rb, metric)

    def differences(self, archives: Archives, metric: str) -> np.ndarray:
        a, b = self.sides(archives, metric)
        return b - a


@dataclasses.dataclass(frozen=True)
class Comparison:
    """B - A on `metric`, paired over the seeds of one archive, judged by the rule with
    `margin`."""

    label: str  # what the docs call it
    scope: str  # the family, budget, seeds and machine, in words
    archive: str
    a: Arm
    b: Arm
    metric: str = "SR"
    margin: float = PAPER_MARGIN
    section: str = ""  # where the docs report it ("doc.md#anchor")

    def differences(self, archives: Archives) -> np.ndarray:
        return Pair(Ref(self.archive, self.a), Ref(self.archive, self.b), self.label).differences(archives, self.metric)

    def row(self, archives: Archives) -> str:
        v = verdict(self.differences(archives), self.metric, self.margin)
        label = f"[{self.label}]({self.section})" if self.section else self.label
        return f"| {label} | {self.scope} | {self.metric} | {v.figures()} | {v.words()} |"


def comparisons_table(comparisons, archives: Archives) -> str:
    header = "| B - A | where, how long, which seeds | metric | mean [95% CI] | verdict |\n|---|---|---|---|---|\n"
    return header + "\n".join(c.row(archives) for c in comparisons) + "\n"


A3 = "a3c@learning_rate=3e-4"
F3 = "a3c+foresit@learning_rate=3e-4"
CRITIC = "a3c+critic@learning_rate=3e-4"
HEAD_ORACLE = "a3c+oracle@learning_rate=3e-4,sigma2_max=0"
FAIR = "docs/fair.md"
REPLICATION = "docs/replication.md"
CEILING = "docs/ceiling.md"
TARGETS_STAGE1 = "docs/targets.md#stage-1-the-three-targets-beside-the-base-seeds-0-4-3000-updates-2026-12-02"
TARGETS_STAGE2 = "docs/targets.md#stage-2-the-compass-target-on-fresh-seeds-5-9-3000-updates-2026-12-02"

# The comparisons the README's Results quote, in the order a reader asks them.
README_COMPARISONS: tuple[Comparison, ...] = (
    Comparison(
        "a3c+foresit - a3c, each at its validated rate",
        "rooms, 3000, 0-4",
        "fair_tune.tar.xz",
        Chosen((A3, "a3c@learning_rate=1e-3")),
        Chosen((F3, "a3c+foresit@learning_rate=1e-3")),
        section=f"{FAIR}#fairness-each-arm-at-its-own-validated-learning-rate-5-seeds-2026-11-27",
    ),
    Comparison(
        "a3c+foresit - a3c, both at 3e-4",
        "rooms, 9000, 0-4 (Xeon)",
        "fair_3x.tar.xz",
        A3,
        F3,
        section=f"{FAIR}#fairness-the-three-arms-at-3e-4-for-3x-the-budget-5-seeds-2026-11-27",
    ),
    Comparison(
        "a3c+foresit@3e-4 - a3c at its validated rate",
        "rooms, 9000, 5-9 (EPYC)",
        "replication_3x.tar.xz",
        Chosen((A3, "a3c@learning_rate=1e-3")),
        F3,
        section=f"{REPLICATION}#replication-the-3x-pair-on-fresh-seeds-seeds-5-9-2026-11-29",
    ),
    Comparison(
        "a3c+foresit - a3c",
        "houses, 12,000, 0-4",
        "house_study.tar.xz",
        "a3c",
        "a3c+foresit",
        section="docs/houses.md#does-imagination-help-on-long-paths-in-houses-the-mechanism-study-repeated",
    ),
    Comparison(
        "a3c+foresit - a3c+critic (the critic held)",
        "houses, 12,000, 0-4",
        "house_study.tar.xz",
        "a3c+critic",
        "a3c+foresit",
        section="docs/houses.md#does-imagination-help-on-long-paths-in-houses-the-mechanism-study-repeated",
    ),
    Comparison(
        "compass every step, encoder (privileged) - critic",
        "priors, range 4, 3000, 0-4",
        "channels_stage1.tar.xz",
        CRITIC,
        "a3c+compass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0",
        section=f"{CEILING}#stage-1-can-a-compass-be-carried-rooms-with-priors-range-4-quick-seeds-0-4-2026-11-29",
    ),
    Comparison(
        "compass of the start, held (privileged) - critic",
        "priors, range 4, 3000, 0-4",
        "channels_stage1.tar.xz",
        CRITIC,
        "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0",
        section=f"{CEILING}#stage-1-can-a-compass-be-carried-rooms-with-priors-range-4-quick-seeds-0-4-2026-11-29",
    ),
    Comparison(
        "compass of the start, held (privileged) - critic",
        "priors, range 4, 3000, 0-4",
        "channels_stage1.tar.xz",
        CRITIC,
        "a3c+startcompass@learning_rate=3e-4,imagination_input=encoder,sigma2_max=0",
        metric="SPL",
        section=f"{CEILING}#stage-1-can-a-compass-be-carried-rooms-with-priors-range-4-quick-seeds-0-4-2026-11-29",
    ),
    Comparison(
        "goal view, head (privileged) - critic",
        "priors, range 4, 9000, 0-4",
        "channels_stage3.tar.xz",
        CRITIC,
        HEAD_ORACLE,
        section=f"{CEILING}#stage-3-three-times-the-budget-rooms-with-priors-range-4-seeds-0-4-2026-11-29",
    ),
    Comparison(
        "goal view, head (privileged) - critic",
        "rooms, 3000, 0-4",
        "channels_rooms.tar.xz",
        CRITIC,
        HEAD_ORACLE,
        section=f"{CEILING}#stage-4-the-best-channel-in-todays-rooms-quick-seeds-0-4-2026-11-29",
    ),
    *(
        Comparison(
            f"{what} as a training target - a3c, both at 3e-4",
            "priors, range 4, 3000, 0-4",
            "targets_stage1.tar.xz",
            A3,
            f"{A3},aux_target={target},aux_weight=0.1",
            section=TARGETS_STAGE1,
        )
        for what, target in (("compass", "compass"), ("goal view", "goal_view"))
    ),
    Comparison(
        "the same, on fresh seeds",
        "priors, range 4, 3000, 5-9",
        "targets_stage2.tar.xz",
        A3,
        f"{A3},aux_target=compass,aux_weight=0.1",
        section=TARGETS_STAGE2,
    ),
    Comparison(
        "a3c at its validated 1e-3 - a3c at 3e-4",
        "priors, range 4, 3000, 0-4",
        "targets_stage1.tar.xz",
        A3,
        "a3c@learning_rate=1e-3",
        section=TARGETS_STAGE1,
    ),
)
