"""Verdicts: a run judged against its scenario's pass criteria (``expect:``).

:func:`~twolevel.verdict.judge.judge_run` reads what a run recorded (its trace, its summary and
the scenario's world) and judges every criterion (:mod:`twolevel.verdict.criteria`), each with
its measured value, its bound and a margin (≥ 0 passes; the robustness a campaign searches).
Nothing here runs during the simulation.
"""
