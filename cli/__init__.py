"""The ``physanim`` command line: the application layer above ``flows/`` and ``tasks/``.

The library (``physanim/``) never imports this package or ``flows/``; the commands load the
DAG declarations from ``flows.dags`` and run plans through the executors (``physanim``'s
local one, ``flows.executors``' Prefect and Dask ones). ``python -m cli`` runs it.
"""
