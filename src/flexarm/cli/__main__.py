"""``python -m flexarm.cli``."""

from flexarm.cli import main

main()
