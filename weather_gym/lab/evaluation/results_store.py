"""The results of a resumable run: one SQLite row per finished cell, exported as a tidy CSV.

``results.csv`` (the export every report and reader uses) has its store beside it, ``results.sqlite``:
table ``cells`` (``key`` primary key: the cell's key fields as a canonical JSON object; ``status``
``ok``/``failed``; ``error``: one line or NULL; ``elapsed_s``; ``metrics``: a JSON object in the order
the cell function returned them) and table ``run`` (the key fields, checked on every resume). A run
holds SQLite's exclusive lock until it closes the store, so a second run on the same results is
refused at once; the kernel drops the lock however a run ends. The CSV holds the key fields,
``status``, ``error``, ``elapsed_s`` and the metrics in order of appearance (nested values as JSON,
None as an empty field).

Example:
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "results.csv"
    >>> with ResultsStore(path, ["x"]) as store:
    ...     store.put(cell_key({"x": 1}, ["x"]), "ok", None, 0.5, '{"y": 2.5}')
    ...     store.export(list(store.rows))
    >>> read_results(path)
    [{'x': 1, 'status': 'ok', 'error': None, 'elapsed_s': 0.5, 'y': 2.5}]
    >>> path.read_text()
    'x,status,error,elapsed_s,y\\n1,ok,,0.5,2.5\\n'
"""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import json
import os
import sqlite3
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from weather_gym.core._io import atomic_file, check_not_input, write_failure
from weather_gym.core.errors import (
    FileFormatError,
    InputError,
    MissingInputError,
    OutputExistsError,
    OutputPathError,
)

__all__ = ["RESERVED_COLUMNS", "ResultsStore", "cell_key", "check_results_path", "read_results", "store_path", "table", "to_json"]

RESERVED_COLUMNS = ("status", "error", "elapsed_s")
"""Columns written after the key fields; cells and metrics may not use these names."""
_SCHEMA = ("CREATE TABLE IF NOT EXISTS run (key_fields TEXT NOT NULL)",
           "CREATE TABLE IF NOT EXISTS cells (key TEXT PRIMARY KEY, status TEXT NOT NULL CHECK (status IN "
           "('ok', 'failed')), error TEXT, elapsed_s REAL NOT NULL, metrics TEXT NOT NULL)")


def _plain(o: Any) -> Any:
    if isinstance(o, np.generic | np.ndarray):
        return o.tolist()
    return dataclasses.asdict(o) if dataclasses.is_dataclass(o) else str(o)  # type: ignore[arg-type]  # rows hold instances, not classes


def to_json(value: Any, *, sort_keys: bool = False) -> str:
    """JSON text of ``value``: numpy values as numbers, dataclasses as objects, anything else as its text."""
    return json.dumps(value, sort_keys=sort_keys, default=_plain)


def cell_key(fields: Mapping[str, Any], key_fields: Sequence[str]) -> str:
    """A cell's identity in the store: its key fields as canonical JSON."""
    if missing := [k for k in key_fields if k not in fields]:
        raise InputError(f"cell {dict(fields)!r} lacks key field(s) {', '.join(missing)}")
    return to_json({k: fields[k] for k in key_fields}, sort_keys=True)


def store_path(results_path: str | os.PathLike) -> Path:
    """The SQLite store of a results file: ``results.csv`` -> ``results.sqlite``."""
    return Path(results_path).with_suffix(".sqlite")


def check_results_path(results_path: str | os.PathLike) -> Path:
    """Create the results file's folder and check it can be written (:class:`OutputPathError` if not)."""
    path = Path(results_path)
    check_not_input(path, what="results path")
    if path.is_dir():
        raise OutputPathError(f"results path {path} is a folder; give a file path such as {path / 'results.csv'} "
                              "(or move the folder away)")
    if path.suffix == ".sqlite" or (path.exists() and not path.is_file()):
        raise OutputPathError(f"results path {path} must be a regular file not ending in .sqlite (its store's name)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"cannot write results to {path}: {exc.strerror or exc}") from None
    if not os.access(path.parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise OutputPathError(f"cannot write results to {path}: permission denied")
    return path


class ResultsStore:
    """The store of ``path`` for one run (``key_fields`` given: created if need be, checked against the
    stored key fields, held exclusively until closed) or for reading (``key_fields`` None). A CSV
    without its store is imported once, its key fields typed like those of the cell ``like``.
    ``rows``: key -> row (key fields, ``status``, ``error``, ``elapsed_s``, metrics), in store order."""

    def __init__(self, path: str | os.PathLike, key_fields: Sequence[str] | None,
                 like: Mapping[str, Any] | None = None) -> None:
        self.path, self.store, write = Path(path), store_path(path), key_fields is not None
        if not self.store.exists() and not write:
            raise MissingInputError(f"results file {path} does not exist (nor its store {self.store.name})")
        legacy = None  # the rows of a results.csv of a version without the store: imported once
        if key_fields is not None and not self.store.exists() and self.path.exists() and self.path.stat().st_size > 0:
            legacy = legacy_rows(self.path, like)
            if legacy[0] != tuple(key_fields):
                raise _other_configuration(self.path, legacy[0], key_fields)
        self.con = sqlite3.connect(self.store.absolute().as_uri() + ("" if write else "?mode=ro"), uri=True,
                                   timeout=0, isolation_level=None)
        try:
            self._load(key_fields, legacy[1] if legacy else [])
        except BaseException:
            self.con.close()
            raise

    def _load(self, key_fields: Sequence[str] | None, legacy: list[dict[str, Any]]) -> None:
        try:
            if key_fields is not None:  # EXCLUSIVE locking mode keeps BEGIN EXCLUSIVE's lock until close
                self.con.execute("PRAGMA locking_mode = EXCLUSIVE")
            self.con.execute("BEGIN" if key_fields is None else "BEGIN EXCLUSIVE")
            for statement in _SCHEMA if key_fields is not None else ():
                self.con.execute(statement)
            got = self.con.execute("SELECT key_fields FROM run").fetchone()
            self.key_fields = tuple(json.loads(got[0]) if got else key_fields or ())
            if got is None and key_fields is not None:
                self.con.execute("INSERT INTO run VALUES (?)", (json.dumps(list(key_fields)),))
            elif key_fields is not None and self.key_fields != tuple(key_fields):
                raise _other_configuration(self.path, self.key_fields, key_fields)
            self.con.executemany("INSERT OR REPLACE INTO cells VALUES (?, ?, ?, ?, ?)", [
                (cell_key(r, self.key_fields), r["status"], r["error"], r["elapsed_s"] or 0.0,
                 to_json({c: v for c, v in r.items() if c not in {*self.key_fields, *RESERVED_COLUMNS}})) for r in legacy])
            self.rows = {r[0]: self._row(*r) for r in self.con.execute("SELECT * FROM cells ORDER BY rowid")}
            self.con.execute("COMMIT")
        except sqlite3.OperationalError as exc:
            if "locked" in str(exc):
                raise OutputExistsError(f"another run is writing results in {self.path.parent} ({self.store.name});"
                                        " wait for it to finish or use another output folder") from None
            raise OutputPathError(f"cannot use the results store {self.store}: {exc}") from None
        except sqlite3.DatabaseError as exc:
            raise FileFormatError(f"{self.store} is not a results store ({exc}); move it away") from None

    def _row(self, key: str, status: str, error: str | None, elapsed_s: float, metrics: str) -> dict[str, Any]:
        fields = json.loads(key)
        return {**{k: fields[k] for k in self.key_fields}, "status": status, "error": error, "elapsed_s": elapsed_s,
                **json.loads(metrics)}

    def put(self, key: str, status: str, error: str | None, elapsed_s: float, metrics: str) -> None:
        """Store one finished cell (``metrics``: a JSON object) durably; it moves to the end of ``rows``."""
        try:
            self.con.execute("INSERT OR REPLACE INTO cells VALUES (?, ?, ?, ?, ?)", (key, status, error, elapsed_s,
                                                                                     metrics))
        except sqlite3.Error as exc:  # a full disk is the machine's state, not a bug
            raise OutputPathError(f"cannot write {self.store}: {exc}") from None
        self.rows.pop(key, None)
        self.rows[key] = self._row(key, status, error, elapsed_s, metrics)

    def export(self, keys: Sequence[str]) -> None:
        """Rewrite the CSV atomically: the rows of other keys first (store order), then ``keys`` in order."""
        wanted = set(keys)
        columns, rows = table([r for k, r in self.rows.items() if k not in wanted] +
                              [self.rows[k] for k in keys if k in self.rows])
        try:
            with atomic_file(self.path, overwrite=True, newline="") as f:
                w = csv.writer(f, lineterminator="\n")
                w.writerow(columns)
                w.writerows([to_json(v, sort_keys=True) if isinstance(v, list | dict) else v for v in r.values()]
                            for r in rows)
        except OSError as exc:
            raise write_failure(self.path, exc) from None

    def __enter__(self) -> ResultsStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.con.close()


def _other_configuration(path: Path, theirs: Sequence[str], ours: Sequence[str]) -> InputError:
    return InputError(f"{path} was written by a different configuration: its key fields are ({', '.join(theirs)}), "
                      f"this run's are ({', '.join(ours)}); use another output path (nothing was changed)")


def legacy_rows(path: Path, like: Mapping[str, Any] | None = None) -> tuple[tuple[str, ...], list[dict[str, Any]]]:
    """The key fields and rows of a results CSV without its store (a version that kept only the CSV):
    key fields typed like those of the cell ``like``, other values as that version read them back
    (numbers, booleans, JSON lists and objects, '' -> None)."""
    try:
        with open(path, encoding="utf-8", newline="") as f:
            header, *lines = list(csv.reader(f))
    except (UnicodeDecodeError, ValueError, csv.Error) as exc:
        raise FileFormatError(f"{path} is not a UTF-8 CSV ({exc}); choose another output path") from None
    if "status" not in header:
        raise InputError(f"{path} is not a results file written by weather-gym's runner (no 'status' column; "
                         f"header: {', '.join(header)}); choose another output path")
    ok = [v for v in lines if len(v) == len(header) and v[header.index("status")] in ("ok", "failed")]
    like = like or {}
    return tuple(header[:header.index("status")]), [{c: _typed(t, like.get(c)) for c, t in zip(header, v, strict=True)}
                                                    for v in ok]


def _typed(text: str, like: Any = None) -> Any:
    """A CSV field typed like ``like`` (a key field of this run's cells), else as that version guessed."""
    if isinstance(like, str):
        return text
    if text in ("", "True", "False"):
        return None if text == "" else text == "True"
    for parse in (type(like) if isinstance(like, int | float) else int, float, json.loads if text[0] in "[{" else str):
        with contextlib.suppress(ValueError):
            return parse(text)
    return text


def table(rows: Sequence[Mapping[str, Any]]) -> tuple[list[str], list[dict[str, Any]]]:
    """The columns (in order of appearance) and every row with every column (None where it has no value)."""
    columns = list(dict.fromkeys(c for r in rows for c in r))
    return columns, [{c: r.get(c) for c in columns} for r in rows]


def read_results(path: str | os.PathLike) -> list[dict[str, Any]]:
    """All rows of a results file, typed as stored (read from its store, which is never written here;
    a CSV of a version without the store is read as that version read it)."""
    if not store_path(path).exists() and Path(path).is_file():
        return table(legacy_rows(Path(path))[1])[1]
    with ResultsStore(path, None) as store:
        return table(list(store.rows.values()))[1]
