"""Field-wise mutation of YAML documents, and writing them back as YAML.

A document is plain data (mappings, lists, text, numbers, booleans, null) as
:func:`twolevel.world.document.read_document` builds it. :func:`mutate` changes one field of it:
a number becomes NaN, ±inf, huge, tiny, negative or zero (or is scaled); a list is emptied or
loses or repeats an item; a key is dropped, repeated or invented; a value gets another type.
:func:`dump` writes the result as block-style YAML, one entry per line, so a diagnostic's line
says which entry it is about; a mapping given as :class:`Pairs` may repeat a key.

Standard library and PyYAML only.
"""

from __future__ import annotations

import copy
import math
import random
import re
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import yaml

__all__ = ["Path_", "Bounds", "Pairs", "Mutation", "SPECIAL_NUMBERS", "numbers", "nodes", "mutate", "apply", "dump"]

Path_ = tuple[str | int, ...]
Bounds = Callable[[Path_], "tuple[float, float] | None"]
"""The allowed range (lo, hi) of the number at a path, if known: mutations then also try its
ends and values inside it, where accepted inputs are most extreme."""

SPECIAL_NUMBERS: tuple[float | int, ...] = (
    math.nan, math.inf, -math.inf, 1e300, -1e300, 1e-300, -1e-300, 0, 0.0, -1, -1.0, 1e-5, 1e9, 10**30, -(10**30),
)
"""Values every numeric field is tried with: NaN, ±inf, huge, tiny, negative, zero."""

_OTHER_TYPES: tuple[Any, ...] = ("text", "", True, False, None, [1, 2], {"k": 1}, "1e5", "nan", "x" * 300)


class Pairs(list):  # type: ignore[type-arg]
    """A mapping written as (key, value) pairs, so that one key can appear twice."""


@dataclass(frozen=True)
class Mutation:
    """One change to a document: ``op`` at ``path`` with ``value`` (set, add, duplicate).

    ``op``: "set" (replace the value), "drop" (remove the key or item), "duplicate" (repeat the
    key — with ``value`` as the repeated key's value — or the item), "add" (a new key ``value[0]``
    = ``value[1]``), "empty" (an empty list or mapping).
    """

    path: Path_
    op: str
    value: Any = None

    def __str__(self) -> str:
        where = ".".join(str(p) for p in self.path) or "the document"
        return f"{self.op} {where}" + (f" = {self.value!r}" if self.op in ("set", "add", "duplicate") else "")


def nodes(data: Any, path: Path_ = ()) -> Iterator[tuple[Path_, Any]]:
    """Every entry of ``data`` (depth first) with its path; the root is not included."""
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(data, list) else ()
    for key, value in items:
        yield path + (key,), value
        yield from nodes(value, path + (key,))


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def numbers(data: Any) -> list[Path_]:
    """The path of every number in ``data``."""
    return [p for p, v in nodes(data) if _is_number(v)]


def _number_for(value: float | int, rnd: random.Random, bounds: "tuple[float, float] | None" = None) -> float | int:
    if bounds is not None and rnd.random() < 0.6:
        lo, hi = bounds
        roll = rnd.random()
        if roll < 0.5:
            out = rnd.choice((lo, hi))
        elif roll < 0.75 or lo <= 0 or not math.isfinite(hi):
            out = rnd.uniform(lo, hi if math.isfinite(hi) else lo + 1e3)
        else:  # log-uniform: small values as often as large ones
            out = math.exp(rnd.uniform(math.log(lo), math.log(hi)))
        return round(out) if isinstance(value, int) and math.isfinite(out) else out
    if rnd.random() < 0.7:
        return rnd.choice(SPECIAL_NUMBERS)
    factor = rnd.choice((-1.0, 1e6, 1e-6, 0.5, 2.0, 1.0001, 0.9999))
    out = value * factor
    return int(out) if isinstance(value, int) and rnd.random() < 0.5 and math.isfinite(out) else out


def mutate(data: Any, rnd: random.Random, bounds: Bounds | None = None) -> Mutation:
    """A random mutation of ``data`` (half of them on numbers, when it has any; with ``bounds``,
    numbers are often set to the ends of their range or inside it)."""
    entries = list(nodes(data))
    nums = [(p, v) for p, v in entries if _is_number(v)]
    if nums and rnd.random() < 0.5:
        path, value = rnd.choice(nums)
        return Mutation(path, "set", _number_for(value, rnd, bounds(path) if bounds else None))
    path, value = rnd.choice(entries)
    containers = [(p, v) for p, v in entries if isinstance(v, (dict, list))]
    roll = rnd.random()
    if roll < 0.25:
        return Mutation(path, "set", copy.deepcopy(rnd.choice(_OTHER_TYPES)))
    if roll < 0.45:
        return Mutation(path, "drop")
    if roll < 0.6 and isinstance(path[-1], str):
        return Mutation(path, "duplicate", copy.deepcopy(value) if rnd.random() < 0.5 else rnd.choice(_OTHER_TYPES))
    if roll < 0.7 and isinstance(path[-1], int):
        return Mutation(path, "duplicate")
    if containers and roll < 0.85:
        cpath, cvalue = rnd.choice(containers)
        if isinstance(cvalue, dict) and rnd.random() < 0.6:
            return Mutation(cpath, "add", (rnd.choice(("bogus", "x", "s", "id", "lane", "kind")), rnd.choice(_OTHER_TYPES)))
        return Mutation(cpath, "empty")
    if _is_number(value):
        return Mutation(path, "set", _number_for(value, rnd))
    return Mutation(path, "set", copy.deepcopy(rnd.choice(_OTHER_TYPES)))


def apply(data: Any, mutation: Mutation) -> Any:
    """A copy of ``data`` with ``mutation`` applied (``data`` is not changed)."""
    out = copy.deepcopy(data)
    *parents, last = mutation.path
    holder = out
    for key in parents:
        holder = holder[key]
    if mutation.op == "set":
        holder[last] = mutation.value
    elif mutation.op == "drop":
        del holder[last]
    elif mutation.op == "empty":
        holder[last] = type(holder[last])()
    elif mutation.op == "add":
        holder[last][mutation.value[0]] = mutation.value[1]
    elif mutation.op == "duplicate" and isinstance(holder, list):
        holder.insert(last, copy.deepcopy(holder[last]))
    elif mutation.op == "duplicate":
        pairs = Pairs()
        for key, value in holder.items():
            pairs.append((key, value))
            if key == last:
                pairs.append((key, mutation.value))
        if parents:
            _set(out, tuple(parents), pairs)
        else:
            out = pairs
    else:
        raise ValueError(f"unknown mutation {mutation.op!r}")
    return out


def _set(data: Any, path: Path_, value: Any) -> None:
    for key in path[:-1]:
        data = data[key]
    data[path[-1]] = value


# ------------------------------------------------------------------------------------ dumping

_NUMBER_LIKE = re.compile(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?")


_PLAIN = re.compile(r"[A-Za-z_][A-Za-z0-9_./-]*")
_YAML_WORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null", "nan", "inf"}


def _scalar(value: Any) -> str:
    if value is None or isinstance(value, bool):
        return {None: "null", True: "true", False: "false"}[value]
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return ".nan" if value != value else (".inf" if value > 0 else "-.inf") if math.isinf(value) else repr(value)
    if isinstance(value, str) and _PLAIN.fullmatch(value) and value.lower() not in _YAML_WORDS:
        return value
    if isinstance(value, str) and (_NUMBER_LIKE.fullmatch(value) or not value.isprintable() or not value.isascii()):
        # text that looks like a number stays text; control characters are escaped, on one line
        return yaml.safe_dump(value, default_style='"', width=10**9).removesuffix("\n")
    text = yaml.safe_dump(value, default_flow_style=True, width=10**9, allow_unicode=True)
    return text.removesuffix("\n").removesuffix("\n...")


def _lines(value: Any, indent: int) -> list[str]:
    pad = " " * indent
    if isinstance(value, (dict, Pairs)):
        out = []
        for key, item in (value if isinstance(value, Pairs) else value.items()):
            if isinstance(item, (dict, list)) and item:
                out.append(f"{pad}{_scalar(key)}:")
                out += _lines(item, indent + 2)
            else:
                out.append(f"{pad}{_scalar(key)}: {_inline(item)}")
        return out
    if isinstance(value, list):
        out = []
        for item in value:
            if isinstance(item, (dict, list)) and item:
                sub = _lines(item, indent + 2)
                out.append(f"{pad}- {sub[0][indent + 2:]}")
                out += sub[1:]
            else:
                out.append(f"{pad}- {_inline(item)}")
        return out
    return [pad + _inline(value)]


def _inline(value: Any) -> str:
    if isinstance(value, dict):
        return "{}"
    if isinstance(value, list):
        return "[]"
    return _scalar(value)


def dump(data: Any) -> str:
    """``data`` as block-style YAML text, one entry per line (empty containers as ``{}``/``[]``)."""
    if isinstance(data, (dict, Pairs)) and not data:
        return "{}\n"
    return "\n".join(_lines(data, 0)) + "\n"
