"""Shared readers for the contract's TOML and CSV files, with one-line validation errors.

Every problem raises :class:`~lhgraph.errors.InputError` naming the file and the key or row.
Every output goes through :func:`write_atomic` (temporary file, fsync, rename; never
replaces an existing file unless asked); inside :func:`guard_inputs` never one of the
command's input files either.
"""

from __future__ import annotations

import contextlib
import csv
import math
import os
import stat
import tomllib
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np
import tomli_w
from numpy.typing import NDArray

from lhgraph.errors import InputError

INT_EXACT = 2**53
"""Integers in the contract files (ids, indices, counts) stay below this magnitude: exact as
a float, and far inside 64 bits."""
TEXT_ENCODING = "utf-8-sig"
"""Text inputs (CSV, TOML) are UTF-8; a leading byte-order mark (as some spreadsheet programs
and editors write) is skipped."""


def unreadable(exc: OSError, path: str | Path, expected: str) -> InputError:
    """The InputError for an input file ``path`` that could not be opened (``exc``):
    missing (also when a folder on its path is a file), a directory (``expected`` says what
    it should be, e.g. ``"a TOML file"``), or unreadable for another reason (permissions)."""
    if isinstance(exc, FileNotFoundError):
        return InputError("file not found", path)
    if isinstance(exc, NotADirectoryError):
        return InputError("file not found (a folder on its path is a file)", path)
    if isinstance(exc, IsADirectoryError):
        return InputError(f"is a directory, expected {expected}", path)
    return InputError(f"cannot be read ({exc.strerror or exc})", path)


def read_input(path: str | Path, expected: str) -> bytes:
    """The bytes of the input file ``path``; a file that cannot be read raises InputError
    naming it (:func:`unreadable`)."""
    path = Path(path)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise unreadable(exc, path, expected) from None


def read_json_object(path: str | Path) -> dict[str, Any] | None:
    """The JSON object in ``path``, or None when the file cannot be read, is not JSON or
    holds something else (a stored result a command then makes again)."""
    import json  # here: only the run and study folders need it

    try:
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def read_toml(path: str | Path) -> dict[str, Any]:
    """Parse a TOML file; missing or malformed files raise InputError."""
    data = read_input(path, "a TOML file")
    try:
        return tomllib.loads(data.decode(TEXT_ENCODING))  # a leading BOM is skipped
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML ({exc})", path) from None
    except UnicodeDecodeError:
        raise InputError("not a text file", path) from None


@dataclass
class _Guard:
    """What :func:`guard_inputs` holds: the input files by (device, inode), and who is told
    of a created folder."""

    inputs: dict[tuple[int, int], Path] = field(default_factory=dict)
    on_created: Callable[[Path], None] | None = None


_GUARD: ContextVar[_Guard | None] = ContextVar("lhgraph_input_guard", default=None)


@contextlib.contextmanager
def guard_inputs(paths: Iterable[str | Path | None],
                 on_created: Callable[[Path], None] | None = None) -> Iterator[None]:
    """While active, :func:`check_writable` (so every writer) refuses to write over any of
    the input files ``paths`` (also through another spelling, a symbolic or a hard link),
    with or without ``overwrite``; ``on_created(folder)`` is called for each output folder
    it creates. More inputs join with :func:`protect_inputs` (e.g. those a config names)."""
    token = _GUARD.set(_Guard(on_created=on_created))
    try:
        protect_inputs(paths)
        yield
    finally:
        _GUARD.reset(token)


def protect_inputs(paths: Iterable[str | Path | None]) -> None:
    """Add the regular files among ``paths`` to the active :func:`guard_inputs` (none
    active: nothing to do; missing files and directories are skipped)."""
    guard = _GUARD.get()
    if guard is None:
        return
    for p in paths:
        with contextlib.suppress(OSError, TypeError, ValueError):
            st = os.stat(p)  # type: ignore[arg-type]
            if stat.S_ISREG(st.st_mode):
                guard.inputs[(st.st_dev, st.st_ino)] = Path(p)  # type: ignore[arg-type]


def _refuse_input(path: Path) -> None:
    """InputError when ``path`` is one of the guarded input files."""
    guard = _GUARD.get()
    if guard is None or not guard.inputs:
        return
    try:
        st = os.stat(path)
    except OSError:
        return
    source = guard.inputs.get((st.st_dev, st.st_ino))
    if source is not None:
        same = "" if source == path else f" ({source})"
        raise InputError(f"is an input of this command{same}: write the output elsewhere "
                         "(--force never overwrites an input)", path)


def check_writable(path: str | Path, overwrite: bool, *, create_parents: bool = True) -> Path:
    """Refuse an output ``path`` that cannot be written, before any work is done.

    InputError when ``path`` is a directory, one of the inputs :func:`guard_inputs`
    guards, exists and not ``overwrite``, or lies under a regular file or in a directory
    that is not writable. Missing parent directories are created when ``create_parents``
    (and reported to the guard's ``on_created``), else only checked (nothing is created).
    """
    path = Path(path)
    if path.is_dir():
        raise InputError("is a directory", path)
    _refuse_input(path)
    if path.exists() and not overwrite:
        raise InputError("exists already (use --force to overwrite)", path)
    base = path.parent
    while not base.exists() and base != base.parent:
        base = base.parent
    if not base.is_dir():
        raise InputError("is not a directory", base)
    if not os.access(base, os.W_OK | os.X_OK):
        raise InputError("directory is not writable", base)
    if create_parents and not path.parent.exists():
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputError(f"cannot create the directory: {exc.strerror or exc}",
                             path.parent) from None
        guard = _GUARD.get()
        if guard is not None and guard.on_created is not None:
            guard.on_created(path.parent)
    return path


def write_atomic(path: str | Path, data: bytes, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` so that no half file ever appears under that name.

    The bytes go to a temporary file in the same directory, are flushed to the disk
    (fsync), then the file is renamed to ``path``. An existing ``path`` is never replaced
    unless ``overwrite`` (also not one that appears while writing: the final step is a hard
    link, which fails when the name exists). Missing parent directories are created. Any
    failure raises InputError naming the file; the temporary file is removed.
    """
    path = check_writable(path, overwrite)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.{os.urandom(4).hex()}.part")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise InputError(f"cannot write here: {exc.strerror or exc}", path.parent) from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        if overwrite:
            os.replace(tmp, path)
        else:
            _rename_no_clobber(tmp, path)
    except OSError as exc:
        raise InputError(f"cannot write: {exc.strerror or exc}", path) from None
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
    return path


def _rename_no_clobber(tmp: Path, path: Path) -> None:
    """Give ``tmp`` the name ``path`` unless that name exists (atomic where links work)."""
    try:
        os.link(tmp, path)  # fails if the name exists
    except FileExistsError:
        raise InputError("exists already (use --force to overwrite)", path) from None
    except OSError:  # no hard links on this file system: check, then rename
        if path.exists():
            raise InputError("exists already (use --force to overwrite)", path) from None
        os.replace(tmp, path)


def write_toml(path: str | Path, data: dict[str, Any], overwrite: bool = False) -> Path:
    """Write a TOML file atomically."""
    return write_atomic(path, tomli_w.dumps(data).encode(), overwrite)


def get_key(table: dict[str, Any], key: str, source: str | Path, where: str) -> Any:
    """``table[key]`` or InputError 'missing key'."""
    if key not in table:
        raise InputError(f"missing key '{key}'", source, where)
    return table[key]


def as_int(value: Any, source: str | Path, where: str) -> int:
    """An integer value (bools are refused) of magnitude below ``INT_EXACT``."""
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError(f"expected an integer, got {value!r}", source, where)
    if not -INT_EXACT < value < INT_EXACT:
        raise InputError(f"{value} is out of range", source, where)
    return value


def as_float(value: Any, source: str | Path, where: str) -> float:
    """A finite number."""
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise InputError(f"expected a finite number, got {value!r}", source, where)
    return float(value)


def as_vector(value: Any, n: int, source: str | Path, where: str) -> NDArray[np.float64]:
    """A list of ``n`` finite numbers."""
    if not isinstance(value, list) or len(value) != n:
        raise InputError(f"expected a list of {n} numbers, got {value!r}", source, where)
    return np.array([as_float(v, source, where) for v in value])


def as_matrix(value: Any, rows: int, cols: int, source: str | Path, where: str) -> NDArray:
    """A list of ``rows`` lists of ``cols`` finite numbers."""
    if not isinstance(value, list) or len(value) != rows:
        raise InputError(f"expected a {rows}x{cols} matrix", source, where)
    return np.stack([as_vector(row, cols, source, where) for row in value])


def station_tables(
    data: dict[str, Any], source: str | Path
) -> Iterator[tuple[int, dict[str, Any], str]]:
    """``(index, table, where)`` of every ``[lighthouses.<index>]`` table of a TOML document."""
    tables = data.get("lighthouses")
    if not isinstance(tables, dict) or not tables:
        raise InputError("expected [lighthouses.<index>] tables", source)
    seen: dict[int, str] = {}
    for name, table in tables.items():
        where = f"lighthouses.{name}"
        try:
            index = int(name)
        except ValueError:
            raise InputError("station index must be an integer", source, where) from None
        if not 0 <= index < INT_EXACT:
            raise InputError(f"station index must be >= 0, got {index}", source, where)
        if index in seen:
            raise InputError(f"station {index} given twice (also as lighthouses.{seen[index]})",
                             source, where)
        seen[index] = name
        if not isinstance(table, dict):
            raise InputError("expected a table", source, where)
        yield index, table, where


def _numeric_table(f: TextIO, n_columns: int) -> NDArray | None:
    """The rest of an open CSV as a float array when every field is a finite number and every
    row has ``n_columns`` fields (numpy's C parser); ``None`` means: validate row by row."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": handled below
            data = np.loadtxt(f, delimiter=",", ndmin=2, dtype=np.float64)
    except (ValueError, UnicodeDecodeError):
        return None
    if data.size == 0:
        return None
    if data.shape[1] != n_columns or not np.all(np.isfinite(data)):
        return None
    return data


def read_csv_columns(
    path: str | Path, columns: Sequence[tuple[str, type]], optional: Iterable[str] = ()
) -> dict[str, NDArray]:
    """Read a CSV with a header into typed numpy columns.

    ``columns`` lists the required (name, int|float) pairs; any other columns are read as
    float when they parse as numbers (extra columns are allowed by the contract). Errors
    name the file, the line number and the column.
    """
    path = Path(path)
    try:
        f = path.open(newline="", encoding=TEXT_ENCODING)
    except OSError as exc:
        raise unreadable(exc, path, "a CSV file") from None
    with f:
        reader = csv.reader(f)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            raise InputError("empty file, expected a header line", path) from None
        except UnicodeDecodeError:
            raise InputError("not a text file", path) from None
        missing = [name for name, _ in columns if name not in header]
        if missing:
            raise InputError(
                f"missing column(s) {', '.join(missing)} (header: {','.join(header)})", path, "1"
            )
        fast = _numeric_table(f, len(header))
        if fast is None:
            f.seek(0)
            next(reader)
            try:
                rows = list(reader)
            except (csv.Error, UnicodeDecodeError) as exc:
                raise InputError(f"unreadable CSV ({exc})", path) from None
    types = dict(columns)
    if fast is not None:
        wanted = [(j, name) for j, name in enumerate(header) if name in types or name in optional]
        if all(types.get(name, float) is float
               or (np.array_equal(fast[:, j], np.round(fast[:, j]))
                   and np.all(np.abs(fast[:, j]) < INT_EXACT))
               for j, name in wanted):
            return {name: fast[:, j].astype(np.int64) if types.get(name, float) is int
                    else fast[:, j] for j, name in wanted}
        f = path.open(newline="", encoding=TEXT_ENCODING)
        with f:
            rows = list(csv.reader(f))[1:]
    out: dict[str, NDArray] = {}
    for j, name in enumerate(header):
        if name not in types and name not in optional:
            continue
        kind = types.get(name, float)
        values = np.empty(len(rows), dtype=np.int64 if kind is int else np.float64)
        for i, row in enumerate(rows):
            line = str(i + 2)
            if len(row) != len(header):
                raise InputError(f"expected {len(header)} fields, got {len(row)}", path, line)
            text = row[j].strip()
            try:
                value = int(text) if kind is int else float(text)
            except ValueError:
                kind_name = "an integer" if kind is int else "a number"
                raise InputError(f"column '{name}': expected {kind_name}, got {text!r}", path,
                                 line) from None
            if kind is float and not math.isfinite(value):
                raise InputError(f"column '{name}': value is {text}", path, line)
            if kind is int and not -INT_EXACT < value < INT_EXACT:
                raise InputError(f"column '{name}': {text} is out of range", path, line)
            values[i] = value
        out[name] = values
    return out


def write_csv_columns(
    path: str | Path, columns: dict[str, NDArray], formats: dict[str, str], overwrite: bool
) -> Path:
    """Write named columns as CSV (header in dict order) atomically."""
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    lines = [",".join(names)]
    cols = [columns[k] for k in names]
    fmts = [formats.get(k, "{:.17g}") for k in names]
    for i in range(n):
        lines.append(",".join(fmt.format(col[i]) for fmt, col in zip(fmts, cols, strict=True)))
    return write_atomic(path, ("\n".join(lines) + "\n").encode(), overwrite)
