"""Hermetic Prefect settings: call ``configure`` before the first ``import prefect``.

Prefect keeps its profile, SQLite database and logs under ``PREFECT_HOME``; pointing it into the
run directory keeps runs (and tests) away from the user's own Prefect profile.  With no
``PREFECT_API_URL`` every flow run starts a temporary local API server (SQLite), which needs no
network; its startup takes 10-20 s here, so the default 20 s timeout is raised.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: Settings applied unless the user already set them in the environment.
DEFAULTS = {
    "PREFECT_SERVER_ANALYTICS_ENABLED": "false",  # offline: telemetry only logs errors
    "PREFECT_SERVER_EPHEMERAL_STARTUP_TIMEOUT_SECONDS": "120",
    "PREFECT_LOGGING_LEVEL": "WARNING",
    "PREFECT_RESULTS_PERSIST_BY_DEFAULT": "false",  # arrays live in the stage store
    "PREFECT_LOGGING_TO_API_ENABLED": "false",
    "DASK_LOGGING__DISTRIBUTED": "warning",  # Dask's per-worker INFO lines drown the progress
}


def configure(run_dir: Path) -> Path:
    """Set Prefect's home inside ``run_dir`` (unless PREFECT_HOME is set); returns the home."""
    if "prefect" in sys.modules:  # settings are read at import: too late to change them
        return Path(os.environ.get("PREFECT_HOME", "~/.prefect")).expanduser()
    home = Path(os.environ.setdefault("PREFECT_HOME", str(Path(run_dir).resolve() / "prefect")))
    home.mkdir(parents=True, exist_ok=True)
    for k, v in DEFAULTS.items():
        os.environ.setdefault(k, v)
    return home
