"""The documentation cannot rot: generated references cover the code, the tutorial runs, the README is short."""

from __future__ import annotations

import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bioform_mj.core.errors import InputError
from bioform_mj.scenario import doc as scenario_doc
from bioform_mj.scenario.loader import load

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _gen_docs():
    spec = importlib.util.spec_from_file_location("gen_docs", ROOT / "scripts" / "gen_docs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_every_scenario_key_has_a_description_and_no_entry_is_stale():
    keys = scenario_doc.scenario_keys()
    assert len(keys) >= 90  # 95 keys today
    missing = [k for k in keys if not scenario_doc.KEYS.get(k, ("", ""))[1].strip()]
    assert not missing, f"scenario keys without a description in scenario_doc.KEYS: {missing}"
    stale = sorted(set(scenario_doc.KEYS) - set(keys))
    assert not stale, f"scenario_doc.KEYS names keys the scenario does not have: {stale}"
    assert set(scenario_doc.CHOICES) <= set(keys)


@pytest.mark.parametrize("key", [k for k in scenario_doc.CHOICES if "[]" not in k])
def test_documented_choices_are_the_validated_ones(key):
    """Every allowed value the reference lists is accepted by validation's list, and another string is refused."""
    with pytest.raises(InputError, match=re.escape(key)):
        load("paper", {key: "no-such-value"})


def test_scenario_reference_has_one_row_per_key_with_type_default_and_choices():
    md = _gen_docs().scenario_reference()
    rows = [ln for ln in md.splitlines() if ln.startswith("| `")]
    assert len(rows) == len(scenario_doc.scenario_keys())
    frame = next(r for r in rows if r.startswith("| `formation.frame`"))
    assert '"world", "leader"' in frame and '`"world"`' in frame  # allowed values and default
    jitter = next(r for r in rows if r.startswith("| `formation.init_jitter`"))
    assert "| number | m | `0.0` |" in jitter


def test_cli_reference_lists_every_subcommand_and_option():
    gen = _gen_docs()
    md = gen.cli_reference()
    from bioform_mj.cli.main import build_parser

    subs = gen._subcommands(build_parser(), "bioform")
    assert {c for c, _h, _p in subs} >= {"bioform run", "bioform sweep", "bioform robot check", "bioform bench"}
    for cmd, _help, parser in subs:
        assert f"## `{cmd}`" in md
        for action in parser._actions:
            for opt in action.option_strings:
                if opt not in ("-h", "--help"):
                    assert f"`{opt}`" in md, (cmd, opt)


def test_log_reference_names_every_channel_and_column():
    from bioform_mj.core.engine import CHANNELS
    from bioform_mj.run.logtable import column_units

    md = _gen_docs().log_reference()
    for ch in CHANNELS:
        assert f"| `{ch}` |" in md
    for col in column_units():
        if col != "follower":
            assert f"`{col}`" in md


def test_tutorial_runs_and_prints_what_the_docs_show():
    """docs/tutorials/own_controller.py, included into its page, prints the committed output."""
    script = DOCS / "tutorials" / "own_controller.py"
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout == (DOCS / "tutorials" / "own_controller.out").read_text()
    errs = [float(x) for x in re.findall(r"\d+\.\d+", out.stdout.splitlines()[0])]
    assert len(errs) == 3 and max(errs) < 0.05  # the user's controller holds the formation: 0.019-0.022 m
    page = (DOCS / "tutorials" / "own-controller.md").read_text()
    assert '--8<-- "docs/tutorials/own_controller.py"' in page and '--8<-- "docs/tutorials/own_controller.out"' in page


def test_the_rerun_entities_documented_are_the_ones_logged():
    import inspect

    from bioform_mj.outputs import rerun_log

    page = (DOCS / "guide" / "outputs.md").read_text()
    for leaf, _fn, _names in rerun_log._SERIES:
        assert f"`{leaf}`" in page, leaf
    src = inspect.getsource(rerun_log)
    for entity in ("/world/leader", "/world/paths/leader", "/summary"):
        assert f'"{entity}"' in src and f"`{entity}`" in page
    for leaf in ("robot", "estimate", "slot", "path"):
        assert f'f"{{base}}/{leaf}"' in src and f"`/world/follower/<i>/{leaf}`" in page
    assert 'base = f"/world/follower/{i + 1}"' in src


def test_every_page_is_in_the_nav_and_every_nav_entry_exists():
    nav = re.findall(r":\s*([\w/.-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), flags=re.M)
    generated = {"reference/scenario.md", "reference/cli.md", "reference/log.md"}
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.rglob("*.md")}
    assert set(nav) - generated <= pages, set(nav) - generated - pages
    assert generated <= set(nav)
    assert pages <= set(nav), f"pages not in mkdocs.yml's nav: {sorted(pages - set(nav))}"


def test_findings_are_a_report_not_a_diary():
    diary = re.compile(r"\bround \d|\bissue \d|this round|previous measurement|\bRound \d", re.I)
    for page in sorted((DOCS / "findings").glob("*.md")):
        hits = [ln for ln in page.read_text().splitlines() if diary.search(ln)]
        assert not hits, (page.name, hits[:3])
    for page in sorted((DOCS / "findings").glob("*.md")):
        if page.name != "index.md":
            text = page.read_text()
            # each finding says how to reproduce it: a command in backticks right after the bold label
            assert re.search(r"\*\*Reproduce:\*\*\s+`[^`]+`", text), page.name
            # and the scripts and test files those commands run are in the repository
            for named in re.findall(r"\b((?:scripts|tests)/[\w/.-]+\.py)\b", text):
                assert (ROOT / named).exists(), (page.name, named)


def test_readme_is_a_front_door():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 250
    for target in re.findall(r"\]\((docs/[^)#]+)", text):
        assert (ROOT / target).exists() or target.startswith("docs/reference/"), target
    assert "/world/follower/" not in text or "/world/follower/<i>/robot" in text
    found = text.split("## What we found", 1)[1].split("\n## ", 1)[0]
    assert 0 < len([ln for ln in found.splitlines() if ln.strip()]) <= 15  # headline findings, then a link
    for extra in ("`test` extra", "`gpu` extra", "`docs` extra"):  # what make test installs, said
        assert extra in text
    assert text.count("~/.cache/bioform_mj/numba-") == 1  # the compile cache, stated once


def test_readme_python_quick_start_runs_as_written(capsys):
    """The README's Python quick start, executed as it stands (no pandas needed), prints what its comments say."""
    text = (ROOT / "README.md").read_text()
    block = text.split("## Quick start: Python", 1)[1].split("```python\n", 1)[1].split("```", 1)[0]
    exec(compile(block, "README.md (Python quick start)", "exec"), {})
    first, second = capsys.readouterr().out.splitlines()[:2]
    errs = [float(x) for x in re.findall(r"\d+\.\d+(?:e-?\d+)?", first)]
    assert len(errs) == 3 and max(errs) < 0.05  # 10 s on the ideal plant: 0.021-0.029 m
    assert second.startswith("3000 ['t_s', 'follower', 'leader_pose_x_m'")  # 1000 rows × 3 followers


def _mkdocs_strict(cwd: Path, site: Path) -> subprocess.CompletedProcess:
    """``mkdocs build --strict -d site`` in ``cwd`` with this checkout's src first on the path."""
    env = dict(
        os.environ,
        NO_MKDOCS_2_WARNING="1",
        DISABLE_MKDOCS_2_WARNING="true",
        PYTHONPATH=str(ROOT / "src") + os.pathsep + os.environ.get("PYTHONPATH", ""),
    )
    # not --quiet: it hides the warnings from strict mode too, and a broken link would pass
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(site)]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=env, timeout=300)


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="the docs extra is not installed")
def test_docs_build_strictly(tmp_path):
    """mkdocs build --strict: a broken link, a missing page or a stale API reference fails."""
    out = _mkdocs_strict(ROOT, tmp_path / "site")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "WARNING" not in out.stderr, out.stderr[-3000:]
    site = tmp_path / "site"
    scen = (site / "reference" / "scenario.html").read_text()  # use_directory_urls: false, browsable from disk
    assert "formation.init_jitter" in scen and "faults.friction_patch" in scen
    api = (site / "reference" / "api.html").read_text()
    for name in ("bioform_mj.assess.check.check", "bioform_mj.robots.prepare.prepare_robot", "RobotLayout"):
        assert name in api, name  # the robot modules' public names (after the split of scene.py)
    assert not re.search(r":(func|class|mod|meth|data):", api)  # Sphinx roles rendered as code, not as typed
    tut = (site / "tutorials" / "own-controller.html").read_text()
    assert "SlotTracker" in tut and "--8&lt;--" not in tut and "8 &lt; --" not in tut  # the script itself, included
    # opened from disk (file://): every internal link and asset names a file, never a folder (a browser shows a
    # folder as a directory listing); search's index is a script a page loads without a server (offline plugin)
    assert len(list(site.rglob("*.html"))) >= 30
    broken = _links_not_files(site)
    assert not broken, broken[:10]
    assert (site / "search" / "search_index.js").read_text().startswith("var __index = {")
    bundle = next((site / "assets" / "javascripts").glob("bundle.*.min.js")).read_text()
    assert "search_index.js" in bundle  # which the theme loads when the page is a file:// one


def _links_not_files(site: Path) -> list[str]:
    """``page: link`` for every relative ``href``/``src`` of the built site that is not an existing file."""
    from urllib.parse import unquote, urlsplit

    bad, pages = [], sorted(site.rglob("*.html"))
    for page in pages:
        if page.name == "404.html" and page.parent == site:  # a server's error page: its links are site-absolute
            continue
        for link in re.findall(r'(?:href|src)="([^"]*)"', page.read_text()):
            parts = urlsplit(link)
            if parts.scheme or link.startswith(("#", "//")) or not parts.path:
                continue
            target = (page.parent / unquote(parts.path)).resolve()
            if not target.is_file():
                bad.append(f"{page.relative_to(site)}: {link}")
    return bad


def test_the_link_check_finds_a_folder_link_and_a_missing_file(tmp_path):
    """What a directory-URL build writes (``guide/x/``: a folder, a directory listing from disk) is found, as is a
    missing file; files, anchors, external and the 404 page's site-absolute links are not."""
    site = tmp_path / "site"
    (site / "guide" / "x").mkdir(parents=True)
    (site / "guide" / "x" / "index.html").write_text("")
    (site / "a.html").write_text('<a href="a.html#top"></a><a href="https://x.org/"></a><img src="guide/x/index.html">')
    (site / "b.html").write_text('<a href="guide/x/"></a><a href="nope.html"></a><link href="#s">')
    (site / "404.html").write_text('<a href="/index.html"></a>')
    assert _links_not_files(site) == ["b.html: guide/x/", "b.html: nope.html"]


@pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None, reason="the docs extra is not installed")
def test_a_broken_link_fails_the_strict_build(tmp_path):
    """The build make test runs would fail on a broken link (a copy of the docs with one added)."""
    import shutil

    work = tmp_path / "w"
    shutil.copytree(DOCS, work / "docs")
    shutil.copy(ROOT / "mkdocs.yml", work / "mkdocs.yml")
    (work / "scripts").mkdir()
    for script in ("gen_docs.py", "griffe_sphinx_roles.py"):  # what mkdocs.yml runs
        shutil.copy(ROOT / "scripts" / script, work / "scripts" / script)
    (work / "src").symlink_to(ROOT / "src")
    with open(work / "docs" / "guide" / "faults.md", "a") as fh:
        fh.write("\n[a page that is not there](no-such-page.md)\n")
    out = _mkdocs_strict(work, tmp_path / "site")
    assert out.returncode != 0 and "no-such-page.md" in out.stderr


@pytest.mark.skipif(shutil.which("make") is None, reason="no make")
def test_make_docs_without_the_docs_extra_says_how_to_install_it(tmp_path):
    """`make docs` in a venv that lacks MkDocs: one error line naming the install command, exit 2, no build."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    (venv / ".installed").touch()  # the package's own install step (make's stamp) taken as done
    out = subprocess.run(
        ["make", "-s", "-C", str(ROOT), "docs", f"VENV={venv}"], capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 2, out.stderr
    first = out.stderr.splitlines()[0]
    assert first.startswith("error: the docs extra is missing") and "pip install -e '.[docs]'" in first
    assert "Traceback" not in out.stderr


def _package_modules() -> dict[str, str]:
    """``{"robot_prepare": "bioform_mj.robots.prepare", "batch.support": ..., ...}``: every module by its short name."""
    pkg = ROOT / "src" / "bioform_mj"
    out = {}
    for p in pkg.rglob("*.py"):
        parts = p.relative_to(pkg).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        if parts:
            out[".".join(parts)] = "bioform_mj." + ".".join(parts)
    return out


def test_code_the_docs_name_exists_and_the_design_names_its_home():
    """Every `module.name` in README and docs/ resolves; the design documents name the module that defines it
    (after a split, `scene.prepare_robot` still resolved through a re-export while the code was elsewhere)."""
    import importlib
    import inspect

    mods = _package_modules()
    keys = set(scenario_doc.scenario_keys())
    alt = "|".join(re.escape(m) for m in sorted(mods, key=len, reverse=True))
    ref = re.compile(r"`(?:bioform_mj\.)?(" + alt + r")\.([A-Za-z_]\w*)(?:\.(\w+))?(?:\(\))?`")
    suffixes = {"py", "xml", "md", "json", "toml", "csv", "npz", "rrd", "mp4", "parquet", "txt"}
    bad = []
    for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        design = page.name in ("design.md", "warp_engine.md")
        for ln, line in enumerate(page.read_text().splitlines(), 1):
            for m in ref.finditer(line):
                mod, attr, sub = m.groups()
                if attr in suffixes or any(k == f"{mod}.{attr}" or k.startswith(f"{mod}.{attr}[") for k in keys):
                    continue  # a file name, or a scenario key (sim.seed, faults.delay, plant.robots[] …)
                try:
                    module = importlib.import_module(mods[mod])
                except ImportError:  # an extra that is not installed here (warp, pettingzoo)
                    continue
                obj = getattr(module, attr, None)
                if obj is None and f"{mod}.{attr}" not in mods or (sub and not hasattr(obj, sub)):
                    bad.append(f"{page.relative_to(ROOT)}:{ln}: {m.group(0)} does not exist")
                elif design and (inspect.isfunction(obj) or inspect.isclass(obj)) and obj.__module__ != mods[mod]:
                    bad.append(f"{page.relative_to(ROOT)}:{ln}: {m.group(0)} is defined in {obj.__module__}")
    for page in [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]:
        for path in re.findall(
            r"`((?:src/bioform_mj|scripts|tests|examples|docs)/[\w/.*-]+\.(?:py|toml|xml|md))", page.read_text()
        ):
            generated = path.startswith("docs/reference/") and path.rsplit("/", 1)[-1] in (
                "scenario.md",
                "cli.md",
                "log.md",
            )
            if not generated and not list(ROOT.glob(path)):
                bad.append(f"{page.relative_to(ROOT)}: `{path}` does not exist")
        for path in re.findall(
            r"`((?:core|formation|control|robots|scenario|plants|outputs|assess|run|batch|envs|jobs|cli)/[\w/]+\.py)",
            page.read_text(),
        ):
            if not (ROOT / "src" / "bioform_mj" / path).exists():  # a subpackage's module, named from the package
                bad.append(f"{page.relative_to(ROOT)}: `{path}` does not exist")
    assert not bad, "\n".join(bad)
