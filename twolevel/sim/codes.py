"""Diagnostic codes of closed-loop simulation (``SIM61x``; ``SIM63x`` traffic co-simulated in SUMO;
``SIM60x`` are the trace monitor's).

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. No heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO

__all__ = ["SIM610", "SIM611", "SIM612", "SIM613", "SIM614", "SIM615", "SIM616", "SIM617", "SIM618", "SIM630", "SIM631", "SIM632"]

SIM610 = Code("SIM610", "bad-controller", E, "The requested controller is not known or not available.")
SIM611 = Code("SIM611", "bad-run-setting", E, "A run setting given on the command line is out of range.")
SIM612 = Code("SIM612", "run-interrupted", W, "The run was interrupted (Ctrl-C, SIGTERM or SIGHUP); every completed "
              "step is in the trace.")
SIM613 = Code("SIM613", "run-crashed", E, "The run stopped on an internal error; every completed step is in the trace.")
SIM614 = Code("SIM614", "collision", W, "The ego collided with another vehicle (oriented boxes overlapped); "
              "the message says whether it was the ego's fault.")
SIM615 = Code("SIM615", "cannot-write-run", E, "The run directory cannot be created or written.")
SIM616 = Code("SIM616", "unsafe-start", W, "The initial state has no verified fail-safe: the scenario starts where the "
              "ego may not be able to avoid a collision that would be its fault.")
SIM617 = Code("SIM617", "run-dir-busy", E, "Another run is writing the run directory: a second run into it is refused "
              "(choose another --out, or wait for the first).", bad_input=True)
SIM618 = Code("SIM618", "rules-unsatisfiable", W, "For a while no plan satisfied every rule: the high level fell back; the "
              "message names the rules that conflict and what the car did instead.")
SIM630 = Code("SIM630", "sumo-unavailable", E, "SUMO traffic needs libsumo (pip install 'twolevel[sumo]').")
SIM631 = Code("SIM631", "sumo-start-failed", E, "SUMO could not start with the scenario's network and routes.")
SIM632 = Code("SIM632", "sumo-failed", E, "SUMO stopped with an error during the run (a vehicle, route or flow of its "
              "files it could not insert or build when due): the run is aborted; every completed step is in the "
              "trace.")
