"""Shared fixtures: the real data sets in ``../shared/data`` (skipped when absent)."""

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Root of ``../shared/data``; tests that need it skip with a message when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (clone with ../shared beside the repo)")
    return SHARED_DATA


@pytest.fixture(scope="session", autouse=True)
def _render_cache(tmp_path_factory):
    """Renders made by tests go to a temporary cache, never the user's ``~/.cache/studio``
    (set in the environment so subprocesses inherit it)."""
    import os

    previous = os.environ.get("STUDIO_CACHE")
    os.environ["STUDIO_CACHE"] = str(tmp_path_factory.mktemp("studio-cache"))
    yield
    if previous is None:
        os.environ.pop("STUDIO_CACHE", None)
    else:
        os.environ["STUDIO_CACHE"] = previous
