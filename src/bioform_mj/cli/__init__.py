"""The ``bioform`` command (design §10): the only package that prints."""

import warnings as _warnings

from bioform_mj.core.errors import CacheWarning as _CacheWarning

# the kernels' cache folder that could not be written: said once as a warning: line by the command (main.py),
# not as Python's two-line warning while the package is imported
_warnings.filterwarnings("ignore", category=_CacheWarning)
