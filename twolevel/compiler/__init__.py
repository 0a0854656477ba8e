"""The STL → MILC compiler: rules over an MPC horizon → mixed-integer linear constraints.

Entry point: :func:`twolevel.compiler.driver.encode` (requirements, signals, a
:class:`~twolevel.milp.builder.ModelBuilder` → rows, binaries and disjunctions in the builder).
The stages and what they exchange:

* ``signals.py`` — signals with two faces (known constant or affine in the decision
  variables) and the table of one trace (:class:`TraceSignals`)
* ``evaluator.py`` — stage 1: a formula at one trace step → its robustness tree
* ``tree.py`` — the robustness tree, the intermediate representation (its invariants,
  producers and consumers are documented there), its vectorised leaves (the block protocol),
  interval bounds, sharing
* ``sink.py`` — the row sink a block emits into (implemented by stage 2)
* ``affine_block.py`` — ``always`` over linear predicates as one block
* ``collision.py`` — the ``collision_free(d)`` built-in and its block; reachable boxes
* ``emitter.py`` — stage 2: a tree required above a margin → rows, big-M from bounds,
  disjunctions
* ``driver.py`` — :func:`encode`: both stages over every requirement, rule recovery
* ``types.py`` — requirements, the encoding's result, pending disjunctions, built-ins
* ``codes.py`` — diagnostic codes ``MIL501``–``MIL504`` and the error that carries them

The compiler writes into the solver-neutral model of :mod:`twolevel.milp` and never imports a
solver. This module imports nothing, so that importing :mod:`twolevel.compiler.codes` stays light.
"""
