"""``python -m bench.suite``: the speed-against-accuracy benchmark (``rig bench``)."""

from __future__ import annotations

from bench.suite import main

raise SystemExit(main())
