"""Helpers the tests share: worlds, systems, formulas and run directories built with the real
loaders and writers. Importable as ``helpers.<module>`` (pytest's ``pythonpath`` puts ``tests/``
on the path: see ``pyproject.toml``); no test module imports another test module.

* ``milp_systems`` — the double integrator and random formulas of the compiler and solver tests;
* ``mpc_worlds`` — worlds, rules and closed loops of the controller tests;
* ``safety_worlds`` — the small maps and scenarios of ``tests/safety/worlds/``, placing the ego
  and others; ``legal`` — sampled legal behaviours of others (the soundness tests);
* ``formulas`` — formula and trace strategies of the monitor tests;
* ``report_runs`` — hand-made run directories of the report tests;
* ``world_files`` — a small map and scenario text of the loader tests.
"""
