"""Diagnostic codes of the rule-file stages.

``STL1xx`` the file and its syntax, ``STL2xx`` names, types and signals, ``STL3xx`` style and
portability (texts that other STL tools read differently). Declaring a code registers it in
:data:`twolevel.diagnostics.REGISTRY`; :data:`ALL` lists this module's codes in order.
"""

from __future__ import annotations

from twolevel.diagnostics import Code, Severity

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO

# ----------------------------------------------------------------------------- STL1xx file & syntax
STL100 = Code("STL100", "unreadable-file", E, "The rule file cannot be read (missing, a directory, not a regular file, no permission).",
              bad_input=True)
STL101 = Code("STL101", "syntax-error", E, "The text is not valid rule-language syntax.")
STL102 = Code("STL102", "unexpected-character", E, "A character that no token of the language starts with.")
STL103 = Code("STL103", "unbalanced-bracket", E, "A '(' or '[' is not closed, or a ')' or ']' closes nothing.")
STL104 = Code("STL104", "empty-file", W, "The file holds no declaration and no rule (empty or only comments).")
STL105 = Code("STL105", "binary-file", E, "The file contains NUL bytes: it is binary, not a rule file.")
STL106 = Code("STL106", "invalid-utf8", E, "The file is not valid UTF-8.")
STL107 = Code("STL107", "file-too-large", E, "The file is larger than the rule-file size limit.")
STL108 = Code("STL108", "nesting-too-deep", E, "Parentheses, prefix operators or operator chains nest deeper than the limit.")
STL109 = Code("STL109", "unsupported-feature", E, "An RTAMT construct that twolevel does not support (imports).")
STL110 = Code("STL110", "invalid-literal", E, "A number that is out of range, or a time unit outside an interval.")

# ----------------------------------------------------------------------------- STL2xx names & types
STL201 = Code("STL201", "undeclared-name", E, "A name that is neither a declared signal or constant nor an earlier rule.")
STL202 = Code("STL202", "unused-declaration", W, "A declared input or constant is never read, or an output is never assigned.")
STL203 = Code("STL203", "duplicate-name", E, "A name declared or assigned twice.")
STL204 = Code("STL204", "forward-reference", E, "A rule refers to itself or to a rule defined later in the file.")
STL205 = Code("STL205", "assign-to-non-output", E, "A rule assigns to a name declared as an input or a constant.")
STL206 = Code("STL206", "type-mismatch", E, "A term (number) where a formula is expected, or a formula where a term is expected.")
STL207 = Code("STL207", "inverted-interval", E, "An interval whose lower bound exceeds its upper bound: it is empty.")
STL208 = Code("STL208", "point-interval", W, "An interval [a:a] of one instant: the temporal operator is a plain time shift.")
STL209 = Code("STL209", "interval-not-multiple-of-dt", E, "An interval bound that is not a multiple of the sampling period dt.")
STL210 = Code("STL210", "unbounded-future", W, "An unbounded future operator: the rule cannot run online or in the MPC.")
STL211 = Code("STL211", "horizon-exceeds-mpc", W, "The formula looks further ahead than the MPC horizon H*dt.")
STL212 = Code("STL212", "nonlinear-predicate", W, "A predicate that is not linear in the signals: it cannot be encoded as a MILC.")
STL213 = Code("STL213", "float-equality", W, "'==' or '!==' on real-valued signals: exact equality rarely holds on floats.")
STL214 = Code("STL214", "unknown-builtin", E, "A call to a function that is not a built-in world predicate.")
STL215 = Code("STL215", "builtin-arity", E, "A built-in predicate called with the wrong number of arguments.")
STL216 = Code("STL216", "signal-not-provided", E, "A declared input that the world does not provide.")
STL217 = Code("STL217", "unbound-constant", I, "A constant without a value: the scenario must bind it.")
STL218 = Code("STL218", "non-constant-value", E, "A constant's value is not a constant expression.")
STL219 = Code("STL219", "unknown-binding", E, "A binding for a name that is not a declared constant.")
STL220 = Code("STL220", "interval-too-long", E, "An interval longer than any trace can be (over 1e7 samples at dt, or 1e6 s).")
STL221 = Code("STL221", "division-by-zero", E, "A division whose divisor is the constant 0: the term is infinite or NaN at every sample.")
STL222 = Code("STL222", "non-finite-constant", E, "A constant whose value (declared or bound) is infinite or NaN.")
STL223 = Code("STL223", "term-overflow", E, "Arithmetic on constants that overflows: the term is infinite or NaN at every sample.")
STL224 = Code("STL224", "unknown-domain", E, "A quantifier over a domain the world does not provide (it provides 'vehicles').")
STL225 = Code("STL225", "participant-signal-call", E, "A participant's signal read without exactly one participant bound by a quantifier.")
STL226 = Code("STL226", "participant-as-value", E, "A quantified participant used as a number or a formula instead of through one of its signals.")
STL227 = Code("STL227", "shadowing-variable", E, "A quantified variable named like a declaration, a rule or an enclosing quantifier's variable.")
STL228 = Code("STL228", "nested-quantifier", E, "A quantifier inside another: participant signals relate one participant to the ego, so nesting is not supported.")
STL229 = Code("STL229", "unused-quantified-variable", W, "A quantifier whose body reads no signal of its participant: it only asks whether any participant is present.")

# ----------------------------------------------------------------------------- STL3xx style & portability
STL301 = Code("STL301", "and-or-mix", W, "'and' and 'or' mixed without parentheses; tools disagree on their precedence.")
STL302 = Code("STL302", "not-implies-mix", W, "'not a -> b' without parentheses; tools disagree whether 'not' covers the implication.")
STL303 = Code("STL303", "chained-implies", W, "'a -> b -> c' without parentheses; tools disagree on its associativity.")
STL304 = Code("STL304", "prefix-over-binary", W, "A temporal prefix followed by a binary operator ('always a and b'); tools disagree on its scope.")
STL305 = Code("STL305", "arith-chain", W, "'a - b + c' or 'a / b * c' without parentheses: RTAMT 0.4.10 computes them right-to-left.")

ALL: tuple[Code, ...] = (
    STL100, STL101, STL102, STL103, STL104, STL105, STL106, STL107, STL108, STL109, STL110,
    STL201, STL202, STL203, STL204, STL205, STL206, STL207, STL208, STL209, STL210,
    STL211, STL212, STL213, STL214, STL215, STL216, STL217, STL218, STL219, STL220, STL221, STL222, STL223,
    STL224, STL225, STL226, STL227, STL228, STL229,
    STL301, STL302, STL303, STL304, STL305,
)
# STL100 is bad input (the CLI exits 2: usage error); binary, non-UTF-8, oversized or too deeply
# nested files were read and are findings (exit 1).
