"""``python -m optmodels``: the same as the ``optmodels`` console script."""

from optmodels.cli import main

raise SystemExit(main())
