"""Fixtures shared by every test package: one local Ray for the whole test run (started on first use)."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def ray_session():
    """A local Ray (2 CPUs, no dashboard, small object store), shut down at the end of the test run."""
    import ray

    if not ray.is_initialized():
        ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20,
                 logging_level="WARNING", runtime_env={"env_vars": {"PYOPENGL_PLATFORM": "egl"}})
    yield ray
    ray.shutdown()
