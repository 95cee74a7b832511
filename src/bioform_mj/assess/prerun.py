"""The robot check a run makes before it starts (design §14.2).

``bioform run`` (and :func:`bioform_mj.run.simulate.simulate`, so a sweep's every run) refuses with exit 2
what ``robot check`` fails and no run survives (``assess.feasibility.run_refusals``: a skid-steer base,
a statically unstable chassis, ...). What else ``robot check`` fails (an identification more than
``FAIL_ID`` off the formula, with its named cause; a caster that stops the robot) is a ``warning:``
before the run and an entry in ``summary.json`` (``robot_check``): the user may want to see what
happens. :func:`before_run` does it once per distinct robot (the prepared model and its mapping),
remembered in the process and on disk (:func:`cache_dir`), keyed by the robot's content, the
package's code and MuJoCo's version, so a sweep of a thousand runs checks each robot once.
``BIOFORM_NO_ROBOT_CHECK=1`` (``--no-robot-check``) skips it.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import os
import time
import warnings
from pathlib import Path
from typing import Any

from bioform_mj.assess.skip import SKIP_ENV, skipped
from bioform_mj.plants.base import RobotModels

log = logging.getLogger(__name__)

__all__ = ["before_run", "cache_dir", "robot_key", "skipped", "SKIP_ENV", "CACHE_ENV", "COMPUTED"]

#: the cache's parent folder (else ``$NUMBA_CACHE_DIR``, else ``~/.cache/bioform_mj``, as the kernels')
CACHE_ENV = "BIOFORM_CACHE_DIR"
#: the shape of a cache entry; an entry of another shape is recomputed
CACHE_FORMAT = 3
#: entries of this process, by :func:`robot_key`
_MEMO: dict[str, dict[str, Any]] = {}
#: robot checks this process computed (neither remembered nor read from the cache): a counter for tests
COMPUTED = [0]


def cache_dir() -> Path:
    """``$BIOFORM_CACHE_DIR`` (or ``$NUMBA_CACHE_DIR``, or ``~/.cache/bioform_mj``) ``/robot-check``."""
    base = os.environ.get(CACHE_ENV) or os.environ.get("NUMBA_CACHE_DIR") or Path.home() / ".cache" / "bioform_mj"
    return Path(base) / "robot-check"


@functools.cache
def code_digest() -> bytes:
    """The package's Python source (:func:`bioform_mj.core.codehash.source_digest`) and MuJoCo's version:
    a check computed by other code is not reused."""
    import mujoco

    from bioform_mj.core.codehash import source_digest

    return hashlib.sha256(mujoco.__version__.encode() + source_digest()).digest()


def robot_key(ref: Any) -> str:
    """The cache key of one resolved :class:`~bioform_mj.robots.refs.RobotRef`: the prepared robot's MJCF
    (``prepare_robot``: the file with its mapping applied, a URDF imported; not its path), the bytes of every asset
    file it names (meshes), the mapping, and :func:`code_digest`. Hex, 32 characters."""
    from bioform_mj.robots.prepare import prepare_robot
    from bioform_mj.robots.spec_files import spec_files

    spec, lay = prepare_robot(ref)[:2]
    h = hashlib.sha256(code_digest())
    # the layout stored in the spec names the file: the same content elsewhere is the same robot
    h.update(spec.to_xml().replace(f'"file": {json.dumps(str(lay.file))}', '"file": ""').encode())
    for asset in spec_files(spec):  # skins and cube faces too (issue 28: a changed face kept the old verdict)
        f = Path(asset.path(spec.modelfiledir or "."))
        if f.is_file():
            h.update(f.read_bytes())
    mapping = {k: v for k, v in dataclasses.asdict(ref).items() if k not in ("model", "package_path", "asset_roots")}
    h.update(json.dumps(mapping, sort_keys=True, default=str).encode())
    return h.hexdigest()[:32]


def _check(ref: Any, run_step: float | None = None) -> dict[str, Any]:
    """``robot check``'s verdict of one robot, reduced to what a run says (a cache entry); ``run_step``: the
    run's physics step, s (the identification is repeated there: design §14.2)."""
    from bioform_mj.assess.check import check
    from bioform_mj.assess.outcomes import identified_resistances
    from bioform_mj.core.errors import InputError

    t0 = time.perf_counter()
    try:
        with warnings.catch_warnings():  # what the robot's import says, the run has said already
            warnings.simplefilter("ignore")
            res = check(ref, run_step=run_step)
    except InputError as exc:  # robot check's exit 2 (a mapping no test can use), where the run starts
        return {"verdict": "error", "error": str(exc), "fail_reasons": [], "seconds": time.perf_counter() - t0}
    except Exception as exc:  # noqa: BLE001 - a check that breaks is said, and does not stop the run
        why = f"internal error {type(exc).__name__}: {exc}"
        return {"verdict": "error", "error": why, "fail_reasons": [], "seconds": time.perf_counter() - t0}
    cause = res.get("cause")
    return {
        "format": CACHE_FORMAT,
        "verdict": res["verdict"],
        "fail_reasons": list(res.get("fail_reasons", [])),
        "cause": None if cause is None else {"kind": cause["kind"], "detail": cause["detail"]},
        "formula": {"a": res["a_eff"], "b": res["b_eff"]},
        "identified": {"a": res["a_identified"], "b": res["b_identified"]},
        "relative_error": res["relative_error"],
        # the identified dead band [on τ_a, on τ_b] N·m (learner_sizing, design §14), or None
        "deadband_torque_Nm": ((res.get("wheel_joints") or {}).get("identified") or {}).get("deadband_torque_Nm"),
        # what a run's c_hat_off names as its likely cause, with the numbers (design §14.2)
        "resistances": identified_resistances(res),
        "seconds": time.perf_counter() - t0,
    }


def cached_check(ref: Any, key: str, run_step: float | None = None) -> dict[str, Any]:
    """The entry of robot ``key``: remembered, read from :func:`cache_dir`, or computed (and written);
    ``run_step`` (s) is part of the key (the identification is repeated at it)."""
    if run_step is not None:
        key = hashlib.sha256(f"{key}/{run_step!r}".encode()).hexdigest()[:32]
    if key in _MEMO:
        return {**_MEMO[key], "from": "memory"}
    path = cache_dir() / f"{key}.json"
    from bioform_mj.assess.cache_schema import entry_problem
    from bioform_mj.robots.sanity import not_regular

    stale = ""
    try:
        if not_regular(path):  # a FIFO or a device in the cache folder: never opened
            raise OSError(not_regular(path))
        entry = json.loads(path.read_text(encoding="utf-8"))
        stale = entry_problem(entry, CACHE_FORMAT)
        if not stale:
            _MEMO[key] = entry
            return {**entry, "from": "disk"}
    except FileNotFoundError:
        pass  # not checked yet: computed below
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        stale = f"unreadable ({' '.join(str(exc).split())})"
    if stale:  # issue 28: a cache never breaks a run; one warning names the file, the entry is rewritten
        import warnings

        from bioform_mj.core.errors import RobotWarning

        warnings.warn(f"robot-check cache entry '{path}' ignored and rewritten: {stale}", RobotWarning, stacklevel=2)
        try:
            if not not_regular(path):
                path.unlink(missing_ok=True)
        except OSError:
            pass
    COMPUTED[0] += 1
    entry = _check(ref, run_step)
    _MEMO[key] = entry
    out = {**entry, "from": "computed"}
    if entry.get("format") == CACHE_FORMAT:
        from bioform_mj.outputs.files import write_json

        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            write_json(path, entry)
        except Exception as exc:  # noqa: BLE001 - a cache that cannot be written costs time, not the run
            out["cache_error"] = f"not cached in '{path.parent}': {exc}"
            log.info(out["cache_error"])
    return out


#: what :func:`before_run` measures of itself (its time, where each check came from): said on a run's log, not kept
#: in its summary, which is the same bit for bit for the same seed (design §14.2)
VOLATILE = ("seconds", "from", "cache_error")


def for_summary(rc: dict[str, Any]) -> dict[str, Any]:
    """:func:`before_run`'s result without the :data:`VOLATILE` keys: what summary.json keeps."""
    return {
        **{k: v for k, v in rc.items() if k not in VOLATILE},
        "robots": [{k: v for k, v in r.items() if k not in VOLATILE} for r in rc.get("robots", [])],
    }


def before_run(sc: Any, plant: Any) -> dict[str, Any]:
    """summary.json's ``robot_check`` for a MuJoCo run: ``{"skipped", "seconds", "robots", "warnings"}``.

    ``robots``: per distinct robot ``{"model", "followers" (1-based), "verdict", "fail_reasons",
    "cause", "formula", "identified", "relative_error", "seconds" (of the check itself), "from"
    (computed, memory or disk)}``; ``warnings``: one line per reason a robot fails ``robot check``
    (what :func:`~bioform_mj.assess.feasibility.run_refusals` refuses never gets here: exit 2 before).
    Warned by the caller before the run. ``plant``: the built scene (only MuJoCo plants are checked)."""
    t0 = time.perf_counter()
    if skipped():
        return {"skipped": True, "seconds": 0.0, "robots": [], "warnings": [], "how": f"{SKIP_ENV}=1"}
    from bioform_mj.robots.entries import resolve_robot

    entries = list(sc.plant.robots) * (sc.n if len(sc.plant.robots) == 1 else 1)
    by_ref: dict[Any, list[int]] = {}  # a robot's key once per distinct entry (256 followers: one prepare)
    for i, e in enumerate(entries[: getattr(plant, "n", sc.n)]):
        by_ref.setdefault(resolve_robot(e), []).append(i + 1)
    groups: dict[str, tuple[Any, list[int]]] = {}
    for ref, who in by_ref.items():
        groups.setdefault(robot_key(ref), (ref, []))[1].extend(who)
    robots, lines = [], []
    for key, (ref, who) in groups.items():
        step = float(plant.model.opt.timestep) if isinstance(plant, RobotModels) else None  # the run's physics step
        entry = {"model": ref.model, "followers": who, **cached_check(ref, key, step)}
        entry.pop("format", None)
        robots.append(entry)
        whom = f"follower{'s' if len(who) > 1 else ''} {', '.join(map(str, who))}"
        head = f"{whom}: robot check fails '{ref.model}' (the run goes ahead; design §14.2)"
        if entry["verdict"] == "error":
            lines.append(f"{whom}: robot check cannot check '{ref.model}': {entry['error']}")
        lines += [f"{head}: {why}" for why in entry["fail_reasons"]]
    return {"skipped": False, "seconds": time.perf_counter() - t0, "robots": robots, "warnings": lines}
