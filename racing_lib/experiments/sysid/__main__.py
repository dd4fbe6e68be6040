"""``python -m racing_lib.experiments.sysid``: regenerate the shipped identified parameters."""

from racing_lib.experiments.sysid.identify import main

raise SystemExit(main())
