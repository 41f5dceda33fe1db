"""The fit to the drawing's budget (`reconstruct.fitting`): its default and its check, apart from the fitting
itself so that the method registry and the command line read them without loading OpenCV and SciPy."""
from __future__ import annotations

import numpy as np

from species.errors import TreefarmError

__all__ = ["DEFAULT_FIT_EVALS", "FitError", "check_fit_evals"]

# Candidate trees a drawing method's fit grows and redraws by default: a few seconds on one core for most drawings
# (docs/reconstruct.md, Fitting to the drawing, has the measured figures).
DEFAULT_FIT_EVALS = 32


class FitError(TreefarmError):
    """A fitting budget that is not a count of evaluations."""


def check_fit_evals(evals) -> int:
    """The budget as an int, or a FitError naming it and what is allowed."""
    if isinstance(evals, bool) or not isinstance(evals, (int, np.integer)) or evals < 0:
        raise FitError(f"--fit-evals {evals!r} is invalid: allowed an integer >= 0 (0 turns fitting off)")
    return int(evals)
