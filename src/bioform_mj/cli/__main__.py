"""``python -m bioform_mj.cli``: the ``bioform`` command."""

from bioform_mj.cli.main import entry

entry()
