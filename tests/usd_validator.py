"""Test helper: open a USD file and check it with usd-core's validators (`pxr.UsdValidation`, what `usdchecker`
runs).

`assert_valid_usd(path) -> Usd.Stage` asserts that no validator reports an error and returns the open stage.
"""
from __future__ import annotations

from pathlib import Path


def assert_valid_usd(path: str | Path):
    """The stage of `path`, after asserting every registered validator finds no error in it."""
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path))
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = [e for e in UsdValidation.ValidationContext(validators).Validate(stage)
              if e.GetType() == UsdValidation.ValidationErrorType.Error]
    assert not errors, [e.GetMessage() for e in errors]
    return stage
