"""Layouts with priors (envs.priors): today's layouts unchanged, the relation table complete
and holding over layouts (checked by an independent reading of the grids), furniture kinds
in the view (against the reference ray marcher), houses' room pairs, related target
vectors, the option reaching the env, the evaluator and the bank cache.  The oracle and the
calibration of the priors kit run in test_oracle.py and test_calibration.py (here, in
tests/envs/); the study's figures in tests/studies/test_priors_data.py."""

import hashlib
from collections import defaultdict

import numpy as np
import pytest

import envs
from envs import bank_cache as BC
from envs import catalog as C
from envs import priors as P
from envs.bank import generate_scene
from envs.houses import generate_house
from envs.scenes import generate_layout
from env_reference import reference_view

ROOM_NUMBERS = [o + i for o in C.ROOM_OFFSETS for i in range(1, 31)]
HOUSE_NUMBERS = [1000 * s + i for s in C.HOUSE_SIZES for i in range(1, 31)]
TODAY_DIGEST = "7db7b41aeb77c069"  # every layout of today's generator, measured before envs.priors existed


def layouts_digest():
    """A short sha256 of every room and house of both setups as today's generator makes them."""
    h = hashlib.sha256()
    for setup in ("savn", "org"):
        for n in ROOM_NUMBERS + HOUSE_NUMBERS:
            layout = generate_scene(n, setup, 30 if C.is_house(n) else 20)
            for a in (layout.cell_type, layout.obj_cat, layout.obj_band, layout.cell_room):
                h.update(np.ascontiguousarray(a).tobytes())
            h.update(repr((layout.room_type, layout.room_types, sorted(layout.target_room.items()))).encode())
    return h.hexdigest()[:16]


def test_todays_layouts_are_unchanged():
    """Every room and house of both setups, as generated before priors existed (so their
    banks, views, oracle and every trained number stay as they were)."""
    assert layouts_digest() == TODAY_DIGEST
    assert generate_layout(7, "savn").furniture is None


def test_generation_is_deterministic_and_rooms_keep_their_walls():
    for n in (3, 214, 329, 407):
        a, b = generate_layout(n, "org", priors=True), generate_layout(n, "org", priors=True)
        for name in ("cell_type", "obj_cat", "obj_band", "furniture"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        today = generate_layout(n, "org")
        np.testing.assert_array_equal(a.cell_type == C.CELL_WALL, today.cell_type == C.CELL_WALL)
        assert ((a.furniture >= 0) == (a.cell_type == C.CELL_FURNITURE)).all()
    a, b = generate_house(3007, "savn", priors=True), generate_house(3007, "savn", priors=True)
    np.testing.assert_array_equal(a.obj_cat, b.obj_cat)
    np.testing.assert_array_equal(a.furniture, b.furniture)


def test_the_relation_table_is_complete_and_each_relation_can_hold():
    """Every category of both setups has a relation, and in every room type that holds it
    a piece of one of its anchor kinds is furnished (else it could never hold)."""
    for setup in C.SETUPS:
        for room in range(4):
            kinds = {piece.kind for piece in P.PRIOR_FURNITURE[room]}
            for name in C.SETUPS[setup][1][room]:
                rel = P.RELATIONS[name]
                assert rel.on or rel.zone, name
                assert not rel.on or kinds & set(rel.on), (setup, C.ROOM_TYPES[room], name)
                assert set(rel.on) <= set(C.FURNITURE_KINDS) and set(rel.near) <= set(P.RELATIONS)
    assert {p.kind for pieces in P.PRIOR_FURNITURE.values() for p in pieces} == set(C.FURNITURE_KINDS)


def relation_holds(layout, setup):
    """[(category name, whether its relation holds)] of every object of a layout, read from
    the grids by hand: mid band on a piece of an anchor kind, floor band with one of them
    4-beside it, high band with one of them within 2 cells (Chebyshev), a corner zone at (floor)
    or next to (high) a free cell walled on two perpendicular sides."""
    cats, g = C.categories(setup), layout.cell_type.shape[0]
    cell, kind = layout.cell_type, layout.furniture

    def inside(cells):
        return [(a, b) for a, b in cells if 0 <= a < g and 0 <= b < g]

    def corner(a, b):
        wall = lambda x, y: cell[x, y] == C.CELL_WALL  # noqa: E731
        free = cell[a, b] not in (C.CELL_WALL, C.CELL_FURNITURE)
        return free and (wall(a - 1, b) or wall(a + 1, b)) and (wall(a, b - 1) or wall(a, b + 1))

    out = []
    for r, c in np.argwhere(layout.obj_cat >= 0):
        name, band = cats[layout.obj_cat[r, c]], layout.obj_band[r, c]
        rel = P.RELATIONS[name]
        four = inside([(r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)])
        eight = inside([(r + i, c + j) for i in (-1, 0, 1) for j in (-1, 0, 1) if i or j])
        if rel.zone == "corner":
            ok = (
                corner(r, c)
                if band == C.BAND_FLOOR
                else any(corner(a, b) for a, b in eight if 0 < a < g - 1 and 0 < b < g - 1)
            )
        else:
            on = {C.FURNITURE_KINDS.index(k) for k in rel.on}
            within_two = kind[max(r - 2, 0) : r + 3, max(c - 2, 0) : c + 3]
            ok = {
                C.BAND_MID: kind[r, c] in on,
                C.BAND_FLOOR: any(kind[a, b] in on for a, b in four),
                C.BAND_HIGH: np.isin(within_two, list(on)).any(),
            }[int(band)]
        out.append((name, bool(ok)))
    return out


@pytest.mark.parametrize("setup", ["savn", "org"])
def test_relations_hold_over_layouts(setup):
    """Over all 120 rooms and 90 houses: at least 85% of the objects stand where their
    relation says (RELATION_NOISE = 10% are placed as today's layouts place them, a few
    find no related cell free), every category at least half the time; measured 90% overall
    and 59-100% by category (the television lowest: in a house, a wall it could hang on
    next to its stand often faces another room too, and a wall object is seen from its own
    room only)."""
    held = defaultdict(list)
    for n in ROOM_NUMBERS + HOUSE_NUMBERS:
        for name, ok in relation_holds(generate_scene(n, setup, 30 if C.is_house(n) else 20, True), setup):
            held[name].append(ok)
    overall = np.mean([ok for v in held.values() for ok in v])
    assert 0.85 <= overall <= 0.95, overall
    worst = min(held, key=lambda k: np.mean(held[k]))
    assert np.mean(held[worst]) >= 0.5, (worst, np.mean(held[worst]))
    assert set(held) == set(C.categories(setup))


def test_furniture_kinds_show_in_the_view_as_the_reference_marcher_sees_them(priors_kit):
    """The bank's view of poses of a priors scene against the reference ray marcher given
    the furniture's classes: equal on every pixel clear of a window edge; the kinds' classes
    come after the categories, and a plain (today's) env shows no such class."""
    kit, rng = priors_kit, np.random.default_rng(3)
    assert kit.env.num_semantic == C.num_semantic("savn", priors=True) == 4 + 18 + len(C.FURNITURE_KINDS)
    seen_kinds = set()
    for scene in (1, 6, 13):
        grids = [kit.bank[k][scene] for k in ("cell_type", "obj_cat", "obj_band")]
        free = np.argwhere(grids[0] == C.CELL_FLOOR)
        for pos in free[rng.choice(len(free), 6, replace=False)]:
            heading, horizon = int(rng.integers(8)), int(rng.integers(2))
            pose = ((pos[0] * grids[0].shape[0] + pos[1]) * 8 + heading) * 2 + horizon
            sem = kit.bank["view_sem"][scene, pose]
            ref, _, margin = reference_view(
                *grids, pos, heading, horizon, kit.env.view_width, furniture_sem=kit.bank["furniture_sem"][scene]
            )
            clear = margin > 1e-3
            np.testing.assert_array_equal(sem[clear], ref[clear])
            seen_kinds |= {int(s) for s in sem.ravel() if s >= C.furniture_sem("savn", 0)}
    assert len(seen_kinds) >= 4 and max(seen_kinds) < kit.env.num_semantic


def test_house_rooms_come_in_adjacent_pairs():
    """In the houses holding both rooms of a pair (kitchen and living room, bedroom and
    bathroom), a doorway joins the two in at least 80% (RELATION_NOISE leaves 10% to
    chance); today's houses join them less often."""

    def joined(layout, a, b):
        rooms = layout.cell_room
        index = {t: i for i, t in enumerate(layout.room_types)}
        ra, rb = rooms == index[a], rooms == index[b]
        door = (layout.cell_type == C.CELL_FLOOR) & (rooms < 0)  # doorway cells belong to no room
        near = lambda m: np.roll(m, 1, 0) | np.roll(m, -1, 0) | np.roll(m, 1, 1) | np.roll(m, -1, 1)  # noqa: E731
        return bool((door & near(ra) & near(rb)).any())

    rates = {}
    for priors in (True, False):
        hits = [
            joined(layout, *pair)
            for n in HOUSE_NUMBERS
            for layout in [generate_house(n, "savn", priors=priors)]
            for pair in P.ROOM_PAIRS
            if set(pair) <= set(layout.room_types)
        ]
        assert len(hits) >= 40
        rates[priors] = np.mean(hits)
    assert rates[True] >= 0.8 and rates[True] > rates[False] + 0.15, rates


def test_prior_word_vectors_relate_categories_that_share_anchors():
    vectors = {c: P.prior_word_vector(c) for c in C.categories("savn")}
    cos = lambda a, b: float(vectors[a] @ vectors[b] / np.linalg.norm(vectors[a]) / np.linalg.norm(vectors[b]))  # noqa: E731
    assert cos("Toaster", "Fridge") > 0.35 and cos("Toaster", "CoffeeMaker") > 0.35
    assert abs(cos("Toaster", "Pillow")) < 0.15 and abs(cos("ToiletPaper", "Television")) < 0.15
    for c, v in vectors.items():
        np.testing.assert_allclose(np.linalg.norm(v), np.linalg.norm(C.word_vector(c)), rtol=1e-5)
    np.testing.assert_array_equal(P.target_encodings("org"), C.target_encodings("org"))


def test_the_option_reaches_the_env_the_evaluator_and_the_cache(priors_test):
    from foresit_jax.config import Config
    from foresit_jax.evaluate import Evaluator
    from foresit_jax.train import make_env

    env, params = priors_test
    assert env.priors and params.bank.furniture_sem is not None
    np.testing.assert_array_equal(params.bank.target_vectors, P.target_encodings("savn"))
    plain, _ = envs.make("GridNav-v0", setup="savn", split="val", room_types="bathroom", view_width=2)
    assert plain.num_semantic == 4 + 18 and not plain.priors
    config = Config(method="a3c", priors=True, room_types=("bathroom",))
    env, params = make_env(config, "val")
    assert env.num_semantic == 35 and params.bank.furniture_sem is not None
    evaluator = Evaluator.for_config(config)
    assert evaluator.env.priors and Evaluator.scenes_of(config) == ("savn", "room", True, None)
    with pytest.raises(ValueError, match="priors"):
        Evaluator("savn", "room")._check(config, "val", 1)
    numbers = tuple(C.scene_numbers("val", [C.BATHROOM]))
    assert BC.bank_cache_key("savn", numbers, 20, 2) != BC.bank_cache_key("savn", numbers, 20, 2, priors=True)
    path = BC.bank_cache_path("savn", numbers, 20, 2, priors=True)
    assert path is None or "-priors-" in path.name


def test_docs_relation_table_is_the_code():
    """docs/priors.md's relation table, row for row, is envs.priors.RELATIONS."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[2] / "docs" / "priors.md").read_text()
    band = {C.BAND_FLOOR: "on the floor, beside", C.BAND_MID: "on", C.BAND_HIGH: "high on a wall, within 2 cells of"}
    for name, rel in P.RELATIONS.items():
        rooms = sorted(
            {C.ROOM_TYPES[r].replace("_", " ") for s in C.SETUPS for r in range(4) if name in C.SETUPS[s][1][r]}
        )
        setups = ", ".join(s for s in C.SETUPS if name in C.categories(s))
        where = ", ".join(rel.on) if rel.on else f"a {rel.zone}"
        row = f"| {name} | {setups} | {', '.join(rooms)} | {band[C.category_band(name)]} | {where} | {', '.join(rel.near) or '-'} |"
        assert row in doc, row


def test_priors_is_the_sweeps_not_an_arms():
    """The scenes are one sweep's (one Evaluator serves it): an arm cannot set priors, the
    preset's override can."""
    from experiments.running.presets import preset, split_arm

    with pytest.raises(ValueError, match="'priors' is not a Config field an arm can set.*--priors"):
        split_arm("a3c@priors=true")
    assert preset("quick", "a3c", priors=True)[0].priors and not preset("quick", "a3c")[0].priors


@pytest.mark.slow
def test_the_gpu_script_runs_dry_on_a_cpu(tmp_path):
    """scripts/priors_study_gpu.sh at a tiny size: the savn and org arms side by side in rooms
    with priors, a table and the pairs per setup, one archive without checkpoints."""
    import os
    import subprocess
    import tarfile
    from pathlib import Path

    repo = Path(__file__).resolve().parents[2]
    env = {
        **os.environ,
        "PRESET": "tiny",
        "SEEDS": "2",
        "UPDATES": "4",
        "OUT": str(tmp_path / "out"),
        "RUNS": str(tmp_path / "runs"),
    }
    proc = subprocess.run(
        ["bash", str(repo / "scripts" / "priors_study_gpu.sh")], env=env, capture_output=True, text=True, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    runs_ = tmp_path / "runs"
    savn = (runs_ / "savn_all" / "compare.md").read_text()
    assert "a3c+foresit@learning_rate=3e-4 - a3c+critic@learning_rate=3e-4" in savn
    assert "a3c+foresit@learning_rate=3e-4 - a3c" in savn
    assert "a3c+org+foresit - a3c+org" in (runs_ / "org_all" / "compare.md").read_text()
    from experiments import rundir

    assert all(rundir.read_json(runs_ / f"{s}_all" / "sweep.json")["config"]["priors"] is True for s in ("savn", "org"))
    with tarfile.open(tmp_path / "out" / "priors_gpu.tar.xz") as tar:
        names = tar.getnames()
    assert any(n.endswith("org_all/table1.md") for n in names) and not any("checkpoints" in n for n in names)


def test_the_view_table_equals_the_ray_cast_at_every_step():
    """Under priors the precomputed view (a table gather) and the one cast at every step
    (`precomputed_views=False`, which reads the bank's furniture classes) agree."""
    import jax

    kw = dict(setup="savn", split="val", room_types=("bedroom",), view_width=3, priors=True)
    table, params = envs.make("GridNav-v0", **kw)
    cast, params_cast = envs.make("GridNav-v0", precomputed_views=False, **kw)
    keys = jax.random.split(jax.random.key(4), 64)
    obs_t, _ = jax.vmap(table.reset, in_axes=(0, None))(keys, params)
    obs_c, _ = jax.vmap(cast.reset, in_axes=(0, None))(keys, params_cast)
    np.testing.assert_array_equal(obs_t["view"], obs_c["view"])
    assert obs_t["view"][..., C.furniture_sem("savn", 0) : -1].any()  # furniture kinds are in view
