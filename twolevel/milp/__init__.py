"""The solver-neutral layer: mixed-integer models in arrays, the solvers, the mode search.

* ``model.py`` — :class:`MilpModel` (rows, bounds, costs, disjunctions) and CSC patterns
* ``builder.py`` — :class:`ModelBuilder`: a model from named blocks of whole arrays
* ``solution.py`` — :class:`Status`, :class:`Solution` and the :class:`Capabilities` every
  backend declares
* ``highs.py`` — HiGHS: MILP/LP, MIP start, time limit, export to ``.mps``/``.lp``
* ``clarabel.py`` — Clarabel: the convex QP of one mode (integer columns fixed), updated in place
* ``gurobi.py`` — Gurobi (optional): the MIQP as it is
* ``l1_surrogate.py`` — the L1 surrogate of a least-squares cost (the exact path's MILP)
* ``modes.py`` — the real-time disjunctive mode search over one Clarabel QP

Nothing here knows about formulas: :mod:`twolevel.compiler` writes rules into these models.
This module imports nothing.
"""
