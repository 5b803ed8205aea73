"""Orbax checkpoints with checksums.

Every checkpoint gets a checksum of its files at save (`save`), checked before it is
restored (`restore`): a corrupt or truncated one is one line naming it, and a resume falls
back to the newest intact one (`intact_step`).
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import shutil
from pathlib import Path

import jax
import numpy as np

from experiments.errors import UserError
from experiments.rundir import write_json


def checkpoint_manager(path: Path, keep: int):
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(max_to_keep=keep, create=True)
    return ocp.CheckpointManager(path.absolute(), options=options)


CHECKSUM_FILE = "foresit_sha256.json"


class CorruptCheckpoint(UserError):
    """A checkpoint whose files are not those saved (or that orbax cannot read)."""


def step_dir(manager, step: int) -> Path:
    return Path(str(manager.directory)) / str(step)


def _digest(folder: Path) -> str:
    """SHA-256 over every file under `folder` (but the checksum file): names and bytes."""
    h = hashlib.sha256()
    for f in sorted(p for p in folder.rglob("*") if p.is_file() and p.name != CHECKSUM_FILE):
        h.update(str(f.relative_to(folder)).encode() + b"\0")
        with open(f, "rb") as stream:
            for block in iter(lambda: stream.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()


def save(manager, step: int, tree) -> None:
    """Save `tree` as checkpoint `step` and record its checksum (`verify`). A disk too full
    for it is an OSError (ENOSPC) before orbax starts writing: orbax's failure in the
    middle of a write prints hundreds of lines from its storage threads."""
    import orbax.checkpoint as ocp

    folder = Path(str(manager.directory))
    need = sum(int(getattr(leaf, "nbytes", 0)) for leaf in jax.tree.leaves(tree))
    free = shutil.disk_usage(folder).free
    if free < need * 1.25 + (1 << 20):
        raise OSError(
            errno.ENOSPC,
            f"No space left on device for checkpoint {step} (about {need / 2**20:.1f} MB; {free / 2**20:.1f} MB free)",
            str(folder),
        )
    try:
        manager.save(step, args=ocp.args.StandardSave(tree), force=True)
        manager.wait_until_finished()
    except Exception as e:
        if "No space left on device" in str(e) or "os_error_code='28'" in str(e):
            raise OSError(
                errno.ENOSPC, f"No space left on device while writing checkpoint {step}", str(folder)
            ) from None
        raise
    folder = step_dir(manager, step)
    write_json(folder / CHECKSUM_FILE, {"sha256": _digest(folder)})


def verify(manager, step: int) -> None:
    """Raise CorruptCheckpoint (one line naming it) when checkpoint `step`'s files are not
    those `save` wrote. A checkpoint without a checksum (saved before checksums were
    recorded) passes."""
    folder = step_dir(manager, step)
    recorded = folder / CHECKSUM_FILE
    if not recorded.is_file():
        return
    try:
        expected = json.loads(recorded.read_text())["sha256"]
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError):
        raise CorruptCheckpoint(f"checkpoint {folder} is damaged (its checksum file cannot be read)") from None
    if _digest(folder) != expected:
        raise CorruptCheckpoint(
            f"checkpoint {folder} is corrupt or truncated: its files no longer match the "
            "checksum recorded when it was saved"
        )


def intact_step(manager, at_most: int | None = None) -> tuple[int | None, list[str]]:
    """The newest checkpoint step (at most `at_most`) that `verify` passes, or None, and
    one line per newer one skipped as corrupt."""
    skipped = []
    for step in sorted(manager.all_steps(), reverse=True):
        if at_most is not None and step > at_most:
            continue
        try:
            verify(manager, step)
            return step, skipped
        except CorruptCheckpoint as e:
            skipped.append(str(e))
    return None, skipped


def drop_steps_after(manager, step: int) -> None:
    """Delete the checkpoints of steps after `step` (written after what a resume starts from)."""
    for s in manager.all_steps():
        if s > step:
            manager.delete(s)


# The lanes' state before 0.4.0: ActorState's fields flat (issue 82 nested the agent's carry
# and imagination's); a checkpoint written then restores into today's records.
FLAT_ACTOR_FIELDS = ("env_state", "obs", "lstm", "prev_probs", "imagined", "s_0", "episode_step", "memory", "tracker")


def _is_flat_actor(like, saved) -> bool:
    """`like` is today's ActorState and `saved` a checkpoint's lanes written before 0.4.0."""
    return hasattr(like, "agent") and hasattr(like, "env_state") and isinstance(saved, dict) and "lstm" in saved


def _flat_actor(actor) -> dict:
    """Today's ActorState as the flat fields of the one before 0.4.0."""
    agent, imag = actor.agent, actor.agent.imagination
    return dict(
        env_state=actor.env_state,
        obs=actor.obs,
        lstm=agent.lstm,
        prev_probs=agent.prev_probs,
        imagined=imag.imagined,
        s_0=imag.s_0,
        episode_step=agent.episode_step,
        memory=actor.memory,
        tracker=imag.tracker,
    )


def _nested_actor(like, flat: dict):
    """The flat fields (`_flat_actor`'s) in today's ActorState, shaped as `like`."""
    agent, imag = like.agent, like.agent.imagination
    imagination = imag._replace(imagined=flat["imagined"], s_0=flat["s_0"], tracker=flat["tracker"])
    agent = agent._replace(
        lstm=flat["lstm"],
        prev_probs=flat["prev_probs"],
        episode_step=flat["episode_step"],
        imagination=imagination,
    )
    return like._replace(env_state=flat["env_state"], obs=flat["obs"], agent=agent, memory=flat["memory"])


def _fields_added_since(like, saved) -> object:
    """`like` as the checkpoint holds it: a NamedTuple field that is None in `like` and absent
    from the checkpoint (`saved`, its metadata tree: dicts by field name), a field added to
    a record after the checkpoint was written (`RunnerState.targets`, 0.4.0), is dropped, and
    the record becomes a dict of its other fields; the lanes' state of a checkpoint written
    before 0.4.0 is read as its flat fields (`FLAT_ACTOR_FIELDS`); `_rebuild` puts both back."""
    if _is_flat_actor(like, saved):
        return {f: _fields_added_since(v, saved.get(f)) for f, v in _flat_actor(like).items()}
    if isinstance(like, tuple) and hasattr(like, "_fields") and isinstance(saved, dict):
        kept = [f for f in like._fields if f in saved or getattr(like, f) is not None]
        inner = {f: _fields_added_since(getattr(like, f), saved.get(f)) for f in kept}
        return inner if len(kept) < len(like._fields) else type(like)(**inner)
    if isinstance(like, dict) and isinstance(saved, dict):
        return {k: _fields_added_since(v, saved.get(k)) for k, v in like.items()}
    return like


def _rebuild(like, restored) -> object:
    """The restored tree in `like`'s records (the inverse of `_fields_added_since`)."""
    if hasattr(like, "agent") and hasattr(like, "env_state") and isinstance(restored, dict) and "lstm" in restored:
        flat = _flat_actor(like)
        return _nested_actor(like, {f: _rebuild(v, restored.get(f)) for f, v in flat.items()})
    if isinstance(like, tuple) and hasattr(like, "_fields"):
        get = restored.get if isinstance(restored, dict) else lambda f, d=None: getattr(restored, f)
        return type(like)(**{f: _rebuild(getattr(like, f), get(f, None)) for f in like._fields})
    if isinstance(like, dict):
        return {k: _rebuild(v, restored[k]) for k, v in like.items()}
    return restored


def restore(manager, step: int, like):
    """The checkpoint of `step`, shaped as `like` and placed where `like`'s arrays are
    (numpy leaves and shapes without a sharding, `jax.eval_shape`'s: on the first local
    device), not where the saving process had them:
    without a sharding orbax restores the saved one, so a sweep's checkpoint of seeds
    spread over 2 devices came back spread over them in any reader, which then ran
    cross-device collectives it never asked for (and on the CPU these could time out:
    "Termination timeout for all reduce") and failed in a process with 1 device."""
    import orbax.checkpoint as ocp

    verify(manager, step)
    first = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
    absl = logging.getLogger("absl")  # orbax warns that it cannot restore what it only describes here
    level = absl.level
    absl.setLevel(logging.ERROR)
    try:
        saved = manager.item_metadata(step).tree
    except Exception:  # no metadata to read: orbax's own error below names the checkpoint
        saved = None
    finally:
        absl.setLevel(level)
    abstract = jax.tree.map(
        lambda x: jax.ShapeDtypeStruct(np.shape(x), x.dtype, sharding=getattr(x, "sharding", None) or first),
        _fields_added_since(like, saved),
    )  # (`like` may be arrays or shapes, `jax.eval_shape`'s)
    try:
        return _rebuild(like, manager.restore(step, args=ocp.args.StandardRestore(abstract)))
    except Exception as e:  # orbax's (often multi-line) reason, as one line naming the checkpoint
        reason = " ".join(str(e).split())[:300]
        raise CorruptCheckpoint(
            f"cannot restore checkpoint {step_dir(manager, step)}: {type(e).__name__}: {reason}"
        ) from None
