from pathlib import Path

import pytest

from physanim.dynamics import Figure

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.fixture(scope="session")
def arm2() -> Figure:
    return Figure.from_yaml(CONFIGS / "figures" / "arm2.yaml")


@pytest.fixture(scope="session")
def human() -> Figure:
    return Figure.from_yaml(CONFIGS / "figures" / "human30.yaml")
