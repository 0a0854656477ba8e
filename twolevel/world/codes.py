"""Diagnostic codes of maps and scenarios (``YML4xx``).

Declared once here; each :class:`~twolevel.diagnostics.Code` registers itself. Imported by
``twolevel check``: no heavy imports.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W = Severity.ERROR, Severity.WARNING

YML401 = Code("YML401", "file-unreadable", E, "The file does not exist or cannot be read.", bad_input=True)
YML402 = Code("YML402", "file-too-large", E, "The file is larger than the loader accepts.")
YML403 = Code("YML403", "binary-file", E, "The file is binary (contains NUL bytes), not YAML text.")
YML404 = Code("YML404", "not-utf8", E, "The file is not valid UTF-8.")
YML405 = Code("YML405", "empty-file", E, "The file holds no YAML document.")
YML406 = Code("YML406", "yaml-syntax", E, "The YAML cannot be parsed.")
YML407 = Code("YML407", "unsafe-tag", E, "A YAML tag that could construct objects or is unknown.")
YML408 = Code("YML408", "alias-bomb", E, "Too many or recursive YAML aliases (billion laughs).")
YML409 = Code("YML409", "duplicate-key", E, "A key appears twice in the same mapping.")
YML410 = Code("YML410", "wrong-kind", E, "The file is not the kind expected (map vs scenario).")
YML411 = Code("YML411", "unknown-key", E, "A key the schema does not know.")
YML412 = Code("YML412", "missing-key", E, "A required key is missing.")
YML413 = Code("YML413", "wrong-type", E, "A value of the wrong type.")
YML414 = Code("YML414", "out-of-range", E, "A number outside its allowed range.")
YML415 = Code("YML415", "invalid-value", E, "A value the schema does not accept.")
YML416 = Code("YML416", "bad-reference", E, "A reference to an id that does not exist.")
YML417 = Code("YML417", "duplicate-id", E, "Two items share one id.")
YML418 = Code("YML418", "missing-file", E, "A referenced file does not exist.")
YML419 = Code("YML419", "reference-cycle", E, "Files that extend each other in a cycle.")
YML420 = Code("YML420", "bad-geometry", E, "A position or route that does not fit the map's geometry.")
YML421 = Code("YML421", "population-crowded", W, "A population could not place all its vehicles.")
YML422 = Code("YML422", "not-a-mapping", E, "The document is not a mapping of keys to values.")
YML423 = Code("YML423", "assumption-tighter", W,
              "An assumption about other road users tighter than its documented default (the guarantee covers less).")
YML424 = Code("YML424", "bad-parameter-reference", E, "A ${...} value that is not a valid expression of the parameters.")
YML425 = Code("YML425", "unknown-parameter", E, "A value given for a parameter the scenario does not declare.")
YML426 = Code("YML426", "parameter-range-invalid", W, "Some value within a parameter's range makes the scenario invalid.")
YML427 = Code("YML427", "goal-out-of-reach", W, "The goal cannot be reached within the run (or its deadline) at the speed limits.")
YML428 = Code("YML428", "duplicate-rule", E,
              "Two rules of a scenario share a name: two rule files define it, or one file is listed twice.")
YML430 = Code("YML430", "look-ahead-invalid", E,
              "The MPC's look-ahead (horizon_s, coarse_dt, coarse_steps) is not whole periods or contradicts itself.")
YML431 = Code("YML431", "sensing-short", W,
              "The sensing range is shorter than the stopping distance at the speeds the scenario allows.")
YML432 = Code("YML432", "bend-too-fast", W,
              "A bend of the route cannot be driven at its speed limit within the comfort lateral acceleration.")
YML433 = Code("YML433", "impossible-motion", E, "A scripted participant asks for more acceleration or braking than any tyre gives.")
YML434 = Code("YML434", "beyond-assumptions", W,
              "A participant is scripted beyond what the safety layer assumes of its kind; the simulation limits it.")
YML435 = Code("YML435", "unknown-rule-margin", E,
              "controller.margins names a rule that none of the scenario's rule files defines.")
YML436 = Code("YML436", "unknown-expected-rule", E,
              "expect.rules names a rule that none of the scenario's rule files defines.")

__all__ = [name for name in dir() if name.startswith("YML")]
