"""``python -m diathermy`` runs the command line."""

from diathermy.cli import main

raise SystemExit(main())
