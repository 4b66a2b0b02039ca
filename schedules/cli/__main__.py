"""``python -m schedules.cli``: the ``compose`` command."""
from schedules.cli.main import main

raise SystemExit(main())
