"""``python -m hubsgo_ppl.cli``: the ``hubsgo`` command."""

import sys

from .entry import main

sys.exit(main())
