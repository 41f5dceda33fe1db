"""Errors a user can act on. The CLI prints their message in one line; library code raises them.

Every error here pickles by its state, so one raised in a Ray worker reaches the driver as the same error.
"""
from __future__ import annotations

import os
from contextlib import contextmanager

__all__ = ["TreefarmError", "ParameterError", "TreeTooLargeError", "PathError", "user_path"]


def _rebuilt(cls, args):
    return cls.__new__(cls, *args)  # BaseException.__new__ sets args; the state comes back through __setstate__


class TreefarmError(ValueError):
    """Base class of errors caused by input a user gave (a value, a file, a name)."""

    def __reduce__(self):
        # The default pickling calls cls(*args), which subclasses taking (key, value, allowed) cannot take.
        return _rebuilt, (type(self), self.args), self.__dict__ or None


class ParameterError(TreefarmError):
    """A parameter dictionary has an unknown key, a wrong type or a value out of range."""

    def __init__(self, key: str, value, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"parameter {key!r} = {value!r} is invalid: allowed {allowed}")


class TreeTooLargeError(TreefarmError):
    """A tree grows more stems or nodes than a dictionary's limits or its caller allow."""


class PathError(TreefarmError):
    """A file or folder the user named is missing, of the wrong kind, or cannot be read or written."""


@contextmanager
def user_path(path, action: str):
    """Raise a file error inside the block as a PathError naming `path` (the user's file or folder) and `action`
    ("read", "write", ...); some file systems (pyarrow's) name no file in their errors."""
    try:
        yield
    except OSError as exc:
        reason = exc.strerror or str(exc)  # pyarrow's strerror names the file and the system's reason
        if exc.filename is not None and os.path.abspath(exc.filename) != os.path.abspath(str(path)):
            reason = f"{exc.filename}: {reason}"
        raise PathError(f"cannot {action} {path}: {reason}") from exc
