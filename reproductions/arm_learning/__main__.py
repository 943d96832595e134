"""``python -m reproductions.arm_learning``: :func:`reproductions.arm_learning.cli.main`."""

from reproductions.arm_learning.cli import main

raise SystemExit(main())
