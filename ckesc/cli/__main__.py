"""``python -m ckesc.cli`` is the ``ckesc`` command (as ``python -m ckesc`` is)."""

import sys

from . import main

sys.exit(main())
