"""Default output folders, one per configuration (issue 28, :mod:`bioform_mj.cli.outdir`): commands copied one
after another, each with its own ``--set``/``--duration``, all succeed; the same configuration twice is refused
saying how to proceed."""

from __future__ import annotations

import json
import re
from pathlib import Path

from bioform_mj.cli.main import main
from bioform_mj.jobs.sweep import content_key
from bioform_mj.scenario.loader import load


def _err(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


def test_default_folders_distinct_per_configuration(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    base = ["run", "paper", "--plant", "ideal", "--quiet"]
    cmds = [
        [*base, "--duration", "0.2"],
        [*base, "--duration", "0.2", "--set", "kinematic.k1=3"],
        [*base, "--duration", "0.2", "--seed", "4"],
    ]
    for c in cmds:
        assert main(c) == 0, _err(capsys)
    folders = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert len(folders) == 3 and all(re.fullmatch(r"paper-ideal-bioinspired-learning-[0-9a-f]{8}", f) for f in folders)
    for f in folders:  # each folder's hash is its own recorded configuration's content key (seed included)
        sc = load(str(tmp_path / "runs" / f / "resolved.toml"))
        assert f.endswith(content_key(sc)[:8]), f
        assert json.loads((tmp_path / "runs" / f / "summary.json").read_text())["config"]["sim"]["duration"] == 0.2
    # the same configuration again: its folder holds that run; refused, saying how to proceed, nothing changed
    before = sorted(p.name for p in (tmp_path / "runs").iterdir())
    assert main(cmds[1]) == 2
    err = _err(capsys)
    assert len(err) == 1 and err[0].startswith("error:") and "--overwrite" in err[0] and "--out" in err[0], err
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == before
    # the scenario as named keeps the folder the docs name (no hash); --out is the user's
    assert main([*base, "--out", "runs/mine", "--set", "kinematic.k1=2", "--duration", "0.2"]) == 0
    assert (tmp_path / "runs" / "mine" / "summary.json").is_file()


def test_table1_default_folder_distinct(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    args = ["table1", "paper", "--plant", "ideal", "--quiet", "--methods", "bioinspired", "--duration", "0.2"]
    assert main(args) == 0 and main([*args, "--set", "kinematic.k1=3"]) == 0, _err(capsys)
    names = sorted(p.name for p in Path("runs").iterdir())
    assert len(names) == 2 and all(re.fullmatch(r"table1-ideal-[0-9a-f]{8}", n) for n in names), names


def test_no_doc_page_runs_one_configuration_twice_into_its_default_folder():
    """Copied one after another, a page's commands never meet their own earlier run: within a page, no two
    ``bioform run``/``table1`` commands without ``--out`` differ only by output flags (they would share the
    default folder; the second would be refused)."""
    root = Path(__file__).resolve().parents[1]
    outputs = re.compile(r" --(video|rrd|rosbag|figures|quiet|overwrite)\b")
    for page in [root / "README.md", *sorted((root / "docs").rglob("*.md"))]:
        seen: dict[str, int] = {}
        lines = page.read_text().splitlines()
        for i, line in enumerate(lines):
            m = re.match(r"^(?:\.venv/bin/)?bioform (run|table1) ([^#]*)", line)
            if not m:
                continue
            cmd, j = m.group(0).rstrip(), i
            while cmd.endswith("\\") and j + 1 < len(lines):  # a command continued on the next lines
                j += 1
                cmd = cmd[:-1] + " " + lines[j].split("#")[0].strip()
            if "--out" in cmd:
                continue
            key = " ".join(outputs.sub("", cmd).replace(".venv/bin/", "").split())
            assert key not in seen, f"{page.name}:{i + 1} runs the configuration of line {seen[key]} again: {key}"
            seen[key] = i + 1


def test_xacro_args_and_control_rate_change_the_default_folder():
    """Two runs that differ only in ``--xacro-arg`` (or ``--control-rate``) are different configurations: the
    hash is added, so the second does not meet the first's folder (issue 28)."""
    import argparse

    from bioform_mj.cli.outdir import changes_configuration

    plain = argparse.Namespace(overrides=[], duration=None, seed=None, package_path=[], xacro_arg=[], control_rate=None)
    assert not changes_configuration(plain)
    assert changes_configuration(argparse.Namespace(**{**vars(plain), "xacro_arg": ["WHEEL_R=0.07"]}))
    assert changes_configuration(argparse.Namespace(**{**vars(plain), "control_rate": 50.0}))
