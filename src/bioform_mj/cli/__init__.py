"""The ``bioform`` command (design §10): the only package that prints."""
