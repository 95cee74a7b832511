"""Every command the README and the documentation show runs as written from a fresh clone (issue 28, item 5).

The shell blocks (```` ```bash ````, ```` ```sh ````, ```` ```console ````: in a console block the ``$`` lines) of
README.md and docs/**/*.md are read here. A block whose fence carries a title starting with ``Not run by the docs
test`` (```` ```bash title="Not run by the docs test: needs a GPU" ````, shown as the block's title on the site;
docs/index.md states the convention) is checked for its programs only.

Fast, for every command: the program exists (``bioform``, ``.venv/bin/bioform``, ``python``, ``make`` with its
target, ...); every ``bioform`` invocation parses with the CLI's own argparse (``cli.main.build_parser``); every
preset, robot file, scenario file, bag and example script it names exists (or is made by an earlier command of
its block); and a scenario's ``--set`` overrides load (``scenario.loader.load``: the keys exist, the values fit).

Slow (``test_docs_commands_run_as_written``): every runnable block is run as written, one ``bash`` per block, in a
temporary copy of the repository whose ``.venv`` is this interpreter's environment (the README's set-up, done),
with that ``.venv/bin`` first on ``PATH`` (what ``source .venv/bin/activate`` does) and a per-command time limit.
It runs for many minutes, so beyond ``slow`` it runs only when ``BIOFORM_DOCS_COMMANDS=1`` (``make docs-commands``).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
SHELL = ("bash", "sh", "console")
NOT_RUN = "Not run by the docs test"  # the title that marks a block not runnable here, with its reason
PAGES = [ROOT / "README.md", *sorted(p for p in DOCS.rglob("*.md"))]
PER_COMMAND_S = 900.0  # a command of the docs that runs longer than this is a failure (a shipped sweep: ~4 min)
# programs a docs command may start, besides bioform/python/make/pip (checked below) and these standard tools
TOOLS = {"cat", "echo", "cd", "ls", "head", "tail", "mkdir", "export", "source", "git", "ros2", "rerun", "cp"}
# `make test` is this test suite: running it from inside the suite would run this test again
NEVER_RUN = {"make test": "make test runs this test suite (and this test): not run from inside it"}


@dataclass
class Command:
    """One command of a block: its text (continuation lines joined, a heredoc's body kept), where it starts."""

    text: str
    line: int  # 1-based line in the page
    shown: list[str] = field(default_factory=list)  # a console block: the output shown under it


@dataclass
class Block:
    page: Path
    line: int  # the fence's line
    lang: str
    title: str
    body: list[str]
    commands: list[Command]

    @property
    def where(self) -> str:
        return f"{self.page.relative_to(ROOT)}:{self.line}"

    @property
    def runnable(self) -> bool:
        return not self.title.startswith(NOT_RUN)


def _commands(lines: list[str], first: int, console: bool) -> list[Command]:
    """The commands of a block's lines (``first``: the page line of ``lines[0]``)."""
    out: list[Command] = []
    i = 0
    while i < len(lines):
        raw = lines[i]
        if console:
            if not raw.startswith("$ "):
                if out:
                    out[-1].shown.append(raw)
                i += 1
                continue
            raw = raw[2:]
        if not raw.strip() or raw.lstrip().startswith("#"):
            i += 1
            continue
        start = i
        text = raw
        while text.rstrip().endswith("\\") and i + 1 < len(lines):  # continuation lines
            i += 1
            text = text.rstrip()[:-1] + " " + lines[i].strip()
        here = re.search(r"<<-?\s*'?\"?(\w+)'?\"?", text)
        if here:  # a heredoc: its body, up to the delimiter, belongs to the command
            end = i + 1
            while end < len(lines) and lines[end].strip() != here.group(1):
                end += 1
            text = "\n".join([text, *lines[i + 1 : end + 1]])
            i = end
        out.append(Command(text, first + start))
        i += 1
    return out


def blocks(pages: list[Path] = PAGES) -> list[Block]:
    """Every shell block of ``pages``."""
    found = []
    for page in pages:
        lines = page.read_text().splitlines()
        i = 0
        while i < len(lines):
            m = re.match(r"^(\s*)```(\w*)(.*)$", lines[i])
            if not m:
                i += 1
                continue
            indent, lang, info = m.groups()
            j = i + 1
            while j < len(lines) and lines[j].strip() != "```":
                j += 1
            if lang in SHELL:
                body = [ln[len(indent) :] if ln.startswith(indent) else ln for ln in lines[i + 1 : j]]
                title = re.search(r'title="([^"]*)"', info)
                cmds = _commands(body, i + 2, console=lang == "console")
                found.append(Block(page, i + 1, lang, title.group(1) if title else "", body, cmds))
            i = j + 1
    return found


def _simple_commands(text: str) -> list[list[str]]:
    """The simple commands of a command line (split at ``|``, ``;``, ``&&``, ``||``), each as words, with
    redirections and leading ``VAR=value`` assignments left out; a heredoc's body is not a command."""
    first = text.split("\n", 1)[0]
    lex = shlex.shlex(first, posix=True, punctuation_chars=True)
    lex.whitespace_split = True
    lex.commenters = "#"
    words = list(lex)
    out, cur, skip = [], [], False
    for w in words:
        if w in ("|", ";", "&&", "||", "&"):
            out.append(cur)
            cur = []
        elif w in (">", ">>", "<", "<<", "<<-", "2>", "&>", ">&"):
            skip = True
        elif skip:
            skip = False
        else:
            cur.append(w)
    out.append(cur)
    simple = []
    for c in out:
        while c and re.match(r"^[A-Za-z_]\w*=", c[0]):
            c = c[1:]
        if c:
            simple.append(c)
    return simple


def _assignments(block: Block) -> dict[str, str]:
    """``NAME=value`` lines of a block (``URDF=~/src/...``), for the fast check's expansion of ``$NAME``."""
    env = {}
    for c in block.commands:
        m = re.match(r"^([A-Za-z_]\w*)=(\S+)$", c.text.strip())
        if m:
            env[m.group(1)] = os.path.expanduser(m.group(2))
    return env


def _made_by_block(block: Block) -> list[str]:
    """What the block's own commands create (the fast check takes these as existing): ``--out`` folders and the
    files ``--json``/``--out`` name, a heredoc's file, a ``git clone``'s folder, a run's default ``runs/`` folder."""
    made = ["runs/"]
    for c in block.commands:
        for words in _simple_commands(c.text):
            for flag in ("--out", "--json"):
                if flag in words and words.index(flag) + 1 < len(words):
                    made.append(words[words.index(flag) + 1].rstrip("/"))
            if words[:2] == ["git", "clone"] and len(words) >= 4:
                made.append(os.path.expanduser(words[3]))
            if words[0] == "cp" and len(words) >= 3:
                made.append(words[-1])
        m = re.search(r"cat\s*>\s*(\S+)\s*<<", c.text)
        if m:
            made.append(m.group(1))
    return made


def _exists(path: str, made: list[str]) -> bool:
    p = os.path.expanduser(path)
    return (ROOT / p).exists() or any(p == m or p.startswith(m.rstrip("/") + "/") or p == m + "/" for m in made)


def _check_bioform(argv: list[str], made: list[str], names: bool = True) -> list[str]:
    """Problems with one ``bioform`` invocation: it parses, and (``names``) what it names exists and loads
    (a value ``"auto"`` resolves by a run of the scenario's demand, minutes: its key is checked, not loaded)."""
    from bioform_mj import load
    from bioform_mj.cli.main import build_parser
    from bioform_mj.core.errors import InputError
    from bioform_mj.robots.refs import robot_names
    from bioform_mj.scenario.loader import preset_names

    try:
        args = build_parser().parse_args(argv)
    except InputError as exc:
        return [f"does not parse: {exc}"]
    except SystemExit:  # --help
        return []
    if not names:
        return []
    bad = []
    scenario = getattr(args, "scenario", None)
    if args.command == "calibrate":
        scenario = args.scenario
    if scenario is not None and scenario not in preset_names() and not _exists(scenario, made):
        bad.append(f"scenario {scenario!r} is neither a preset nor a file")
    model = getattr(args, "model", None)
    if model is not None and model not in robot_names() and not _exists(model, made):
        bad.append(f"robot {model!r} is neither a shipped robot nor a file")
    for attr in ("bag", "calibrated"):
        v = getattr(args, attr, None)
        if v is not None and not _exists(str(v), made):
            bad.append(f"--{attr} {v} does not exist")
    for spec in getattr(args, "package_path", None) or []:
        d = spec.split("=", 1)[-1]
        if not _exists(d, made):
            bad.append(f"--package-path {spec}: {d} does not exist")
    if (
        args.command in ("run", "table1", "sweep")
        and scenario in preset_names()
        or (args.command in ("run", "table1", "sweep") and scenario and (ROOT / scenario).is_file())
    ):
        from bioform_mj.scenario.doc import scenario_keys

        auto = [o for o in args.overrides if o.split("=", 1)[-1].strip("'\"") == "auto"]
        bad += [f"--set {o}: no such key" for o in auto if o.split("=", 1)[0] not in scenario_keys()]
        overrides = [o for o in args.overrides if o not in auto]
        if args.duration is not None:
            overrides.append(f"sim.duration={args.duration!r}")
        if args.seed is not None:
            overrides.append(f"sim.seed={args.seed}")
        cwd = os.getcwd()
        try:
            os.chdir(ROOT)  # the docs' relative paths are the clone's
            load(scenario, overrides, plant=args.plant)
        except InputError as exc:
            bad.append(f"does not load: {exc}")
        finally:
            os.chdir(cwd)
    return bad


def _check_command(words: list[str], block: Block, made: list[str], env: dict[str, str]) -> list[str]:
    """Problems with one simple command: the program, and what it names."""
    words = [re.sub(r"\$\{?(\w+)\}?", lambda m: env.get(m.group(1), m.group(0)), w) for w in words]
    prog, rest = words[0], words[1:]
    venv_bin = Path(sys.prefix) / "bin"
    if prog.startswith(".venv/bin/"):
        name = prog.removeprefix(".venv/bin/")
        if not (venv_bin / name).exists():
            return [f"{prog}: {name} is not installed in the environment make test sets up"]
        prog = name
    if prog == "bioform":
        return _check_bioform(rest, made, names=block.runnable)
    if not block.runnable and prog.startswith("..."):  # an elided step of a block that is not run
        return []
    if prog in ("python", "python3"):
        if rest[:1] == ["-m"]:
            import importlib.util

            return [] if importlib.util.find_spec(rest[1]) else [f"python -m {rest[1]}: no such module"]
        if rest and rest[0].endswith(".py") and not _exists(rest[0], made):
            return [f"python {rest[0]}: no such script"]
        return []
    if prog == "make":
        targets = re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), flags=re.M)
        return [
            f"make {t}: no such target" for t in rest if not t.startswith("-") and "=" not in t and t not in targets
        ]
    if prog in ("pip", "pip3"):
        return [] if rest[:1] == ["install"] else [f"pip {' '.join(rest)}: not an install"]
    if prog == "cp":  # what it copies is there (the top-level scenarios link pointed nowhere: issue 28)
        return [f"cp: {s} does not exist" for s in rest[:-1] if not s.startswith("-") and not _exists(s, made)]
    if prog in TOOLS or (venv_bin / prog).exists():
        return []
    return [f"{prog}: not a program the docs' set-up provides"]


def _ids(bs: list[Block]) -> list[str]:
    return [b.where for b in bs]


ALL = blocks()


def test_the_docs_have_shell_blocks_and_the_convention_is_stated():
    assert len(ALL) >= 15, _ids(ALL)
    assert sum(len(b.commands) for b in ALL) >= 40
    index = (DOCS / "index.md").read_text()
    assert NOT_RUN in index and "tests/test_docs_commands.py" in index  # the convention, said where a reader starts
    for b in ALL:
        if not b.runnable:
            reason = b.title.removeprefix(NOT_RUN).strip(" :")
            assert reason, f"{b.where}: a block marked not runnable says why"


def test_the_top_level_links_lead_somewhere():
    """``scenarios/`` and ``models/`` at the top (README's layout, the scenarios page's ``cp scenarios/paper.toml``)
    are links into the package: they resolve to the shipped presets and robots."""
    from bioform_mj.robots.refs import robot_names
    from bioform_mj.scenario.loader import preset_names

    assert {p.stem for p in (ROOT / "scenarios").glob("*.toml")} == set(preset_names())
    assert (ROOT / "scenarios" / "paper.toml").is_file() and "tb3" in robot_names()
    assert any((ROOT / "models").glob("*.xml"))


def test_command_blocks_carry_a_shell_language():
    """A fence holding ``bioform ...`` lines without a language would escape this test: label it."""
    bad = []
    for page in PAGES:
        lines = page.read_text().splitlines()
        i = 0
        while i < len(lines):
            m = re.match(r"^\s*```(\S*)", lines[i])
            if not m:
                i += 1
                continue
            j = i + 1
            while j < len(lines) and lines[j].strip() != "```":
                j += 1
            if not m.group(1) and any(re.match(r"^\s*(\$ )?(\.venv/bin/)?bioform ", ln) for ln in lines[i + 1 : j]):
                bad.append(f"{page.relative_to(ROOT)}:{i + 1}")
            i = j + 1
    assert not bad, f"fences holding commands without bash/sh/console: {bad}"


@pytest.mark.parametrize("block", ALL, ids=_ids(ALL))
def test_every_command_names_what_exists(block):
    """The program exists; ``bioform`` invocations parse and name presets, robots and files that exist."""
    made = _made_by_block(block)
    env = _assignments(block)
    bad = []
    for c in block.commands:
        for words in _simple_commands(c.text):
            bad += [f"line {c.line}: {c.text.splitlines()[0]!r}: {p}" for p in _check_command(words, block, made, env)]
        if block.runnable and re.search(r"\[--|\|cpu\]|<[A-Z]+>|\bROBOT\b|\bBAG\b", c.text.split("\n", 1)[0]):
            bad.append(f"line {c.line}: a placeholder in a block marked runnable: {c.text.splitlines()[0]!r}")
    assert not bad, "\n".join(bad)


def test_bare_bioform_and_python_are_preceded_by_the_venv_line():
    """The docs write bare ``bioform``/``python``: the README's quick start and the getting-started page say once
    to activate .venv (issue 28: the tutorial's own command failed with "No module named 'bioform_mj'")."""
    for page in (ROOT / "README.md", DOCS / "guide" / "getting-started.md", DOCS / "index.md"):
        assert "source .venv/bin/activate" in page.read_text(), page.name


# ---------------------------------------------------------------------------------------------------- the slow run


def _clone(dst: Path) -> None:
    """A fresh clone's files (the tracked and untracked-not-ignored ones) and a ``.venv`` that is this
    interpreter's environment, set up (make's stamps present)."""
    files = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT, capture_output=True, check=True
    ).stdout.split(b"\0")
    for f in filter(None, files):
        src = ROOT / f.decode()
        if src.is_symlink():  # as git checks a link out: a link (scenarios/, models/ at the top)
            (dst / f.decode()).parent.mkdir(parents=True, exist_ok=True)
            (dst / f.decode()).symlink_to(os.readlink(src))
        elif src.is_file():
            (dst / f.decode()).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dst / f.decode())
    venv = dst / ".venv"
    venv.mkdir()
    for entry in ("bin", "lib", "include", "pyvenv.cfg"):
        if (Path(sys.prefix) / entry).exists():
            (venv / entry).symlink_to(Path(sys.prefix) / entry)
    for stamp in (".installed", ".installed-test"):  # make's set-up done: make demo does not reinstall
        (venv / stamp).touch()


def _run_block(block: Block, cwd: Path, env: dict[str, str], done: set[str] | None = None) -> list[str]:
    """Run one block as written in ``cwd``; problems, each naming the command's line. ``done``: the commands
    already run in this copy (an identical command is not run twice; this block's are added)."""
    done = set() if done is None else done
    if block.lang == "console":
        problems = []
        for c in block.commands:
            if _same(c.text) in done:
                continue
            done.add(_same(c.text))
            t0 = time.monotonic()
            out = subprocess.run(
                ["bash", "-c", c.text], cwd=cwd, env=env, capture_output=True, text=True, timeout=PER_COMMAND_S
            )
            want_error = bool(c.shown) and c.shown[0].startswith("error:")
            took = f"{time.monotonic() - t0:.0f} s"
            if want_error and (out.returncode != 2 or "error:" not in out.stderr):
                problems.append(f"line {c.line}: expected exit 2 with an error: line, got {out.returncode} ({took})")
            if not want_error and out.returncode != 0:
                tail = out.stderr.strip().splitlines()[-1:] or [""]
                problems.append(f"line {c.line}: exit {out.returncode} ({took}): {tail[0]}")
        return problems
    r, w = os.pipe()  # the traps report each command's start and each failure on fd w (kept in the child)
    script = ["set -a", f"trap 'echo \"__line $LINENO\" >&{w}' DEBUG", f"trap 'echo \"__fail $LINENO $?\" >&{w}' ERR"]
    lines_of_script = {}
    for c in block.commands:
        if c.text.split("\n", 1)[0].strip() in NEVER_RUN or re.match(r"^make test\b", c.text) or _same(c.text) in done:
            continue
        done.add(_same(c.text))
        lines_of_script[len(script) + 1] = c
        script.append(c.text)
    proc = subprocess.Popen(
        ["bash", "-c", "\n".join(script) + "\n", "docs-block"],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        pass_fds=(w,),
        text=True,
        start_new_session=True,
    )
    os.close(w)
    state = {"line": 0, "since": time.monotonic(), "fails": [], "starts": {}}

    def watch():
        with os.fdopen(r) as fh:
            for msg in fh:
                kind, *rest = msg.split()
                if kind == "__line" and int(rest[0]) != state["line"]:
                    state["line"], state["since"] = int(rest[0]), time.monotonic()
                    state["starts"].setdefault(int(rest[0]), time.monotonic())
                elif kind == "__fail":
                    state["fails"].append((int(rest[0]), int(rest[1]), time.monotonic()))

    th = threading.Thread(target=watch, daemon=True)
    th.start()
    chunks: list[str] = []
    reader = threading.Thread(target=lambda: chunks.append(proc.stdout.read()), daemon=True)
    reader.start()
    problems = []
    while proc.poll() is None:
        if time.monotonic() - state["since"] > PER_COMMAND_S:
            os.killpg(proc.pid, 9)
            c = _at(lines_of_script, state["line"])
            problems.append(f"line {c.line if c else '?'}: still running after {PER_COMMAND_S:.0f} s: killed")
            break
        time.sleep(0.5)
    proc.wait()
    reader.join(10)
    th.join(10)
    output = "".join(chunks)
    for line, rc, _t in state["fails"]:
        c = _at(lines_of_script, line)
        where = f"line {c.line}: {c.text.splitlines()[0]!r}" if c else f"script line {line}"
        problems.append(f"{where}: exit {rc}; {_error_lines(output)}")
    return problems


def _same(text: str) -> str:
    """A command as the shell runs it: comments and ``.venv/bin/`` left out (README's ``.venv/bin/bioform run paper
    --plant ideal`` and the getting-started page's ``bioform run paper --plant ideal`` are one command)."""
    try:
        return " ".join(w.removeprefix(".venv/bin/") for w in shlex.split(text.split("\n", 1)[0], comments=True))
    except ValueError:
        return text


def _at(lines_of_script: dict[int, Command], line: int) -> Command | None:
    """The command of the script that holds script line ``line`` (a heredoc spans several)."""
    starts = [s for s in sorted(lines_of_script) if s <= line]
    return lines_of_script[starts[-1]] if starts else None


def _error_lines(output: str) -> str:
    errs = [ln for ln in output.splitlines() if ln.startswith(("error:", "Traceback", "bash:", "make:"))]
    return "; ".join(errs[-3:]) or output.strip().splitlines()[-1:][0] if output.strip() else "no output"


RUN_PAGES = sorted({b.page for b in ALL if b.runnable})


def _reading_order() -> list[Path]:
    """README, then the site's pages in mkdocs.yml's nav order: the path a newcomer reads."""
    nav = re.findall(r":\s*([\w/.-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), flags=re.M)
    return [ROOT / "README.md", *(DOCS / n for n in nav if (DOCS / n).exists())]


def _clone_env(clone: Path) -> dict[str, str]:
    """The environment of a shell in ``clone`` with its ``.venv`` activated."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST", "BIOFORM_"))}
    env.update(
        PATH=f"{clone / '.venv' / 'bin'}{os.pathsep}{os.environ.get('PATH', '')}",
        VIRTUAL_ENV=str(clone / ".venv"),
        PYTHONPATH=str(clone / "src"),  # this checkout's code, whatever the environment's editable install points at
    )
    return env


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("BIOFORM_DOCS_COMMANDS") != "1",
    reason="runs every docs command, for many minutes: BIOFORM_DOCS_COMMANDS=1 (make docs-commands)",
)
@pytest.mark.parametrize("page", RUN_PAGES, ids=[str(p.relative_to(ROOT)) for p in RUN_PAGES])
def test_docs_commands_run_as_written(page, tmp_path_factory):
    """Every runnable block of ``page``, in order, run as written in a fresh copy of the repository, exits 0 (a
    console block: as shown). One copy per page: a reader follows one page from a fresh clone. Each page's copy
    is made at the same path, after the last one is removed: numba keys its cache by the source's folder, so
    the loop compiles once for all pages (minutes each otherwise), as it would for one user's clone."""
    clone = tmp_path_factory.getbasetemp() / "clone"
    if clone.exists():
        shutil.rmtree(clone)
    clone.mkdir()
    _clone(clone)
    env = _clone_env(clone)
    failed = []
    for b in ALL:
        if b.page == page and b.runnable:
            t0 = time.monotonic()
            problems = _run_block(b, clone, env)
            print(f"{b.where}: {len(b.commands)} commands, {time.monotonic() - t0:.0f} s, {len(problems)} problems")
            failed += [f"{b.where} {p}" for p in problems]
    assert not failed, "\n".join(failed)


def test_the_fast_check_finds_each_kind_of_broken_command(tmp_path):
    """A page of broken commands: each is reported, naming its line; the one good command is not."""
    page = tmp_path / "broken.md"
    page.write_text(
        "```bash\n"
        "bioform run paper --duration 1 --out runs/ok\n"  # good: line 2
        "bioform run paper --no-such-flag\n"
        "bioform run no-such-preset\n"
        "bioform robot check no/such/robot.xml\n"
        "bioform run paper --set no.such_key=1\n"
        "make no-such-target\n"
        "python no/such/script.py\n"
        "no-such-program --help\n"
        "bioform sweep paper --backend warp [--device cuda|cpu] --out runs/x\n"
        "```\n"
        "```console\n$ bioform run paper --set 'sim.duration=-1'\nerror: ...\n```\n"
    )
    (bash, console) = blocks([page])
    assert [c.line for c in bash.commands] == list(range(2, 11)) and console.commands[0].shown == ["error: ..."]
    made, env = _made_by_block(bash), _assignments(bash)
    found = {c.line: _check_command(_simple_commands(c.text)[0], bash, made, env) for c in bash.commands}
    assert found[2] == []
    assert "does not parse" in found[3][0] and "--no-such-flag" in found[3][0]
    assert "neither a preset nor a file" in found[4][0]
    assert "neither a shipped robot nor a file" in found[5][0]
    assert "does not load" in found[6][0] and "no.such_key" in found[6][0]
    assert found[7] == ["make no-such-target: no such target"]
    assert found[8] == ["python no/such/script.py: no such script"]
    assert "not a program" in found[9][0]
    assert found[10]  # the [--device cuda|cpu] placeholder does not parse
    assert "does not load" in _check_command(_simple_commands(console.commands[0].text)[0], console, [], {})[0]


@pytest.mark.slow
@pytest.mark.skipif(
    os.environ.get("BIOFORM_DOCS_COMMANDS") != "1",
    reason="runs every docs command, for many minutes: BIOFORM_DOCS_COMMANDS=1 (make docs-commands)",
)
def test_docs_commands_run_in_one_clone_in_reading_order(tmp_path):
    """The newcomer's whole path: README, then every page in the nav's order, in ONE copy of the repository (an
    identical command is run once). A command that fails here and not on its own page collides with an earlier
    page's outputs (issue 28: a default output folder that ignores --set)."""
    clone = tmp_path / "clone"
    clone.mkdir()
    _clone(clone)
    env = _clone_env(clone)
    failed, done = [], set()
    for page in _reading_order():
        for b in ALL:
            if b.page == page and b.runnable:
                failed += [f"{b.where} {p}" for p in _run_block(b, clone, env, done)]
    assert not failed, "\n".join(failed)


def test_the_runner_reports_a_failing_command_its_line_and_a_hung_one(tmp_path, monkeypatch):
    """The slow test's runner: a failing command is reported with its page line and exit status, the commands
    after it still run, a variable set earlier reaches a later command, a command past the per-command limit is
    killed, and a console command is held to what its block shows (an error: line, exit 2)."""
    page = tmp_path / "p.md"
    page.write_text(
        "```bash\n"
        "X=7\n"  # line 2
        'test "$X" = 7 && echo ok > first.txt\n'
        "sh -c 'exit 3'   # fails\n"  # line 4
        "echo after > second.txt\n"
        "```\n"
        "```bash\nsleep 5\n```\n"
        "```console\n$ sh -c 'echo \"error: bad\" >&2; exit 2'\nerror: bad\n$ sh -c 'exit 0'\nerror: shown\n```\n"
    )
    bash, hung, console = blocks([page])
    env = dict(os.environ)
    problems = _run_block(bash, tmp_path, env)
    assert len(problems) == 1 and problems[0].startswith("line 4: \"sh -c 'exit 3'") and "exit 3" in problems[0]
    assert (tmp_path / "first.txt").read_text() == "ok\n" and (tmp_path / "second.txt").exists()
    monkeypatch.setattr(sys.modules[__name__], "PER_COMMAND_S", 1.0)
    t0 = time.monotonic()
    (killed,) = _run_block(hung, tmp_path, env)
    assert "still running after 1 s: killed" in killed and time.monotonic() - t0 < 4.5
    (shown,) = _run_block(console, tmp_path, env)  # the first is as shown; the second should have failed
    assert shown.startswith(f"line {console.commands[1].line}: expected exit 2")


def test_the_cli_resolves_auto_scale_in_a_fresh_process():
    """The robots page's ``bioform run tb3 --set 'formation.scale="auto"'`` exited 2 ("import bioform_mj.run
    first"): the CLI loaded the scenario without the run package that registers the resolver. In a fresh process
    (this one has imported it), the CLI's own loading resolves it: tb3's half track / the paper robot's 0.2 m."""
    code = (
        "from bioform_mj.cli import main as m\n"
        "a = m.build_parser().parse_args(['run', 'tb3', '--set', 'formation.scale=\"auto\"'])\n"
        "print(m._load(a).formation.scale)"
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    from bioform_mj.robots.entries import resolve_robot
    from bioform_mj.robots.params import robot_truth

    s = float(out.stdout.strip().splitlines()[-1])
    assert s == pytest.approx(robot_truth(resolve_robot("tb3")).half_track / 0.2, rel=1e-6)
