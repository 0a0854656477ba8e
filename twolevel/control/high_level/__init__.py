"""The high level: the paper's MPC, whose traffic rules are mixed-integer linear constraints.

``controller`` (:class:`~twolevel.control.high_level.controller.HighLevelController`, one step
end to end), ``settings``, ``rules`` (which rules it enforces), ``reference`` (waypoints),
``linearisation`` (step data over the look-ahead: linearisation point, bounds), ``guards``
(drivable band, terminal stop, RSS's distance to the vehicle ahead or a pass), ``problem``
(model assembly), ``template`` (in-place refresh of a cached model),
``backend`` (solver objects kept across steps), ``solvers`` (the solve paths: modes, highs,
gurobi), ``robustness`` (the plan's rule robustness), ``fallback``. Import from the modules;
this package imports nothing.
"""
