"""The Python blocks of docs/ARCHITECTURE.md run as they are written (each in a fresh
namespace, from the repository root): a worked example that stops working fails here."""

from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import pytest

DOC = Path(__file__).resolve().parents[2] / "docs" / "ARCHITECTURE.md"
BLOCK = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def _blocks() -> list[str]:
    return BLOCK.findall(DOC.read_text())


def test_the_page_has_its_worked_examples() -> None:
    """A stage and a material law: both examples are there (a lost block fails here)."""
    blocks = _blocks()
    assert len(blocks) == 2
    assert "StageSpec.typed" in blocks[0] and "register_law" in blocks[1]


@pytest.mark.parametrize("index", range(len(_blocks())))
def test_block_runs(index: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each block as a module of its own (dataclasses and pydantic resolve names there)."""
    monkeypatch.chdir(DOC.parents[1])
    module = types.ModuleType(f"architecture_doc_{index}")
    monkeypatch.setitem(sys.modules, module.__name__, module)
    code = compile(_blocks()[index], f"{DOC.name} block {index + 1}", "exec")
    exec(code, module.__dict__)
