"""``python -m cli`` runs the ``physanim`` command."""

from cli.app import main

main()
