"""``scripts/envs_identical.py`` compares the trees it is given, not the installed package with itself: a tree with
no ``bioform_mj`` is refused before any work (one ``error:`` line, exit 2), and a recording whose import did not come
from its tree (an empty ``bioform_mj`` folder: a namespace portion, which an installed regular package beats) is a
failure (exit 1). Both had printed "identical" and exited 0, comparing the installed package with itself."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "scripts" / "envs_identical.py"


def _run(*trees: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, str(SCRIPT), *trees, "--only", "parallel_ideal", "--steps", "3"]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=300)


def test_a_tree_without_the_package_is_refused_before_any_work(tmp_path):
    p = _run(str(ROOT), str(tmp_path / "absent"))
    assert p.returncode == 2 and p.stdout == ""
    assert p.stderr.startswith("error: ") and "no bioform_mj package" in p.stderr and p.stderr.count("\n") == 1


def test_a_recording_that_imported_another_copy_fails_and_the_tree_itself_is_identical(tmp_path):
    fake = tmp_path / "fake"
    (fake / "src" / "bioform_mj").mkdir(parents=True)  # no __init__.py: the installed package is imported instead
    p = _run(str(ROOT), str(fake))
    assert p.returncode == 1 and "identical" not in p.stdout
    # the installed package imported instead (or, where none is installed, the recording failed to import)
    assert "imported bioform_mj from" in p.stderr or "recording under" in p.stderr, p.stderr
    p = _run(str(ROOT), str(ROOT))
    assert p.returncode == 0 and p.stdout.startswith("parallel_ideal: identical"), p.stderr
