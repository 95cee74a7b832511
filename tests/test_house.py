"""The house (design §0): the package's floors, no import cycle (imports inside functions count too), no module over
~800 lines, no import of another package's private names, no name-prefix families at the top level."""

from __future__ import annotations

import ast
from pathlib import Path

PKG = Path(__file__).resolve().parent.parent / "src" / "bioform_mj"

#: cycles allowed (none; the list may only shrink)
KNOWN_CYCLES: set[frozenset[str]] = set()
#: modules over the limit before this test existed (remove an entry when the file is split)
KNOWN_LONG: set[str] = set()
MAX_LINES = 800

#: the package's floors (design §0): a subpackage imports only from a lower floor or from itself; lazy imports
#: inside functions count too. Two packages on one floor know nothing of each other.
FLOORS: dict[str, int] = {
    "core": 0,
    "formation": 1,
    "control": 2,
    "robots": 2,
    "scenario": 3,
    "plants": 3,
    "outputs": 3,
    "assess": 4,
    "run": 5,
    "batch": 6,
    "envs": 7,
    "jobs": 7,
    "cli": 8,
}
#: the only modules at the package's top level: the lazy public API and the version
TOP_LEVEL = {"__init__.py", "_version.py"}
#: imports that go up or sideways, by (importing module, imported module); the list may only shrink. Empty: where a
#: lower floor needs what a higher one computes, the higher one registers it (design §0)
KNOWN_UPWARD: set[tuple[str, str]] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for p in PKG.rglob("*.py"):
        parts = p.relative_to(PKG.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = p
    return out


def _import_nodes(mods: dict[str, Path]):
    """``(module, imported target, imported names)`` for every import statement of the package, lazy ones too."""
    for m, p in mods.items():
        pkg = m if p.name == "__init__.py" else m.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = pkg.split(".")[: len(pkg.split(".")) - (node.level - 1)] if node.level else []
                target = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module
                yield m, target, [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                for a in node.names:
                    yield m, a.name, []


def _imports(mods: dict[str, Path]) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, target, names in _import_nodes(mods):
        cands = [target, *(f"{target}.{a}" for a in names)]
        edges[m] |= {c for c in cands if c in mods and c not in (m, "bioform_mj")}
    return edges


def _package(module: str) -> str | None:
    """The subpackage a module belongs to (``bioform_mj.run.loop`` -> ``run``); None at the top level."""
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and parts[1] in FLOORS) else None


def _upward(mods: dict[str, Path]) -> set[tuple[str, str]]:
    out = set()
    for m, target, _ in _import_nodes(mods):
        a, b = _package(m), _package(target or "")
        if a in FLOORS and b in FLOORS and a != b and FLOORS[b] >= FLOORS[a]:
            out.add((m, target))
    return out


def _cycles(edges: dict[str, set[str]]) -> list[frozenset[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[frozenset[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(frozenset(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [frozenset("abc")]


def test_no_new_import_cycle():
    mods = _modules()
    assert "bioform_mj.batch.runner" in mods and len(mods) > 40
    cycles = set(_cycles(_imports(mods)))
    assert cycles <= KNOWN_CYCLES, sorted(map(sorted, cycles - KNOWN_CYCLES))


def test_no_new_module_over_800_lines():
    long = {p.relative_to(PKG).as_posix(): len(p.read_text().splitlines()) for p in PKG.rglob("*.py")}
    over = {k: v for k, v in long.items() if v > MAX_LINES and k not in KNOWN_LONG}
    assert not over, over


def test_the_floor_check_finds_an_upward_import(tmp_path):
    (tmp_path / "bioform_mj" / "core").mkdir(parents=True)
    (tmp_path / "bioform_mj" / "cli").mkdir()
    (tmp_path / "bioform_mj" / "core" / "x.py").write_text("def f():\n    from bioform_mj.cli.main import main\n")
    (tmp_path / "bioform_mj" / "cli" / "main.py").write_text("from ..core.x import f\n")
    mods = {
        "bioform_mj.core.x": tmp_path / "bioform_mj/core/x.py",
        "bioform_mj.cli.main": tmp_path / "bioform_mj/cli/main.py",
    }
    assert _upward(mods) == {("bioform_mj.core.x", "bioform_mj.cli.main")}


def test_every_import_goes_down_the_floors():
    mods = _modules()
    packages = {p.name for p in PKG.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    assert packages == set(FLOORS), packages ^ set(FLOORS)
    up = _upward(mods)
    assert up <= KNOWN_UPWARD, sorted(up - KNOWN_UPWARD)


def test_the_top_level_holds_the_public_api_only():
    top = {p.name for p in PKG.glob("*.py")}
    assert top == TOP_LEVEL, top ^ TOP_LEVEL
    assert not [p.name for p in PKG.iterdir() if p.is_dir() and p.name not in FLOORS and p.name != "__pycache__"]


def test_no_import_of_another_packages_private_names():
    bad = []
    for m, target, names in _import_nodes(_modules()):
        if not (target or "").startswith("bioform_mj.") or _package(target) in (None, _package(m)):
            continue
        bad += [f"{m} imports {target}.{n}" for n in names if n.startswith("_") and not n.startswith("__")]
    assert not bad, bad
