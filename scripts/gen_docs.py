"""Generate the reference pages of the documentation from the code's own sources.

Run by the ``gen-files`` plugin of ``mkdocs build`` (``mkdocs.yml``), so the pages never go stale:

- ``reference/scenario.md`` from the scenario dataclasses (``scenario/config.py``) and their descriptions
  (``scenario_doc.KEYS``, ``scenario_doc.CHOICES``);
- ``reference/cli.md`` from the ``bioform`` argparse parser (``cli.build_parser``).

``python scripts/gen_docs.py OUTDIR`` writes the same two pages into OUTDIR (to read them without a build).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from bioform_mj.cli.main import build_parser
from bioform_mj.core.engine import CHANNELS, MEAN_CHANNELS
from bioform_mj.run import logtable
from bioform_mj.scenario import doc as scenario_doc


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _prose(text: str) -> str:
    """A help text as a table cell: also no raw ``<...>`` (Markdown would read it as HTML)."""
    return _cell(text).replace("<", "&lt;").replace(">", "&gt;")


def scenario_reference() -> str:
    """The scenario reference as Markdown: one table per section, one row per key."""
    rows = scenario_doc.reference_rows()
    out = [
        "# Scenario reference",
        "",
        "Every key a scenario file (TOML) or `--set KEY=VALUE` accepts, generated from the scenario dataclasses "
        "(`bioform_mj/scenario/config.py`) and their descriptions (`bioform_mj/scenario/doc.py`). "
        "Unknown keys are refused. The defaults are the paper scenario (`scenarios/paper.toml` restates them). "
        "Follower ids are 1-based. "
        '"× scale": multiplied by `formation.scale` when the scenario is loaded '
        "(see [Scenarios](../guide/scenarios.md)).",
        "",
        "`plant.robots` is an array with one entry for all followers or one per follower; each entry is a shipped "
        "robot name, an MJCF path (relative to the TOML file) or a table with the keys `plant.robots[].…` below "
        '(default `["paper"]`). `events` is an array of tables (`[[events]]`), default empty.',
        "",
    ]
    section = None
    for r in rows:
        head = r["key"].split(".")[0] if "." in r["key"] else "top level"
        if head != section:
            section = head
            out += ["", f"## `{head}`" if head != "top level" else "## Top level", ""]
            out += ["| key | type | unit | default | allowed | description |", "|---|---|---|---|---|---|"]
        out.append(
            "| `{key}` | {type} | {unit} | `{default}` | {choices} | {description} |".format(
                **{k: _cell(v) for k, v in r.items()}
            )
        )
    return "\n".join(out) + "\n"


def _subcommands(parser: argparse.ArgumentParser, prefix: str) -> list[tuple[str, str, argparse.ArgumentParser]]:
    """``(full command, help, parser)`` for every (nested) subcommand, in definition order."""
    out = []
    for action in parser._actions:  # argparse keeps subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            for name, sub in action.choices.items():
                out.append((f"{prefix} {name}", helps.get(name, ""), sub))
                out += _subcommands(sub, f"{prefix} {name}")
    return out


def _arg_row(a: argparse.Action) -> str | None:
    if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
        return None
    name = ", ".join(f"`{o}`" for o in a.option_strings) or f"`{a.metavar or a.dest}`"
    if a.option_strings and a.nargs != 0:
        name += f" `{a.metavar or a.dest.upper()}`"
    choices = ", ".join(f"`{c}`" for c in a.choices) if a.choices else ""
    default = "" if a.default in (None, False, [], argparse.SUPPRESS) or a.nargs == 0 else f"`{a.default}`"
    req = " (required)" if a.required and a.option_strings else ""
    return f"| {name}{req} | {_prose(a.help or '')} | {choices} | {default} |"


def cli_reference() -> str:
    """The ``bioform`` command reference as Markdown, from the argparse parser."""
    parser = build_parser()
    out = [
        "# Command-line reference",
        "",
        "Generated from the `bioform` argparse parser (`bioform_mj/cli/main.py`). Exit codes: 0 done; 2 bad input "
        "(one `error:` line on stderr, before any work); 3 the simulation diverged (log kept); 4 `robot check` "
        "verdict `fail`; 130/143 interrupted (SIGINT/SIGTERM, log so far kept); 1 anything else.",
        "",
    ]
    for cmd, help_text, sub in _subcommands(parser, "bioform"):
        rows = [r for r in (_arg_row(a) for a in sub._actions) if r]
        nested = any(isinstance(a, argparse._SubParsersAction) for a in sub._actions)
        out += [f"## `{cmd}`", "", _prose(help_text), ""]
        sub.formatter_class = lambda prog: argparse.HelpFormatter(prog, width=100)  # not the terminal's width
        out += ["```text", sub.format_usage().strip().replace("usage: ", ""), "```", ""]
        if rows and not nested:
            out += ["| argument | meaning | choices | default |", "|---|---|---|---|", *rows, ""]
    return "\n".join(out) + "\n"


def log_reference() -> str:
    """The log channels (``log.npz``, ``RunResult.log``) and their tidy-table columns, from ``engine.CHANNELS``."""
    out = [
        "# Log channels",
        "",
        "Generated from `bioform_mj.core.engine.CHANNELS` and `bioform_mj.run.logtable.COMPONENTS`. `log.npz` and "
        "`RunResult.log` hold one array per channel, `K` rows (one every `sim.log_dt`, the first at t = 0); "
        "`n` is the number of followers, follower `i` at index `i − 1`. States are point samples at the row's "
        f"time; {', '.join(f'`{c}`' for c in MEAN_CHANNELS)} are means over the row's interval `(t_(j−1), t_j]`, "
        "with `_min`/`_max` beside some. `RunResult.table()` has one row per sample and follower, "
        "`t_s` and `follower` first, then the columns below (the leader's repeated on each follower's row).",
        "",
        "| channel | shape | what | table columns |",
        "|---|---|---|---|",
    ]
    for ch, (shape, doc) in CHANNELS.items():
        dims = ", ".join(("K", *shape))
        if ch == "t":
            cols = "`t_s`"
        else:
            cols = ", ".join(f"`{logtable.column_name(ch, c, u)}`" for c, u in logtable.COMPONENTS[ch])
        out.append(f"| `{ch}` | ({dims}) | {_prose(doc)} | {cols} |")
    from bioform_mj.outputs.fullstate import STATE_CHANNELS, STATE_STATICS

    out += [
        "",
        "## The 3-D state",
        "",
        "With `bioform run --rosbag` or `simulate(sc, full_state=True)` the log also holds the state a ROS 2 bag "
        "needs ([ROS 2 bags](../guide/rosbag.md)), sampled at every row and once more at the end of the run "
        "(`K + 1` rows; generated from `bioform_mj.outputs.fullstate.STATE_CHANNELS`). Not in the tidy table.",
        "",
        "| array | shape | what |",
        "|---|---|---|",
    ]
    for ch, (shape, doc) in STATE_CHANNELS.items():
        out.append(f"| `{ch}` | ({', '.join(('K + 1', *shape))}) | {_prose(doc)} |")
    for ch, (shape, doc) in STATE_STATICS.items():
        out.append(f"| `{ch}` | ({', '.join(shape)}) | {_prose(doc)} |")
    return "\n".join(out) + "\n"


PAGES = {
    "reference/scenario.md": scenario_reference,
    "reference/cli.md": cli_reference,
    "reference/log.md": log_reference,
}


def _build_with_gen_files() -> None:
    import mkdocs_gen_files

    for path, fn in PAGES.items():
        with mkdocs_gen_files.open(path, "w") as fh:
            fh.write(fn())


if __name__ == "<run_path>":  # run by mkdocs-gen-files during `mkdocs build`
    _build_with_gen_files()
elif __name__ == "__main__":
    dest = Path(sys.argv[1] if len(sys.argv) > 1 else "site-src")
    for path, fn in PAGES.items():
        (dest / path).parent.mkdir(parents=True, exist_ok=True)
        (dest / path).write_text(fn(), encoding="utf-8")
        print(dest / path)
