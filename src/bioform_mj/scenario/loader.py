"""Loading scenarios: presets, TOML files, a run's record, ``--set`` overrides, and the transforms made on load.

Unknown keys are an error, never ignored. :func:`load` reads, overrides, scales
(:func:`apply_scale`), validates (:func:`bioform_mj.scenario.check.validate`) and, on the ideal
plant, takes ``c_true`` from the robots (:func:`apply_robots_to_ideal`).
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import types
import typing
from collections.abc import Mapping
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from bioform_mj.control.tuning import PAPER_C
from bioform_mj.core.errors import InputError, ScenarioError
from bioform_mj.robots.entries import rebase_entries
from bioform_mj.robots.refs import PackagePath, RobotRef, as_package_path, as_ref, rebase_package_path
from bioform_mj.scenario.check import validate
from bioform_mj.scenario.config import MAX_ARRAY, MAX_FLOAT, MAX_INT, Scenario, keys_of


def preset_names() -> list[str]:
    """Names of the shipped presets (``scenarios/*.toml`` inside the package)."""
    d = resources.files("bioform_mj.scenario") / "presets"
    return sorted(p.name[:-5] for p in d.iterdir() if p.name.endswith(".toml"))


def preset_descriptions() -> dict[str, str]:
    """``{preset name: its one-line description}`` (the file's ``description``, else the default's)."""
    out = {}
    for name in preset_names():
        raw = (resources.files("bioform_mj.scenario") / "presets" / f"{name}.toml").read_bytes()
        text = _read_toml(raw, f"preset {name}").get("description", Scenario.description)
        out[name] = " ".join(str(text).split())
    return out


def load(
    source: str | Path | None = None,
    overrides: Mapping[str, Any] | list[str] | None = None,
    method: str | None = None,
    plant: str | None = None,
) -> Scenario:
    """Load a preset name, a TOML path or a run's ``summary.json`` (its ``config``: the run again, bit for
    bit), apply ``--set`` overrides, method and plant; validate.

    Parameters
    ----------
    source
        A preset name (``bioform presets``), a path to a scenario TOML file, or a run's ``summary.json``
        or ``resolved.toml``; ``None``: the paper scenario (the dataclass defaults).
    overrides
        ``--set`` overrides: a list of ``"KEY=VALUE"`` strings (``"kinematic.k1=3"``, values in TOML syntax) or
        a mapping of dotted keys to values; applied in order, after the file. Units are each key's
        (docs/reference/scenario.md).
    method
        The controller, as ``--method``: one of the paper's four (``bioinspired-learning``, ...); ``None``
        keeps the file's.
    plant
        ``"ideal"`` or ``"mujoco"``, as ``--plant``; ``None`` keeps the file's.

    Returns
    -------
    Scenario
        The frozen, validated scenario.

    Raises :class:`InputError` (or a subclass) with one line naming the problem.
    """
    data: dict[str, Any]
    if source is None:
        source = "paper"
    src = str(source)
    if "\x00" in src:
        raise InputError(f"scenario {src!r} contains a NUL character")
    from bioform_mj.robots.sanity import unstatable

    if unstatable(src):  # a name too long for the file system: one line, not an OSError (issue 28)
        raise InputError(f"scenario file {unstatable(src)}")
    if src.endswith(".toml") or "/" in src or Path(src).is_file():
        path = Path(src)
        if path.is_dir():
            raise InputError(f"scenario file '{path}' is a directory")
        if not path.exists():
            raise InputError(f"scenario file '{path}' does not exist")
        from bioform_mj.robots.sanity import not_regular  # a FIFO or a device would block the read (issue 28)

        if not_regular(path):
            raise InputError(f"scenario file {not_regular(path)}")
        # TOML at most 2 MB (the 1024-robot preset is 74 kB; Python's TOML reader took 52 s for 10 MB of short
        # keys on the loaded 2-core machine, issue 28), a JSON record (a run's summary) at most 16 MB
        most = 16 if path.suffix.lower() == ".json" else 2
        if path.stat().st_size > most * 10**6:
            size = path.stat().st_size / 1e6
            raise InputError(f"scenario file '{path}' is {size:.3g} MB: not a scenario (at most {most} MB)")
        try:
            raw = path.read_bytes()
        except OSError as exc:  # PermissionError, a FIFO that errors, an I/O error
            raise InputError(f"scenario file '{path}' cannot be read: {exc.strerror or exc}") from None
        data = _read_record(raw, str(path)) if path.suffix.lower() == ".json" else _read_toml(raw, str(path))
        if isinstance(data.get("plant"), dict) and "robots" in data["plant"]:  # design §10: relative to the file
            data["plant"]["robots"] = rebase_entries(data["plant"]["robots"], path.parent.resolve())
        if isinstance(data.get("plant"), dict) and "package_path" in data["plant"]:  # design §12: likewise
            data["plant"]["package_path"] = rebase_package_path(data["plant"]["package_path"], path.parent.resolve())
    else:
        names = preset_names()
        if src not in names:
            raise InputError(f"unknown preset '{src}' (expected one of: {', '.join(names)}, or a .toml path)")
        data = _read_toml(
            (resources.files("bioform_mj.scenario") / "presets" / f"{src}.toml").read_bytes(), f"preset {src}"
        )
    if overrides:
        items = overrides.items() if isinstance(overrides, Mapping) else [parse_override(s) for s in overrides]
        for key, value in items:
            _set_path(data, key, value)
    if method is not None:
        data["method"] = method
    if plant is not None:
        data.setdefault("plant", {})["kind"] = plant
    sc = apply_scale(from_dict(data))
    validate(sc)
    return mark_checked(apply_robots_to_ideal(sc))


def mark_checked(sc: Scenario) -> Scenario:
    """``sc``, marked as checked (:func:`checked` then returns it at once): an attribute of this
    frozen object, not a field, so ``dataclasses.replace`` makes an unmarked one (design §18.1). For
    :func:`load`, and a caller that changed a loaded scenario only where it checked the value itself
    (a sweep's seeds)."""
    object.__setattr__(sc, "_bioform_checked", True)
    return sc


def checked(sc: Scenario) -> Scenario:
    """``sc`` refused as :func:`load` refuses a file (the same :class:`InputError` subclasses and
    messages: types, finite numbers, then :func:`validate`), and scaled if its ``formation.scale``
    is not yet applied (:func:`apply_scale`); ``sc`` itself when it needs no scaling. For a scenario
    built or changed in Python (``dataclasses.replace``), which :func:`load` has not seen:
    :func:`bioform_mj.run.simulate.simulate` calls it before any work (design §18.1; 2-5 ms, nothing for a
    scenario :func:`load` returned or this function scaled)."""
    if getattr(sc, "_bioform_checked", False):
        return sc
    plain = _plain_values(sc.to_dict())
    again = _build(Scenario, plain, "")  # what from_dict refuses in a file (NaN, a string for a number, ...)
    f = sc.formation  # what the values already carry (design §18.1, §21)
    again = dataclasses.replace(
        again,
        formation=dataclasses.replace(
            again.formation,
            scale_applied=f.scale_applied,
            time_scale_applied=f.time_scale_applied,
            scale_note=f.scale_note,
        ),
    )
    scaled = apply_scale(again)  # a scale changed after loading: applied now (its range checked)
    validate(scaled)
    return sc if scaled is again else mark_checked(scaled)  # (sc unmarked: it may hold numpy arrays)


def _plain_values(obj: Any) -> Any:
    """``obj`` with numpy arrays and scalars as Python lists and numbers (a scenario changed in
    Python may hold them; a file cannot)."""
    if isinstance(obj, dict):
        return {k: _plain_values(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_plain_values(v) for v in obj]
    if isinstance(obj, np.generic):
        return obj.item()
    return obj


def _read_record(raw: bytes, where: str) -> dict[str, Any]:
    """A run's ``summary.json``: its ``config`` (:func:`bioform_mj.scenario.record.resolved_config`)."""
    import json

    try:
        data = json.loads(raw.decode("utf-8"))
    except (ValueError, UnicodeDecodeError) as exc:
        raise InputError(f"{where} is not valid JSON: {exc}") from None
    except RecursionError:  # [[[[…]]]] 10^5 deep (issue 28)
        raise InputError(f"{where}: arrays or objects nested too deeply to read (not a run's summary.json)") from None
    if not isinstance(data, dict) or not isinstance(data.get("config"), dict):
        raise InputError(f"{where} is not a run's summary.json (no 'config' table); give a scenario TOML file")
    return data["config"]


#: most parts a dotted TOML key may have (the deepest scenario key has 3): Python's TOML parser keeps a tuple of every
#: prefix of a dotted key, so one line ``a.a.a…= 1`` of 10^5 parts (200 kB) asked ~38 GB (a MemoryError after 36 s,
#: issue 28; 20,000 parts: 1.5 GB)
MAX_KEY_PARTS = 256
_KEY_TOKEN = re.compile(r"""\s*(?:([A-Za-z0-9_-]+)|"(?:[^"\\\n]|\\.)*"|'[^'\n]*'|(\.)|.)""")


def deep_key_line(text: str) -> int:
    """The first line (1-based) of ``text`` holding a run of more than :data:`MAX_KEY_PARTS` key parts joined by
    dots, 0 if none: a scan linear in the text (only lines with that many dots are tokenised)."""
    for n, line in enumerate(text.splitlines(), 1):
        if line.count(".") < MAX_KEY_PARTS:
            continue
        run, last = 0, ""  # parts in the current chain; the last token: "part", "dot" or ""
        for m in _KEY_TOKEN.finditer(line):
            tok = m.group(0).strip()
            if m.group(2):
                run, last = (run if last == "part" else 0), "dot"
            elif m.group(1) or (len(tok) >= 2 and tok[0] in "\"'"):
                run, last = (run + 1 if last == "dot" else 1), "part"
            else:
                run, last = 0, ""
            if run > MAX_KEY_PARTS:
                return n
    return 0


def _read_toml(raw: bytes, where: str) -> dict[str, Any]:
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(f"{where} is not valid TOML: {exc}") from None
    if line := deep_key_line(text):
        raise InputError(f"{where}: line {line} has a dotted key of more than {MAX_KEY_PARTS} parts (not a scenario)")
    try:
        return tomllib.loads(text)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{where} is not valid TOML: {exc}") from None
    except ValueError as exc:  # an integer of more than 4300 digits (Python's int limit): was an internal error
        raise InputError(f"{where}: {str(exc).split(';')[0]} (not a scenario)") from None
    except RecursionError:  # [[[[…]]]] 10^5 deep: Python's parser recurses (issue 28)
        raise InputError(f"{where}: arrays or tables nested too deeply to read (not a scenario)") from None


def parse_override(text: str) -> tuple[str, Any]:
    """``'kinematic.k1=3'`` → ``('kinematic.k1', 3)``; values are TOML literals, bare words are strings."""
    if not isinstance(text, str):  # bioform_mj.load(overrides=[3]) was an AttributeError
        raise InputError(f"override {text!r}: expected a string KEY=VALUE, e.g. 'kinematic.k1=3'")
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise InputError(f"--set '{text}': expected KEY=VALUE, e.g. kinematic.k1=3")
    raw = raw.strip()
    if deep_key_line(raw):  # an inline table {a.a.a… = 1}: the parser's memory grows as the square of the parts
        raise InputError(f"--set '{key}': the value has a dotted key of more than {MAX_KEY_PARTS} parts")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    except ValueError as exc:  # an integer of more than 4300 digits (Python's int limit): was an internal error
        raise InputError(f"--set '{key}': {str(exc).split(';')[0]}") from None
    except RecursionError:  # --set k=[[[[…]]]] (issue 28)
        raise InputError(f"--set '{key}': the value is nested too deeply to read") from None
    return key, value


def _set_path(data: dict[str, Any], key: str, value: Any) -> None:
    if not isinstance(key, str):  # bioform_mj.load(overrides={3: 1}) was an AttributeError
        raise InputError(f"override key {key!r}: expected a dotted key string, e.g. 'kinematic.k1'")
    parts = key.split(".")
    cls: Any = Scenario
    node = data
    for i, part in enumerate(parts):
        hints = keys_of(cls)  # an internal field (FormationCfg.scale_applied) is no key
        if part not in hints:
            raise ScenarioError(key, f"unknown key (expected one of: {', '.join(hints)})")
        if i == len(parts) - 1:
            node[part] = value
            return
        cls = hints[part]
        if cls is PackagePath and i == len(parts) - 2:  # plant.package_path.NAME=DIR adds one package
            table = node.get(part)
            node[part] = {**(table if isinstance(table, Mapping) else {}), parts[-1]: value}
            return
        if not dataclasses.is_dataclass(cls):
            raise ScenarioError(key, f"'{'.'.join(parts[: i + 1])}' is a value, not a table")
        node = node.setdefault(part, {})
        if not isinstance(node, dict):  # e.g. `sim = 3` in the file, then --duration
            raise ScenarioError(".".join(parts[: i + 1]), f"expected a table, got {type(node).__name__} {node!r}")


def from_dict(data: Mapping[str, Any]) -> Scenario:
    """Build a :class:`Scenario` from nested dicts; unknown keys and wrong types raise ScenarioError."""
    return _build(Scenario, data, "")


def _build(cls: Any, data: Any, prefix: str) -> Any:
    if not isinstance(data, Mapping):
        raise ScenarioError(prefix.rstrip("."), f"expected a table, got {type(data).__name__}")
    hints = keys_of(cls)  # an internal field (FormationCfg.scale_applied) is no key
    unknown = [k for k in data if k not in hints]
    if unknown:
        raise ScenarioError(prefix + unknown[0], f"unknown key (expected one of: {', '.join(hints)})")
    kwargs = {k: _convert(v, hints[k], prefix + k) for k, v in data.items()}
    return cls(**kwargs)


def _convert(value: Any, tp: Any, key: str) -> Any:
    if tp is RobotRef:  # a name, a path or a mapping table (robots.py)
        return as_ref(value, key)
    if tp is PackagePath:  # {NAME = "DIR"} (robots.py, design §12)
        return as_package_path(value, key)
    if dataclasses.is_dataclass(tp):
        return _build(tp, value, key + ".")
    origin = typing.get_origin(tp)
    if origin is tuple:
        (inner, *_rest) = typing.get_args(tp)
        if not isinstance(value, (list, tuple)):
            raise ScenarioError(key, f"expected an array, got {type(value).__name__} {value!r}")
        if len(value) > MAX_ARRAY:
            raise ScenarioError(key, f"{len(value)} values, above the {MAX_ARRAY} an array of a scenario may have")
        if dataclasses.is_dataclass(inner) and inner is not RobotRef:
            return tuple(_build(inner, v, f"{key}[{i}].") for i, v in enumerate(value))
        return tuple(_convert(v, inner, f"{key}[{i}]") for i, v in enumerate(value))
    if origin is typing.Literal:  # a kind (scenario/config.py): a string here, its value checked by validate()
        tp = str
    if typing.get_origin(tp) is types.UnionType:  # formation.scale, time_scale: a number or "auto" (design §21)
        if value == "auto":
            return value
        if isinstance(value, str):
            raise ScenarioError(key, f'expected a number > 0 or "auto", got {value!r}')
        tp = float
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(key, f"expected a number, got {type(value).__name__} {value!r}")
        if isinstance(value, int) and abs(value) > MAX_FLOAT:  # 10**400: math.isfinite raised OverflowError
            digits = int(abs(value).bit_length() * 0.30103)
            raise ScenarioError(key, f"number out of range (|value| <= {MAX_FLOAT:g}), got ~1e{digits}")
        if not math.isfinite(value):
            raise ScenarioError(key, f"expected a finite number, got {value}")
        if abs(value) > MAX_FLOAT:  # no quantity of a scenario comes near it; ratios of such times overflow
            raise ScenarioError(key, f"number out of range (|value| <= {MAX_FLOAT:g}), got {value:g}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ScenarioError(key, f"expected an integer, got {type(value).__name__} {value!r}")
        if not -MAX_INT <= value <= MAX_INT:  # numpy and the compiled loop take 64-bit integers
            raise ScenarioError(key, f"integer out of range (|value| <= 2^62), got {value}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ScenarioError(key, f"expected a string, got {type(value).__name__} {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ScenarioError(key, f"expected true or false, got {value!r}")
        return value
    raise TypeError(f"unsupported field type {tp} for {key}")  # programming error, not user input


# ---------------------------------------------------------------------------------------
# Robots on the ideal plant (issue 10: plant.robots is never ignored)
# ---------------------------------------------------------------------------------------


def apply_robots_to_ideal(sc: Scenario) -> Scenario:
    """On the ideal plant, ``plant.robots`` other than the shipped ``paper`` robot decide ``c_true``.

    The ideal plant is then the paper's model of that robot: ``c_true = (a_eff, b_eff)`` from its
    compiled model, ``mass = M_eff = 1/(a_eff r)`` and ``inertia = I_eff = l/(b_eff r)`` (for
    payload events). The ``paper`` robot (the default) leaves ``plant.c_true`` as given, so the
    paper's abstract plant keeps ``--set plant.c_true=…``. Refused (ScenarioError): robots whose
    ``c_true`` differ (the ideal plant takes one ``c_true``), and a ``plant.c_true`` other than the
    paper's that disagrees with the robots. The MuJoCo plant is returned unchanged.
    """
    pc = sc.plant
    if pc.kind != "ideal":
        return sc
    from bioform_mj.robots.entries import resolve_robot

    refs = [resolve_robot(r) for r in pc.robots]
    paper = resolve_robot("paper")
    if all(Path(r.model).resolve() == Path(paper.model).resolve() and not r.mapped for r in refs):
        return sc
    from bioform_mj.robots.params import robot_truth  # MuJoCo only when a robot asks for it

    truths = [robot_truth(r) for r in refs]
    c = np.array([t.c for t in truths])
    if np.any(np.abs(c / c[0] - 1) > 1e-6):
        raise ScenarioError(
            "plant.robots",
            "the ideal plant takes one c_true, but the robots differ "
            f"({'; '.join(f'{r.model}: a={x[0]:.4g}, b={x[1]:.4g}' for r, x in zip(refs, c))}); "
            "use plant.kind = 'mujoco' for a heterogeneous team",
        )
    if tuple(pc.c_true) != PAPER_C and np.any(np.abs(np.asarray(pc.c_true) / c[0] - 1) > 1e-3):
        raise ScenarioError(
            "plant.c_true",
            f"{list(pc.c_true)} disagrees with plant.robots ({refs[0].model}: "
            f"a={c[0, 0]:.4g}, b={c[0, 1]:.4g}); give one of them",
        )
    t = truths[0]
    plant = dataclasses.replace(pc, c_true=(float(c[0, 0]), float(c[0, 1])), mass=t.mass_eff, inertia=t.inertia_eff)
    return dataclasses.replace(sc, plant=plant)


# ---------------------------------------------------------------------------------------
# The paper's experiment at a robot's scale (issue 10)
# ---------------------------------------------------------------------------------------


#: the resolver of ``formation.scale/time_scale = "auto"``: ``resolver(sc) -> (s, σ, note)``. "auto" needs a run of the
#: scenario's demand (design §21), a floor above this one, so the run package registers it on import
#: (:func:`register_auto_scale`) instead of this module importing upwards.
_AUTO_SCALE: list[Any] = []


def register_auto_scale(resolver: Any) -> None:
    """Set the resolver of ``"auto"`` scale and time scale (called by :mod:`bioform_mj.run.auto_scale`).

    Parameters
    ----------
    resolver
        ``resolver(sc) -> (s, sigma, note)``: the length and time factors for scenario ``sc`` and why.
    """
    _AUTO_SCALE[:] = [resolver]


def apply_scale(sc: Scenario) -> Scenario:
    """Scale the experiment: lengths × ``s = formation.scale``, times × ``σ = formation.time_scale``,
    every key by its declared unit (:func:`bioform_mj.scenario.similarity.transform`, design §21).

    So the leader, the offsets and initial positions, the obstacles and the safety distances are ×
    s; the duration, the events' and faults' times × σ; speeds × s/σ, accelerations and sign gains
    × s/σ² (υ) or 1/σ² (ω), rates and frequencies × 1/σ, ``k2 / s²``, ``k3 / s``; ``init_jitter``
    × s, ``init_jitter_heading`` (an angle) kept, resolved from -1 to the ``init_jitter`` as written.
    Kept: the numerical steps, the divergence guards, the sensor's noise, the robot and what carries
    a mass (``torque.tau_max``, ``plant.c_true``). The paper's mixed-unit places (eq. 32's ``A, B,
    D``, eq. 37's ``k4``, ``torque.phi``) are said in :mod:`bioform_mj.scenario.similarity`. With ``σ = 1``
    this is the lengths-only scaling of before, bit for bit (``k1, A, B, D, k4`` unchanged).
    ``"auto"`` (either key): from the robot's half track and limits
    (the resolver the run package registers, :func:`register_auto_scale`:
    :func:`bioform_mj.run.auto_scale.resolve_auto`), the reason in ``formation.scale_note``.

    The values are those written (file and ``--set``); the returned scenario holds the scaled values
    and the numeric ``scale``, ``time_scale``; a run's record (:func:`bioform_mj.scenario.record.resolved_config`)
    holds the scaled values with both = 1, so loading it again does not scale twice.
    ``formation.scale_applied`` / ``time_scale_applied`` say what the values already carry (design
    §18.1); a scenario changed after loading (``dataclasses.replace``) is scaled by ``scale /
    scale_applied`` and ``time_scale / time_scale_applied``.
    """
    from bioform_mj.scenario.similarity import check_factor, transform

    f = sc.formation
    if f.scale == f.scale_applied and f.time_scale == f.time_scale_applied:
        return sc
    want_s, want_t, note = f.scale, f.time_scale, f.scale_note
    if isinstance(want_s, str) or isinstance(want_t, str):
        for key, v in (("formation.scale", want_s), ("formation.time_scale", want_t)):
            if isinstance(v, str) and v != "auto":
                raise ScenarioError(key, f'must be a number > 0 or "auto", got {v!r}')
        if not _AUTO_SCALE:
            raise ScenarioError(
                "formation.scale" if isinstance(want_s, str) else "formation.time_scale",
                '"auto" is resolved by a run of the scenario\'s demand: import bioform_mj.run first '
                "(bioform_mj.load and the bioform command do)",
            )
        want_s, want_t, note = _AUTO_SCALE[-1](sc)
    want_s = check_factor("formation.scale", want_s)
    want_t = check_factor("formation.time_scale", want_t)
    if want_s == f.scale_applied and want_t == f.time_scale_applied:
        return dataclasses.replace(
            sc, formation=dataclasses.replace(f, scale=want_s, time_scale=want_t, scale_note=note)
        )
    s = want_s / f.scale_applied  # exactly `want_s` for a scenario as written
    sigma = want_t / f.time_scale_applied
    jh = f.init_jitter if f.init_jitter_heading < 0 else f.init_jitter_heading  # an angle, as written
    out = transform(dataclasses.replace(sc, formation=dataclasses.replace(f, init_jitter_heading=jh)), s, sigma)
    formation = dataclasses.replace(
        out.formation,
        scale=want_s,
        time_scale=want_t,
        scale_applied=want_s,
        time_scale_applied=want_t,
        scale_note=note,
    )
    return dataclasses.replace(out, formation=formation)
