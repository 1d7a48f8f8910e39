"""``python -m growjax.cli``: the command line."""

import sys

from growjax.cli import main

sys.exit(main())
