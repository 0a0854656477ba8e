"""The handful of elementwise operations the vehicle models are written in, for numpy and casadi.

Model code takes an ``xp`` namespace so the same equations run vectorised on numpy arrays
(:data:`NP`) and symbolically on casadi SX for compiled rollouts (:func:`casadi_ops`).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

__all__ = ["NP", "casadi_ops"]

NP = SimpleNamespace(
    sin=np.sin, cos=np.cos, tan=np.tan, atan=np.arctan, tanh=np.tanh, sqrt=np.sqrt,
    fmax=np.maximum, fmin=np.minimum, fabs=np.abs, sign=np.sign, where=np.where,
)
"""numpy's versions."""


def casadi_ops() -> SimpleNamespace:
    """casadi's versions (imported lazily: casadi is heavy)."""
    import casadi as ca

    return SimpleNamespace(
        sin=ca.sin, cos=ca.cos, tan=ca.tan, atan=ca.atan, tanh=ca.tanh, sqrt=ca.sqrt,
        fmax=ca.fmax, fmin=ca.fmin, fabs=ca.fabs, sign=ca.sign, where=ca.if_else,
    )
