"""The encoder object: one trace's signals, builder and memo tables (design in :mod:`twolevel.compiler.driver`).

Evaluation (:mod:`twolevel.compiler.evaluator`) and emission (:mod:`twolevel.compiler.emitter`) are mixins
over the state set up here.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from twolevel.diagnostics import Diagnostic
from twolevel.milp.builder import ModelBuilder
from twolevel.compiler.emitter import RowEmitter
from twolevel.compiler.types import AffineSignal, Builtin, Emission, Signal
from twolevel.compiler.evaluator import TreeEvaluator
from twolevel.compiler.tree import Tree
from twolevel.stl import ast

__all__ = ["Encoder"]


class Encoder(TreeEvaluator, RowEmitter):
    """Evaluates formulas into robustness trees and requires them in a :class:`ModelBuilder`."""

    def __init__(
        self, builder: ModelBuilder, signals: Mapping[str, Signal], dt: float, *,
        consts: Mapping[str, float] | None = None,
        rules: Mapping[str, ast.Node] | None = None,
        builtins: Mapping[str, Builtin] | None = None,
        length: int | None = None,
        stable: bool = False,
    ) -> None:
        self.b = builder
        # stable: vectorised blocks keep redundant rows, faces and pairs so that a model's
        # structure depends only on the formulas and the kept vehicle–step pairs (see Emission)
        self.stable = stable
        self.emissions: list[Emission] = []
        self.signals = signals
        self.dt = dt
        self.consts = dict(consts or {})
        self.rules = dict(rules or {})
        self.builtins = dict(builtins or {})
        if length is None:
            lens = [len(s) for s in signals.values()
                    if isinstance(s, AffineSignal) or np.ndim(s) > 0]
            if not lens:
                raise ValueError("give the trace length: no signal has one")
            length = max(lens)
        self.T = int(length)
        self._rob: dict[tuple[int, int, float], Tree] = {}
        self._sig: dict[tuple[str, int], Tree] = {}
        self._dense: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self._bnd: dict[int, tuple[float, float, object]] = {}
        self._refs: dict[int, int] = {}
        self._shared: dict[int, Tree] = {}
        self._keep: list[object] = []
        # emitted rows, concatenated once in :meth:`flush`
        self._r: list[np.ndarray] = []
        self._c: list[np.ndarray] = []
        self._v: list[np.ndarray] = []
        self._lo: list[float] = []
        self._n = 0
        self._row0 = builder.n_rows
        self._disj: list[dict] = []
        self._rows_of_guard: dict[int, list[int]] = {}
        self.infeasible = False
        self.diagnostics: list[Diagnostic] = []
        self.n_bin = 0
        self.n_cont = 0
        self._label = ""

