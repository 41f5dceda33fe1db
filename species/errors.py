"""Errors a user can act on. The CLI prints their message in one line; library code raises them."""
from __future__ import annotations

__all__ = ["TreefarmError", "ParameterError", "TreeTooLargeError"]


class TreefarmError(ValueError):
    """Base class of errors caused by input a user gave (a value, a file, a name)."""


class ParameterError(TreefarmError):
    """A parameter dictionary has an unknown key, a wrong type or a value out of range."""

    def __init__(self, key: str, value, allowed: str):
        self.key, self.value, self.allowed = key, value, allowed
        super().__init__(f"parameter {key!r} = {value!r} is invalid: allowed {allowed}")


class TreeTooLargeError(TreefarmError):
    """A tree grows more stems or nodes than a dictionary's limits or its caller allow."""
