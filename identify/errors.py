"""Errors for bad input, shared by every part of greybench.

One exception type, :class:`InputError`, carries where the problem is (file, column or
field, row or line, character column) so that the CLI can print one clear line and exit
with code 2, and the service can answer 4xx with the same text.
"""
from __future__ import annotations


class InputError(ValueError):
    """Bad input from a user: a file, a program, a config or a request body.

    Parameters
    ----------
    message : str
        What is wrong, in plain words.
    source : str, optional
        The file (path) or body the input came from.
    field : str, optional
        The column, key or field name.
    row : int, optional
        Data row, 0-based as in the table (header excluded).
    line : int, optional
        1-based line number in a text file (e.g. a G-code program).
    column : int, optional
        1-based character column on that line.
    """

    def __init__(self, message: str, *, source: str | None = None, field: str | None = None,
                 row: int | None = None, line: int | None = None, column: int | None = None):
        self.message = message
        self.source = None if source is None else str(source)
        self.field = field
        self.row = row
        self.line = line
        self.column = column
        super().__init__(str(self))

    def where(self) -> str:
        parts = []
        if self.source:
            parts.append(self.source)
        if self.line is not None:
            parts.append(f"line {self.line}")
        if self.column is not None:
            parts.append(f"column {self.column}")
        if self.field is not None:
            parts.append(f"column '{self.field}'" if self.row is not None else f"field '{self.field}'")
        if self.row is not None:
            parts.append(f"row {self.row}")
        return ", ".join(parts)

    def __str__(self) -> str:
        where = self.where()
        return f"{where}: {self.message}" if where else self.message

    def to_dict(self) -> dict:
        """Machine-readable form (the service returns it as the 4xx detail)."""
        return {k: v for k, v in dict(message=self.message, source=self.source, field=self.field,
                                        row=self.row, line=self.line, column=self.column).items()
                if v is not None}


class NotFittedError(RuntimeError):
    """An estimator was asked to predict or save before ``fit`` was called."""


def read_json(path, missing: str = "not found"):
    """The JSON document in ``path``; ``InputError`` naming the file (``missing`` when it does not
    exist) or the line and column where it is not valid JSON."""
    import json
    from pathlib import Path

    p = Path(path)
    if not p.exists():
        raise InputError(missing, source=str(p))
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}", source=str(p), line=exc.lineno, column=exc.colno) from None
