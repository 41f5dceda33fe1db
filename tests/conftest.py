"""Fixtures shared by every test package: one local Ray for the whole test run (started on first use)."""
from __future__ import annotations

import os

import pytest


@pytest.fixture(scope="session")
def ray_session():
    """A local Ray (2 CPUs, no dashboard, small object store), shut down at the end of the test run."""
    import ray

    # Ray Train's controller polls its workers every 2 s by default, and each state change of a run waits for a
    # poll: a tenth of that takes seconds off each tiny training run in the tests.
    os.environ.setdefault("RAY_TRAIN_HEALTH_CHECK_INTERVAL_S", "0.2")
    if not ray.is_initialized():
        ray.init(address="local", num_cpus=2, include_dashboard=False, object_store_memory=100 * 2**20,
                 logging_level="WARNING", runtime_env={"env_vars": {"PYOPENGL_PLATFORM": "egl"}})
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def chromium_browser():
    """Headless Chromium for one test module (playwright's sync API runs one browser at a time); the module is
    skipped (failed with CI=true) where chromium is not installed."""
    import shutil

    from required_tools import missing_tool

    if shutil.which("chromium") is None:
        missing_tool("chromium is not installed: run `make browser-env`")
    from playwright import sync_api

    from farm.review.browser import launch_chromium

    with sync_api.sync_playwright() as playwright:
        browser = launch_chromium(playwright)
        yield browser
        browser.close()
