"""The one YAML writer of every importer (twolevel/interop/output.py): what it writes reads back
as the data (numbers rounded to millimetres), whatever the keys, strings and nesting."""

from __future__ import annotations

import math

import yaml
from hypothesis import example, given, settings
from hypothesis import strategies as st

from twolevel.interop.output import DIGITS, to_yaml

_text = st.text(st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12)
_scalars = st.none() | st.booleans() | st.integers(-10**6, 10**6) | st.floats(allow_nan=False) | _text
_values = st.recursive(_scalars, lambda inner: st.lists(inner, max_size=6) | st.dictionaries(_text, inner, max_size=5),
                       max_leaves=30)


def _rounded(value):  # noqa: ANN001, ANN202 - the oracle: what the file must read back as
    if isinstance(value, float):
        r = round(value, DIGITS) if math.isfinite(value) else value
        return 0.0 if r == 0 else r
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_rounded(v) for v in value]
    return value


@settings(max_examples=300, deadline=None)
@example({"": 1e300})  # a regression: repr() gives 1e+300, which YAML 1.1 reads as a string
@given(st.dictionaries(_text, _values, max_size=6))
def test_what_is_written_reads_back_as_the_data(data: dict) -> None:
    assert yaml.safe_load(to_yaml(data, "a header\n\nof lines")) == _rounded(data)


def test_a_lane_boundary_is_one_line_and_points_stay_flat() -> None:
    text = to_yaml({"lanes": [{"id": "r1_0_-1", "left_bound": [[0.0, 1.23456], [10.0, 1.0]], "successors": []}]})
    assert text.splitlines() == ["lanes:", "- id: r1_0_-1", "  left_bound: [[0.0, 1.235], [10.0, 1.0]]", "  successors: []"]
