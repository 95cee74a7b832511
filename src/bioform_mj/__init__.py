"""bioform_mj: distributed leader-follower formation control (Xu et al., IEEE T-IV 2024)
on an ideal unicycle plant and on MuJoCo differential-drive robots."""

from __future__ import annotations

__version__ = "0.1.0"
