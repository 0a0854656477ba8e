"""Fuzzing harnesses: hostile inputs generated from real ones, and what the toolchain did with them.

Each target takes one generated input, runs the stages a user would run on it and classifies the
outcome (a diagnostic, a valid result, or an internal error, a hang, a corrupt result), so that the
property tests (``tests/``, derandomized under CI) and long campaigns (``benchmarks/fuzz.py``)
share one definition of "held up". Inputs are drawn from a :class:`random.Random`, so hypothesis
(``st.randoms()``) and a seeded campaign drive the same generators.

- :mod:`twolevel.fuzz.rules`: rule-file text: ``check`` (positions, line endings, renderers,
  printing back), then monitoring what it accepts.
- :mod:`twolevel.fuzz.traces`: trace CSVs: reformatting one never changes a verdict; mangled
  bytes give diagnostics.
- :mod:`twolevel.fuzz.mutation`: field-wise mutation of YAML documents (plain data) and writing
  them back as YAML, duplicate keys included.
- :mod:`twolevel.fuzz.world`: maps and scenarios: ``check``, then (for what it accepts) loading,
  building the world, ``plan`` and ``simulate``.
"""
