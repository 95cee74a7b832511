"""The opt-in gain sizing (design §14.4) reaches the controller's builder by registration, not by an upward import
(design §0): the control package alone imports nothing of ``assess``, refuses the opt-in naming what to import, and
the run package registers ``assess.learner_sizing.sizing``."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import sys, types
import numpy as np
from bioform_mj.control import params
assert not any(m.startswith("bioform_mj.assess") for m in sys.modules), sorted(m for m in sys.modules if "assess" in m)
ns = types.SimpleNamespace
sc = ns(method="bioinspired-learning", n=1, torque=ns(resistance_margin=5.0), learner=ns(kd_deadband=(),
        c_hat0_scale=(1.0, 1.0), c_bounds=(0.1, 10.0)))
try:
    params.stack_params(sc, np.array([[0.4, 10.0]]))
except ValueError as exc:
    print("refused:", exc)
import bioform_mj.run
from bioform_mj.assess.learner_sizing import sizing
print("registered:", params._SIZING == [sizing])
"""


def test_sizing_is_registered_by_the_run_package():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0].startswith("refused: torque.resistance_margin / learner.kd_deadband are sized to robot check's")
    assert "import bioform_mj.run" in lines[0]
    assert lines[1] == "registered: True"
