"""``python -m ckesc`` is the ``ckesc`` command."""

import sys

from .cli import main

sys.exit(main())
