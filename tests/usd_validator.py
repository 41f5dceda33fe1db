"""Test helper: usd-core's UsdValidation (every registered validator) on an open stage.

`assert_valid_usd(stage)` asserts that no validator reports an error (warnings pass), naming each message.
"""
from __future__ import annotations


def assert_valid_usd(stage) -> None:
    from pxr import UsdValidation

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = [e for e in UsdValidation.ValidationContext(validators).Validate(stage)
              if e.GetType() == UsdValidation.ValidationErrorType.Error]
    assert not errors, [e.GetMessage() for e in errors]
