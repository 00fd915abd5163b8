"""The building blocks of the scene schema: each node knows how to check a parsed TOML value (with
messages naming the dotted key, what was expected and what was given) and how to write itself
as JSON Schema; :class:`Checker` turns a dotted key into an error that points into the file.

Generic: nothing here knows the scene's keys (those are in :mod:`sorofem.scene._keys`).
"""

from __future__ import annotations

import copy
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .._validate import MAX_INDEX, Range, shown
from ..errors import SceneError

__all__ = ["Spec", "Number", "Integer", "String", "Boolean", "Array", "Tuple", "Either", "Field", "Group", "Choice",
           "Table", "Tables", "Checker", "NO_DEFAULT", "shown_value", "quoted"]

_HEADER = re.compile(r"^\s*(\[\[?)\s*([^\]]+?)\s*\]\]?\s*(#.*)?$")
_KEY_PART = re.compile(r"^([A-Za-z0-9_\-]+)(?:\[(\d+)\])?$")


def _type_name(value: Any) -> str:
    return {
        bool: "a boolean",
        int: "an integer",
        float: "a number",
        str: "a string",
        list: "an array",
        dict: "a table",
    }.get(type(value), type(value).__name__)


def shown_value(value: Any) -> str:
    """``a string '0.45'``, ``an integer 3``: a value with its TOML type, for messages."""
    text = ("true" if value else "false") if isinstance(value, bool) else shown(value, 60)
    return f"{_type_name(value)} {text}"


def _or(items: list[str]) -> str:
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " or " + items[-1]


def quoted(names: tuple[str, ...] | list[str]) -> list[str]:
    return [f"'{n}'" for n in names]


def _join(key: str, name: str) -> str:
    return f"{key}.{name}" if key else name


class Spec:
    """A node of the schema: a type with its constraints."""

    def what(self) -> str:
        """Singular description with an article, for messages: ``a number > 0``."""
        raise NotImplementedError

    def plural(self) -> str:
        """Plural description without article: ``numbers > 0``."""
        raise NotImplementedError

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> Any:
        """The value, checked and normalised (numbers as float, defaults filled in).

        ``key`` is the dotted key errors name; ``at`` the position inside an array that
        errors report by the array's key (``[2]``), or ``""``.
        """
        raise NotImplementedError

    def schema(self) -> dict[str, Any]:
        """This node as JSON Schema."""
        raise NotImplementedError


@dataclass(frozen=True)
class Number(Spec):
    """A finite number in a :class:`~sorofem.materials.Range` (the reasons of its bounds are
    appended to out-of-range messages)."""

    range: Range = Range()

    def what(self) -> str:
        return " ".join(filter(None, ("a number", self.range.describe())))

    def plural(self) -> str:
        return " ".join(filter(None, ("numbers", self.range.describe())))

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise c.fail(key, at, f"expected {self.what()}, got {shown_value(value)}")
        try:
            x = float(value)
        except OverflowError:  # an integer beyond float64's range
            raise c.fail(key, at, f"expected a finite number, got an integer of {len(str(abs(value)))} digits") from None
        if not math.isfinite(x):
            raise c.fail(key, at, f"expected a finite number, got {x}")
        bound = self.range.violated(x)
        if bound is not None:
            raise c.fail(key, at, f"expected {self.what()}, got {x:g}" + (f" ({bound[2]})" if bound[2] else ""))
        return x

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "number"}
        r = self.range
        for name, v in (("exclusiveMinimum", r.gt), ("minimum", r.ge), ("exclusiveMaximum", r.lt)):
            if v is not None:
                out[name] = v
        return out


@dataclass(frozen=True)
class Integer(Spec):
    """An integer from ``ge`` to ``le``; every integer of a scene has an upper bound (by default
    :data:`~sorofem._validate.MAX_INDEX`), so that no count or index can ask for unbounded work
    or overflow a 64-bit integer."""

    ge: int | None = None
    le: int = MAX_INDEX

    def what(self) -> str:
        return "an integer" + (f" >= {self.ge}" if self.ge is not None else "")

    def plural(self) -> str:
        return "integers" + (f" >= {self.ge}" if self.ge is not None else "")

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise c.fail(key, at, f"expected {self.what()}, got {shown_value(value)}")
        if self.ge is not None and value < self.ge:
            raise c.fail(key, at, f"expected {self.what()}, got {value}")
        if value > self.le:
            raise c.fail(key, at, f"expected an integer <= {self.le} (a documented limit), got {shown(value)}")
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "integer"}
        if self.ge is not None:
            out["minimum"] = self.ge
        out["maximum"] = self.le
        return out


@dataclass(frozen=True)
class String(Spec):
    #: Allowed values (None: any string) ...
    enum: tuple[str, ...] | None = None
    #: ... or, besides them, strings matching this regular expression (described by ``pattern_doc``).
    pattern: str | None = None
    pattern_doc: str = ""

    def what(self) -> str:
        if self.enum is None and self.pattern is None:
            return "a string"
        if self.enum is None:
            return self.pattern_doc
        options = [repr(v) for v in self.enum or ()] + ([self.pattern_doc] if self.pattern else [])
        return f"one of {', '.join(options)}"

    def plural(self) -> str:
        return "strings" if self.enum is None and self.pattern is None else f"strings, each {self.what()}"

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> str:
        if not isinstance(value, str):
            raise c.fail(key, at, f"expected {'a string' if self.enum is None else self.what()}, got {shown_value(value)}")
        if self.enum is not None or self.pattern is not None:
            if value not in (self.enum or ()) and not (self.pattern and re.fullmatch(self.pattern, value)):
                raise c.fail(key, at, f"expected {self.what()}, got {value!r}")
        return value

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "string"}
        if self.enum is not None and self.pattern is not None:
            out["anyOf"] = [{"enum": list(self.enum)}, {"pattern": f"^(?:{self.pattern})$"}]
        elif self.enum is not None:
            out["enum"] = list(self.enum)
        elif self.pattern is not None:
            out["pattern"] = f"^(?:{self.pattern})$"
        return out


@dataclass(frozen=True)
class Boolean(Spec):
    def what(self) -> str:
        return "true or false"

    def plural(self) -> str:
        return "booleans"

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> bool:
        if not isinstance(value, bool):
            raise c.fail(key, at, f"expected true or false, got {shown_value(value)}")
        return value

    def schema(self) -> dict[str, Any]:
        return {"type": "boolean"}


@dataclass(frozen=True)
class Array(Spec):
    items: Spec
    min_items: int = 0
    max_items: int | None = None
    #: Errors inside name the item's own key (``dynamics.actuation[1]``), not the array's.
    indexed: bool = False
    #: Plural name of the items for messages (default: the items' own description).
    noun: str = ""

    def _describe(self, article: bool) -> str:
        inner = self.noun or self.items.plural()
        a = "an array" if article else "arrays"
        if self.max_items is not None and self.max_items == self.min_items:
            return f"{a} of {self.min_items} {inner}"
        if self.min_items == 1:
            return f"{'a non-empty array' if article else 'non-empty arrays'} of {inner}"
        if self.min_items > 1:
            return f"{a} of at least {self.min_items} {inner}"
        return f"{a} of {inner}"

    def what(self) -> str:
        return self._describe(True)

    def plural(self) -> str:
        return self._describe(False)

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> list[Any]:
        if not isinstance(value, list):
            raise c.fail(key, at, f"expected {self.what()}, got {shown_value(value)}")
        n = len(value)
        if n < self.min_items or (self.max_items is not None and n > self.max_items):
            got = "an empty array" if n == 0 else f"an array of length {n}"
            raise c.fail(key, at, f"expected {self.what()}, got {got}")
        if self.indexed:
            return [self.items.check(c, v, f"{key}[{i}]", "") for i, v in enumerate(value)]
        return [self.items.check(c, v, key, f"{at}[{i}]") for i, v in enumerate(value)]

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "array", "items": self.items.schema()}
        if self.min_items:
            out["minItems"] = self.min_items
        if self.max_items is not None:
            out["maxItems"] = self.max_items
        return out


@dataclass(frozen=True)
class Tuple(Spec):
    """A fixed-length array whose items differ, e.g. ``[time, alpha]``."""

    items: tuple[Spec, ...]
    noun: str  # "[time, alpha]"

    def what(self) -> str:
        return f"a pair {self.noun}" if len(self.items) == 2 else f"an array {self.noun}"

    def plural(self) -> str:
        return f"{self.noun} pairs" if len(self.items) == 2 else f"arrays {self.noun}"

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> list[Any]:
        if not isinstance(value, list) or len(value) != len(self.items):
            shown = f"an array of length {len(value)}" if isinstance(value, list) else shown_value(value)
            raise c.fail(key, at, f"expected {self.what()} of {len(self.items)} {self._kinds()}, got {shown}")
        return [spec.check(c, v, key, f"{at}[{i}]") for i, (spec, v) in enumerate(zip(self.items, value))]

    def _kinds(self) -> str:
        kinds = {type(s) for s in self.items}
        return self.items[0].plural().split()[0] if len(kinds) == 1 else "values"

    def schema(self) -> dict[str, Any]:
        # prefixItems types each position and minItems = maxItems fixes the length, so "items"
        # (the items after the prefix) has nothing to check in draft 2020-12: it only gives
        # validators of older drafts, which do not know prefixItems (taplo), the common type.
        n = len(self.items)
        out: dict[str, Any] = {"type": "array", "prefixItems": [s.schema() for s in self.items]}
        types = {s.schema().get("type") for s in self.items}
        if len(types) == 1 and None not in types:
            out["items"] = {"type": types.pop()}
        return {**out, "minItems": n, "maxItems": n}


@dataclass(frozen=True)
class Either(Spec):
    options: tuple[Spec, ...]

    def what(self) -> str:
        return " or ".join(o.what() for o in self.options)

    def plural(self) -> str:
        return " or ".join(o.plural() for o in self.options)

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> Any:
        for option in self.options:
            try:
                return option.check(c, value, key, at)
            except SceneError:
                continue
        raise c.fail(key, at, f"expected {self.what()}, got {shown_value(value)}")

    def schema(self) -> dict[str, Any]:
        return {"anyOf": [o.schema() for o in self.options]}


class _Missing:
    def __repr__(self) -> str:
        return "<no default>"


NO_DEFAULT: Any = _Missing()


@dataclass(frozen=True)
class Field:
    """One key of a table."""

    spec: Spec
    #: What it means (the schema's description; editors show it).
    doc: str
    units: str = ""
    required: bool = False
    #: Filled in when the key is absent (and written to the schema), unless NO_DEFAULT or None.
    default: Any = NO_DEFAULT
    #: Message after "missing: " when a required key is absent (default: ``doc``).
    missing: str = ""
    #: The value the generated documentation shows (default: ``default``); NO_DEFAULT: the key
    #: is left out of the annotated example.
    example: Any = NO_DEFAULT
    #: Shown commented out in the annotated example (an alternative or a rarely needed key).
    commented: bool = False
    #: ``(text, link)`` of a documentation section the key table refers to.
    see: tuple[str, str] | None = None

    def shown_example(self) -> Any:
        """What the annotated example shows for this key (NO_DEFAULT: nothing)."""
        if self.example is not NO_DEFAULT:
            return self.example
        return self.default if self.default is not None else NO_DEFAULT

    def schema(self) -> dict[str, Any]:
        out = dict(self.spec.schema())
        out["description"] = self.doc + (f" [{self.units}]" if self.units else "")
        if self.default is not NO_DEFAULT and self.default is not None:
            out["default"] = self.default
        return out


@dataclass(frozen=True)
class Group:
    """Keys that go together; ``extras`` are optional keys allowed only with them."""

    keys: tuple[str, ...]
    extras: tuple[str, ...] = ()

    def label(self) -> str:
        return " + ".join(quoted(self.keys))


@dataclass(frozen=True)
class Choice:
    """Exactly one (``required``) or at most one of several groups of keys.

    A group is chosen by giving any key that belongs to it alone (with ``partial``, failing that,
    any extra that belongs to it alone); then all its keys are
    required (unless ``partial``: any of them), and keys of the other groups are not allowed.
    """

    groups: tuple[Group, ...]
    required: bool = True
    partial: bool = False

    def _all(self, group: Group) -> tuple[str, ...]:
        return group.keys + group.extras

    def keys(self) -> list[str]:
        return list(dict.fromkeys(k for g in self.groups for k in self._all(g)))

    def check(self, c: "Checker", table: dict[str, Any], key: str) -> None:
        counts: dict[str, int] = {}
        for g in self.groups:
            for k in self._all(g):
                counts[k] = counts.get(k, 0) + 1
        chosen = [g for g in self.groups if any(k in table and counts[k] == 1 for k in g.keys)]
        if not chosen and self.partial:
            chosen = [g for g in self.groups if any(k in table and counts[k] == 1 for k in g.extras)]
        options = _or([g.label() for g in self.groups])
        if len(chosen) > 1 or (self.required and not chosen):
            given = [k for k in self.keys() if k in table]
            got = f"got {', '.join(quoted(given))}" if given else "got none of them"
            raise c.error(key or None, f"expected {'exactly' if self.required else 'at most'} one of {options}; {got}")
        group = chosen[0] if chosen else None
        if group is not None and not self.partial:
            missing = [k for k in group.keys if k not in table]
            if missing:
                others = [g.label() for g in self.groups if g is not group]
                raise c.error(
                    _join(key, missing[0]),
                    f"missing: expected {group.label()} together (or {_or(others)} instead)",
                )
        allowed = set(self._all(group)) if group is not None else set()
        for k in self.keys():
            if k in table and k not in allowed:
                owners = _or([g.label() for g in self.groups if k in self._all(g)])
                with_what = f", not with {group.label()}" if group is not None else f" (and {owners} is not given)"
                raise c.error(_join(key, k), f"only allowed with {owners}{with_what}")

    def schema(self) -> dict[str, Any]:
        every = self.keys()
        alternatives = []
        for g in self.groups:
            alt: dict[str, Any] = {}
            if not self.partial:
                alt["required"] = list(g.keys)
            forbidden = [k for k in every if k not in self._all(g)]
            if forbidden:
                alt["not"] = {"anyOf": [{"required": [k]} for k in forbidden]}
            alternatives.append(alt)
        if not self.required and not self.partial:
            alternatives.append({"not": {"anyOf": [{"required": [k]} for k in every]}})
        return {"anyOf": alternatives}


@dataclass(frozen=True)
class Table(Spec):
    fields: dict[str, Field]
    choices: tuple[Choice, ...] = ()
    #: Shown after "expected a table" when something else is given.
    hint: str = ""
    doc: str = ""

    def what(self) -> str:
        return "a table" + self.hint

    def plural(self) -> str:
        return "tables"

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> dict[str, Any]:
        if not isinstance(value, dict):
            raise c.fail(key, at, f"expected a table{self.hint}, got {_type_name(value)}")
        for name in value:
            if name not in self.fields:
                raise c.error(_join(key, name), f"unknown key '{name}' (allowed: {', '.join(self.fields)})")
        for choice in self.choices:
            choice.check(c, value, key)
        for name, f in self.fields.items():
            if f.required and name not in value:
                raise c.error(_join(key, name), f"missing: {f.missing or f.doc}")
        out = {name: self.fields[name].spec.check(c, v, _join(key, name)) for name, v in value.items()}
        for name, f in self.fields.items():
            if name not in out and f.default is not NO_DEFAULT:
                out[name] = copy.deepcopy(f.default)
        return out

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "object"}
        if self.doc:
            out["description"] = self.doc
        out["properties"] = {name: f.schema() for name, f in self.fields.items()}
        required = [name for name, f in self.fields.items() if f.required]
        if required:
            out["required"] = required
        out["additionalProperties"] = False
        if len(self.choices) == 1:
            out.update(self.choices[0].schema())
        elif self.choices:
            out["allOf"] = [ch.schema() for ch in self.choices]
        return out


@dataclass(frozen=True)
class Tables(Spec):
    """An array of tables: ``[[name]]`` entries (or an inline array of tables)."""

    table: Table
    header: str
    min_items: int = 0
    #: Appended to the message when there are fewer than ``min_items`` entries.
    note: str = ""
    #: The annotated example writes the entries as ``[[header]]`` sections (else inline).
    sections: bool = True

    def what(self) -> str:
        return f"an array of tables ([[{self.header}]])"

    def plural(self) -> str:
        return "arrays of tables"

    def check(self, c: "Checker", value: Any, key: str, at: str = "") -> list[dict[str, Any]]:
        if isinstance(value, dict):
            raise c.fail(key, at, f"expected an array of tables: write [[{self.header}]], not [{self.header}]")
        if not isinstance(value, list):
            raise c.fail(key, at, f"expected {self.what()}, got {_type_name(value)}")
        if len(value) < self.min_items:
            raise c.fail(key, at, f"at least {self.min_items} [[{self.header}]] entry is required{self.note}")
        return [self.table.check(c, v, f"{key}[{i}]") for i, v in enumerate(value)]

    def schema(self) -> dict[str, Any]:
        out: dict[str, Any] = {"type": "array", "items": self.table.schema()}
        if self.min_items:
            out["minItems"] = self.min_items
        return out


# ---------------------------------------------------------------------------
# Errors that point into the file


class Checker:
    """Builds errors that name the scene file, the dotted key and (when found) the line."""

    def __init__(self, path: Path, text: str) -> None:
        self.path = path
        self.lines = text.splitlines()

    def find_line(self, key: str) -> int | None:
        """Best-effort 1-based line of a dotted key such as ``fixed[1].box.min``."""
        parts = []
        for token in key.split("."):
            match = _KEY_PART.match(token)
            if not match:
                return None
            parts.append((match.group(1), None if match.group(2) is None else int(match.group(2))))
        names = [name for name, _ in parts]
        # The longest prefix that is a table header opens the section to search in.
        for depth in range(len(parts), 0, -1):
            header = ".".join(names[:depth])
            span = self._section(header, parts[depth - 1][1])
            if span is not None:
                return self._find_in(span, names[depth:])
        # Keys of the root table, or a table written inline at the root.
        first_header = next((i for i, line in enumerate(self.lines) if _HEADER.match(line)), len(self.lines))
        return self._find_in((0, first_header), names)

    def _section(self, header: str, index: int | None) -> tuple[int, int] | None:
        seen = -1
        for i, line in enumerate(self.lines):
            match = _HEADER.match(line)
            if match and re.sub(r"\s+", "", match.group(2)) == header:
                seen += 1
                if index is None or seen == index:
                    end = next(
                        (j for j in range(i + 1, len(self.lines)) if _HEADER.match(self.lines[j])),
                        len(self.lines),
                    )
                    return i, end
        return None

    def _find_in(self, span: tuple[int, int], names: list[str]) -> int | None:
        start, end = span
        found = start + 1 if start < len(self.lines) and _HEADER.match(self.lines[start]) else None
        if not names and found is not None:
            return found
        for depth, name in enumerate(names):
            pattern = re.compile(
                (r"^\s*" if depth == 0 else r"[{,\s]") + re.escape(name) + r"\s*="
            )
            hit = next((j for j in range(start, end) if pattern.search(self.lines[j])), None)
            if hit is None:
                break
            found, start = hit + 1, hit
        return found

    def error(self, key: str | None, message: str) -> SceneError:
        line = self.find_line(key) if key else None
        return SceneError(message, path=self.path, key=key, line=line)

    def fail(self, key: str, at: str, message: str) -> SceneError:
        """An error about the value at ``key`` (``at``: the item inside it, e.g. ``[2]``)."""
        return self.error(key or None, message + (f" (item {at})" if at else ""))
