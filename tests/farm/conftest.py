"""Farm test fixtures: stand-in builders pickled by value, so Ray workers need not import the tests folder."""
from __future__ import annotations

from ray import cloudpickle

import farm_standins

cloudpickle.register_pickle_by_value(farm_standins)
