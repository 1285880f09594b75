"""``python -m physanim`` runs the CLI."""

from physanim.cli import main

main()
