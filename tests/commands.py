"""Run the ``physanim`` command as a user does: from the repository root, relative paths."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The toy DAG as the CLI addresses it
TOY = "tests.foundation.toy_stages:TOY"


def physanim_env(**extra: str) -> dict[str, str]:
    """The environment of a CLI run: this one without PREFECT_* settings, plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PREFECT_")}
    return {**env, "PYTHONPATH": str(ROOT), **extra}


def physanim(
    *args: str, timeout: float = 600, env: dict[str, str] | None = None, **popen
) -> subprocess.CompletedProcess[str]:
    """``physanim ARGS`` run in the repository root; stdout and stderr captured (text)."""
    return subprocess.run(
        [sys.executable, "-m", "cli", *args],
        cwd=ROOT,
        env=env or physanim_env(),
        capture_output=True,
        text=True,
        timeout=timeout,
        **popen,
    )


def start(*args: str, env: dict[str, str] | None = None, **popen) -> subprocess.Popen[str]:
    """``physanim ARGS`` started in the background in the repository root (output piped)."""
    return subprocess.Popen(
        [sys.executable, "-m", "cli", *args],
        cwd=ROOT,
        env=env or physanim_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        **popen,
    )


def invoke(*args: str) -> subprocess.CompletedProcess[str]:
    """``physanim ARGS`` in this process (no interpreter start: fast), from the repository
    root; returns what ``physanim`` would.  Errors the CLI does not turn into a message
    propagate."""
    from typer.testing import CliRunner

    from cli.app import app

    cwd = os.getcwd()
    os.chdir(ROOT)
    try:
        result = CliRunner().invoke(app, list(args))
    finally:
        os.chdir(cwd)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return subprocess.CompletedProcess(list(args), result.exit_code, result.stdout, result.stderr)
