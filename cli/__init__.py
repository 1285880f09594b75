"""The ``physanim`` command line: the application layer above ``flows/`` and ``tasks/``.

The library (``physanim/``) never imports this package or ``flows/``; the commands load the
DAG declarations from ``flows.dags`` and run plans through the executors (``physanim``'s
local one, ``flows.executors``' Prefect and Dask ones). ``python -m cli`` runs it.
"""

import os

#: Environment of the command's processes, set before numpy is imported (numpy reads it once)
#: unless the user set it: no transparent-huge-page advice for numpy's arrays. On the two-core
#: VMs this project is measured on, the huge-page faults of a 2 mm mesh's setup arrays made
#: `simulate` 18.0-21.4 s against 17.9-18.3 s without, the stepping alike.
PROCESS_ENV = {"NUMPY_MADVISE_HUGEPAGE": "0"}
for _name, _value in PROCESS_ENV.items():
    os.environ.setdefault(_name, _value)
