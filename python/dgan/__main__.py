"""``python -m dgan``."""

from dgan.cli import main

raise SystemExit(main())
