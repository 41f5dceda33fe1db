"""Modelling test helpers (a module of its own: `conftest` is taken by tests/review, whose tests import it by name):
a modelling server on a free localhost port, and rings to draw lobes from."""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np

from farm.modelling.server import create_model_app
from farm.modelling.service import ModelService
from farm.token_server import TokenServer, new_token


def ring(z: float, radius: float, n: int = 40) -> np.ndarray:
    """(n + 1, 3) a closed horizontal circle at height z (Z up), its last point on its first."""
    t = np.linspace(0, 2 * np.pi, n + 1)
    return np.c_[radius * np.cos(t), radius * np.sin(t), np.full(n + 1, z)]


@contextmanager
def model_server(out=None, library=None, tls=None):
    """A modelling server on a free localhost port: yields (base URL, token, service)."""
    token = new_token()
    service = ModelService(out, library)
    server = TokenServer(create_model_app(service, token), "127.0.0.1", 0, tls=tls).start()
    try:
        yield server.base, token, service
    finally:
        server.stop()
