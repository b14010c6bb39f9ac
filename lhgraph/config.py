"""The configuration layer: frozen option dataclasses with declared rules, read from TOML.

An options class declares each field with :func:`option` (default, allowed range or choices,
an old spelling) and calls :func:`check_fields` from ``__post_init__``, so a bad value is
refused wherever the object is made: in Python, from a TOML table (:func:`load_options` or
the checked reader :class:`Table`) or from command-line flags (:func:`override`). Every
refusal is one :class:`~lhgraph.errors.InputError` line naming the file (or flag), the key
and what is allowed, e.g. ``run.toml:graph.max_iterations: must be > 0 (got -3)``.

Adding an option = adding one ``option(...)`` field to its dataclass; the loaders, the
unknown-key check and the messages follow from the declaration.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from numbers import Integral, Real
from pathlib import Path
from typing import Any, TypeVar

from lhgraph.errors import InputError

T = TypeVar("T")
RULE = "lhgraph.rule"
GROUP = "lhgraph.group"
_MISSING: Any = dataclasses.MISSING
KIND_WORDS = {bool: "true or false", int: "an integer", float: "a finite number",
              str: "a string", Path: "a path string"}


@dataclasses.dataclass(frozen=True)
class Rule:
    """What one option accepts: its ``kind`` (bool, int, float, str or Path), bounds
    (``gt``/``ge`` below, ``lt``/``le`` above), ``choices`` for strings, whether ``None`` is
    allowed (``optional``), an old spelling of the key (``alias``) and whether a float must
    be ``finite`` (else TOML's ``inf`` is accepted)."""

    kind: type
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] | None = None
    optional: bool = False
    alias: str | None = None
    finite: bool = True

    def allowed(self) -> str:
        """The accepted values in words (``"> 0"``, ``"in (0, 1]"``, ``"one of lm, isam2"``)."""
        if self.choices is not None:
            return "one of " + ", ".join(self.choices)
        low = self.gt if self.gt is not None else self.ge
        high = self.lt if self.lt is not None else self.le
        if low is not None and high is not None:
            return (f"in {'(' if self.gt is not None else '['}{low:g}, {high:g}"
                    f"{')' if self.lt is not None else ']'}")
        if low is not None:
            return f"{'>' if self.gt is not None else '>='} {low:g}"
        if high is not None:
            return f"{'<' if self.lt is not None else '<='} {high:g}"
        return KIND_WORDS.get(self.kind, self.kind.__name__)

    def check(self, value: Any, source: str | Path | None, where: str) -> Any:
        """``value`` converted to the rule's kind (a TOML integer for a float option becomes a
        float, a string for a path a Path), or InputError naming ``source`` and ``where``."""
        if value is None and self.optional:
            return None
        kind = self.kind
        if kind is bool:
            ok = isinstance(value, bool)
        elif kind is int:
            ok = isinstance(value, Integral) and not isinstance(value, bool)
        elif kind is float:
            ok = (isinstance(value, Real) and not isinstance(value, bool)
                  and (math.isfinite(value) or not self.finite and not math.isnan(value)))
        elif kind is Path:
            ok = isinstance(value, str | Path)
        else:
            ok = isinstance(value, kind)
        if not ok:
            raise InputError(f"expected {KIND_WORDS.get(kind, kind.__name__)}, got {value!r}",
                             source, where)
        if kind is float and not isinstance(value, float):
            value = float(value)
        elif kind is Path:
            value = Path(value)
        if self.choices is not None and value not in self.choices:
            raise InputError(f"must be {self.allowed()} (got {value!r})", source, where)
        if kind in (int, float) and not (
                (self.gt is None or value > self.gt) and (self.ge is None or value >= self.ge)
                and (self.lt is None or value < self.lt) and (self.le is None or value <= self.le)):
            raise InputError(f"must be {self.allowed()} (got {value!r})", source, where)
        return value


def option(default: Any = _MISSING, *, kind: type | None = None, gt: float | None = None,
           ge: float | None = None, lt: float | None = None, le: float | None = None,
           choices: tuple[str, ...] | None = None, alias: str | None = None,
           finite: bool = True, factory: Any = _MISSING) -> Any:
    """A dataclass field with its :class:`Rule`; ``kind`` defaults to the default's type
    (give it when the default is ``None``, which then stays allowed)."""
    if kind is None:
        kind = type(default)
    rule = Rule(kind, gt, ge, lt, le, choices, default is None, alias, finite)
    if factory is not _MISSING:
        return dataclasses.field(default_factory=factory, metadata={RULE: rule})
    return dataclasses.field(default=default, metadata={RULE: rule})


def group(cls: type) -> Any:
    """A dataclass field holding a group of options: an options dataclass ``cls``, made
    with its defaults. A TOML table gives the group's options flat or in a sub-table named
    after the field (:func:`load_options`)."""
    return dataclasses.field(default_factory=cls, metadata={GROUP: cls})


def groups(cls: type) -> dict[str, type]:
    """The option groups of a dataclass (:func:`group` fields), by field name."""
    return {f.name: f.metadata[GROUP] for f in dataclasses.fields(cls) if GROUP in f.metadata}


def rules(cls: type) -> dict[str, Rule]:
    """The rule of every option field of a dataclass, by field name: the :func:`option`
    declaration, else (a plain field whose default is a bool, int, float or str) the
    default's type, with any float accepted for a float field."""
    out = {}
    for f in dataclasses.fields(cls):
        if RULE in f.metadata:
            out[f.name] = f.metadata[RULE]
        elif type(f.default) in (bool, int, float, str):
            out[f.name] = Rule(type(f.default), finite=False)
    return out


def check_fields(obj: Any) -> None:
    """Check every :func:`option` field of a dataclass instance (call from ``__post_init__``;
    the error names the field)."""
    for name, rule in rules(type(obj)).items():
        rule.check(getattr(obj, name), None, name)


class Table:
    """One TOML table read key by key: typed getters with ranges, keys relative to ``where``
    (``""`` = the document), and :meth:`finish` refusing the keys no getter asked for."""

    def __init__(self, data: Any, source: str | Path, where: str = "",
                 base_dir: Path | None = None):
        if not isinstance(data, dict):
            raise InputError("expected a table", source, where or None)
        self.data, self.source, self.where = data, source, where
        self.base_dir = base_dir
        self.used: set[str] = set()

    def key(self, name: str) -> str:
        """The full key of ``name`` in this table (``"graph.loss"``)."""
        return f"{self.where}.{name}" if self.where else name

    def __contains__(self, name: str) -> bool:
        return name in self.data

    def get(self, name: str, default: Any = None, alias: str | None = None) -> Any:
        """The raw value (``default`` when absent); ``alias`` is an accepted old spelling."""
        self.used.add(name)
        if alias is not None:
            self.used.add(alias)
            if name in self.data and alias in self.data:
                raise InputError(f"give '{name}' or its old spelling '{alias}', not both",
                                 self.source, self.key(alias))
            if alias in self.data:
                return self.data[alias]
        return self.data.get(name, default)

    def value(self, name: str, rule: Rule, default: Any = None) -> Any:
        """The value of ``name`` checked by ``rule`` (``default`` unchecked when absent)."""
        present = name in self.data or (rule.alias is not None and rule.alias in self.data)
        raw = self.get(name, default, rule.alias)
        if not present:
            return default
        where = self.key(rule.alias if rule.alias in self.data else name)
        if rule.kind is Path and isinstance(raw, str) and self.base_dir is not None:
            return self.base_dir / rule.check(raw, self.source, where)
        return rule.check(raw, self.source, where)

    def number(self, name: str, default: float | None, *, gt: float | None = None,
               ge: float | None = None, lt: float | None = None,
               le: float | None = None) -> float:
        """A finite number within the given bounds."""
        return self.value(name, Rule(float, gt, ge, lt, le), default)

    def integer(self, name: str, default: int | None, *, gt: float | None = None,
                ge: float | None = None, le: float | None = None) -> int:
        """An integer within the given bounds."""
        return self.value(name, Rule(int, gt, ge, None, le), default)

    def choice(self, name: str, default: str, choices: tuple[str, ...]) -> str:
        """One of ``choices``."""
        return self.value(name, Rule(str, choices=tuple(choices)), default)

    def path(self, name: str, required: bool = False) -> Path | None:
        """A path string, relative to the table's ``base_dir``."""
        if required and name not in self.data:
            raise InputError(f"missing key '{name}'", self.source, self.key(name))
        return self.value(name, Rule(Path))

    def vector(self, name: str, default: Any, n: int) -> tuple[float, ...] | None:
        """A list of ``n`` finite numbers as a tuple (``default`` unchecked when absent)."""
        if name not in self.data:
            self.used.add(name)
            return default
        value = self.get(name)
        if not isinstance(value, list) or len(value) != n:
            raise InputError(f"expected a list of {n} numbers, got {value!r}", self.source,
                             self.key(name))
        return tuple(Rule(float).check(v, self.source, self.key(name)) for v in value)

    def table(self, name: str) -> Table:
        """The sub-table ``name`` (empty when absent)."""
        return Table(self.get(name, {}), self.source, self.key(name), self.base_dir)

    def options(self, name: str, cls: type[T]) -> T:
        """The sub-table ``name`` read into the options dataclass ``cls``."""
        return load_options(cls, self.get(name, {}), self.source, self.key(name))

    def refuse_unknown(self, known: set[str] | None = None) -> None:
        """InputError for the first key not in ``known`` (default: the keys read so far),
        listing the allowed keys."""
        known = self.used if known is None else known
        unknown = [k for k in self.data if k not in known]
        if unknown:
            raise InputError(f"unknown key '{unknown[0]}' (allowed: "
                             f"{', '.join(sorted(known))})", self.source, self.key(unknown[0]))

    def finish(self) -> None:
        """Refuse every key that no getter read."""
        self.refuse_unknown()


def load_options(cls: type[T], data: Any, source: str | Path, where: str = "") -> T:
    """An options dataclass from a TOML table: unknown keys, wrong types and values out of
    their declared range raise InputError naming ``source`` and the key. A class of option
    groups (:func:`group`) takes each group's options flat in the table or in the group's
    sub-table, not both."""
    if groups(cls):
        return _load_groups(cls, data, source, where)
    table = Table(data, source, where)
    declared = rules(cls)
    table.refuse_unknown(set(declared) | {r.alias for r in declared.values() if r.alias})
    values = {name: table.value(name, rule) for name, rule in declared.items()
              if name in table or (rule.alias is not None and rule.alias in table)}
    try:
        return cls(**values)
    except InputError as exc:  # a check across fields in the class's __post_init__
        if exc.source is not None:
            raise
        raise InputError(exc.problem, source, table.key(exc.where) if exc.where else where
                         or None) from None


def _load_groups(cls: type[T], data: Any, source: str | Path, where: str) -> T:
    """:func:`load_options` of a class of option groups."""
    table = Table(data, source, where)
    found = groups(cls)
    owner = {name: g for g, group_cls in found.items() for name in rules(group_cls)}
    owner |= {r.alias: g for g, group_cls in found.items()
              for r in rules(group_cls).values() if r.alias}
    table.refuse_unknown(set(owner) | set(found))
    values = {}
    for g, group_cls in found.items():
        flat = {k: v for k, v in table.data.items() if owner.get(k) == g}
        nested = table.table(g)
        for key in flat:
            if key in nested:
                raise InputError(f"give '{key}' in [{table.key(g)}] or flat, not both", source,
                                 table.key(key))
        values[g] = load_options(group_cls, {**flat, **nested.data}, source,
                                 nested.where if nested.data and not flat else where)
    return cls(**values)


def override(obj: T, flags: Mapping[str, tuple[str, Any]]) -> T:
    """A copy of the options dataclass ``obj`` with fields replaced from command-line flags
    (``{flag: (field, value)}``, ``None`` values skipped), each checked by its field's rule
    (the error names the flag)."""
    declared = rules(type(obj))
    changes = {name: declared[name].check(value, None, flag) if name in declared else value
               for flag, (name, value) in flags.items() if value is not None}
    return dataclasses.replace(obj, **changes) if changes else obj
