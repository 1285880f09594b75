"""The real face (pymeshlab's face000 scan in the actor frame), built once per session."""

from __future__ import annotations

import pytest

from physanim.capture.actor import Actor, build_actor


@pytest.fixture(scope="session")
def actor() -> Actor:
    """Neutral actor mesh: (N, 3) m vertices, +x actor's left, +y up, +z out of the face."""
    return build_actor()
