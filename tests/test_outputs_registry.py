"""The outputs registry (design §22, ``outputs/registry.py``): ``bioform run``'s output flags and ``--overwrite``'s
file list come from it, every registered output writes the files it declares and ``--overwrite`` removes them
(conformance over every entry), and one more output is one registration."""

from __future__ import annotations

import pytest

from bioform_mj.cli.main import build_parser, main
from bioform_mj.outputs import registry
from bioform_mj.outputs.registry import OUTPUTS, Output, output_dirs, output_files, register_output
from bioform_mj.outputs.rundir import RUN_DIRS, RUN_FILES

RUN = ["run", "paper", "--plant", "ideal", "--set", "sim.duration=0.3", "--quiet"]


def _run_options() -> set[str]:
    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    return {opt for a in sub.choices["run"]._actions for opt in a.option_strings}


def test_the_flags_and_the_overwrite_list_come_from_the_registry():
    assert list(OUTPUTS) == ["video", "rrd", "figures", "rosbag"]
    assert {o.flag for o in OUTPUTS.values()} <= _run_options()
    assert output_files() <= RUN_FILES and output_dirs().items() <= RUN_DIRS.items()


@pytest.mark.parametrize("name", list(OUTPUTS))
def test_every_registered_output_writes_its_files_and_overwrite_removes_them(name, tmp_path):
    o = OUTPUTS[name]
    extra = []
    if name == "video":
        from bioform_mj.outputs.gl import GLUnavailable, probe

        try:
            probe()
        except GLUnavailable as exc:
            pytest.skip(f"no OpenGL context in this process: {exc}")
        extra = ["--width", "64", "--height", "48", "--fps", "10"]
    out = tmp_path / "run"
    assert main([*RUN, "--out", str(out), o.flag, *extra]) == 0
    for f in o.files:
        assert (out / f).is_file() and (out / f).stat().st_size > 0, f
    for d, sfx in o.dirs:
        got = list((out / d).iterdir())
        assert got and all(p.suffix in sfx for p in got), got
    assert main([*RUN, "--out", str(out), "--overwrite"]) == 0  # the old run's outputs go with it
    assert not any((out / f).exists() for f in o.files) and not any((out / d).exists() for d, _ in o.dirs)


def test_one_more_output_is_one_registration(tmp_path, monkeypatch):
    (tmp_path / "bioform_notes_output.py").write_text(
        "from pathlib import Path\n\n"
        "def write(result, out, **_):\n"
        "    (Path(out) / 'notes.txt').write_text(result.summary['method'])\n"
        "    return 'notes.txt written'\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(registry, "OUTPUTS", dict(OUTPUTS))
    register_output(Output("notes", "write notes.txt", ("notes.txt",), "bioform_notes_output:write"))
    monkeypatch.setattr("bioform_mj.cli.main.OUTPUTS", registry.OUTPUTS)
    assert "--notes" in _run_options()
    out = tmp_path / "run"
    assert main([*RUN, "--out", str(out), "--notes"]) == 0
    assert (out / "notes.txt").read_text() == "bioinspired-learning"
    with pytest.raises(ValueError, match="registered already"):
        register_output(Output("notes", "again", ("other.txt",), "bioform_notes_output:write"))
    with pytest.raises(ValueError, match="run.rrd written by another output"):
        register_output(Output("rrd2", "again", ("run.rrd",), "bioform_notes_output:write"))
    with pytest.raises(ValueError, match="module:function"):
        register_output(Output("x", "x", ("x.txt",), "no_colon"))
