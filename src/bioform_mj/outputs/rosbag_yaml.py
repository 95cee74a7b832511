"""The YAML of a rosbag2 bag's metadata (issue 29; :mod:`bioform_mj.outputs.rosbag_write`): a block-style
writer for the plain data it holds (:func:`yaml_text`: each connection's QoS, ``metadata.yaml`` and the
MCAP's copy of it), with what recurs from bag to bag made once per process (:func:`qos_text`, each topic's
entry in :func:`metadata_text`).
"""

from __future__ import annotations

import functools
import json
import math
import re
from typing import Any

__all__ = ["metadata_text", "qos_text", "yaml_text"]

_YAML_KEY = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_YAML_PLAIN = re.compile(r"[A-Za-z_/][A-Za-z0-9_/.\-]*")
#: plain words a YAML 1.1 reader takes for booleans or null
_YAML_WORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null"}
_YAML_UNSAFE = re.compile("[\x7f-\x9f\ud800-\udfff\ufeff\ufffe\uffff]")


def _yaml_scalar(v: Any) -> str:
    if v is None:
        return "null"
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else {math.inf: ".inf", -math.inf: "-.inf"}.get(v, ".nan")
    if isinstance(v, dict):
        return "{}"
    if isinstance(v, list | tuple):
        return "[]"
    if type(v) is str:
        return _yaml_str(v)
    return _yaml_text_scalar(v)


def _yaml_text_scalar(v: Any) -> str:
    if _YAML_PLAIN.fullmatch(v) and v.lower() not in _YAML_WORDS:  # a name: plain, as rosbag2 writes it
        return v
    # a JSON string is a YAML double-quoted scalar; the characters YAML wants escaped and JSON leaves, escaped
    return _YAML_UNSAFE.sub(lambda m: f"\\u{ord(m.group()):04x}", json.dumps(str(v), ensure_ascii=False))


@functools.lru_cache(maxsize=1024)
def _yaml_str(v: str) -> str:
    """A string scalar, memoised (a bag's names, types and hashes recur in every bag of a process)."""
    return _yaml_text_scalar(v)


@functools.lru_cache(maxsize=256)
def _yaml_key(k: str) -> str:
    return k if _YAML_KEY.fullmatch(k) else _yaml_scalar(k)


def _yaml_lines(obj: Any, ind: int) -> list[str]:
    pad, out = " " * ind, []
    if isinstance(obj, dict):
        for k, v in obj.items():
            key = _yaml_key(k) if isinstance(k, str) else _yaml_scalar(k)
            if isinstance(v, dict | list | tuple) and v:
                out.append(f"{pad}{key}:")
                out += _yaml_lines(v, ind + 2)
            else:
                out.append(f"{pad}{key}: {_yaml_scalar(v)}")
    else:
        for v in obj:
            if isinstance(v, dict | list | tuple) and v:
                sub = _yaml_lines(v, ind + 2)
                out += [f"{pad}- {sub[0][ind + 2 :]}", *sub[1:]]
            else:
                out.append(f"{pad}- {_yaml_scalar(v)}")
    return out


def yaml_text(obj: Any) -> str:
    """``obj`` (dicts, lists, strings, numbers, None) as block-style YAML, no trailing newline: the rosbag2
    metadata and QoS profiles (strings double-quoted; read back by any YAML 1.1/1.2 reader as ``obj``,
    ``tests/test_outputs_rosbag.py``)."""
    if isinstance(obj, dict | list | tuple) and obj:
        return "\n".join(_yaml_lines(obj, 0))
    return _yaml_scalar(obj)


@functools.lru_cache(maxsize=64)
def qos_text(qos: tuple) -> str:
    """The YAML of QoS profiles ``qos`` as rosbag2 v9 metadata states them, made once per process."""
    from rosbags.rosbag2.metadata import dump_qos_v9

    return yaml_text(dump_qos_v9(list(qos)))


@functools.lru_cache(maxsize=512)
def _topic_entry(name: str, msgtype: str, fmt: str, qos: tuple, digest: str) -> str:
    """One entry of ``topics_with_message_count`` as :func:`yaml_text` writes it in the metadata (indent 2),
    but its last line, ``message_count`` (:func:`metadata_text`)."""
    from rosbags.rosbag2.metadata import dump_qos_v9

    meta = {"name": name, "type": msgtype, "serialization_format": fmt}
    meta |= {"offered_qos_profiles": dump_qos_v9(list(qos)), "type_description_hash": digest}
    lines = _yaml_lines([{"topic_metadata": meta, "message_count": 0}], 2)
    assert lines[-1] == "    message_count: 0"
    return "\n".join(lines[:-1])


def metadata_text(head: dict[str, Any], topics: list[tuple], tail: dict[str, Any]) -> str:
    """``yaml_text(head | {"topics_with_message_count": …} | tail)``, the rosbag2 metadata, each topic's
    entry (``topics``: ``(name, type, serialization format, QoS profiles tuple, type hash, message count)``)
    made once per process (a sweep's bags, a process's later runs, state the same topics)."""
    if not (head and topics and tail):
        raise ValueError("metadata_text: head, topics and tail must not be empty")
    entries = "\n".join(f"{_topic_entry(*t[:5])}\n    message_count: {_yaml_scalar(t[5])}" for t in topics)
    return f"{yaml_text(head)}\ntopics_with_message_count:\n{entries}\n{yaml_text(tail)}"
