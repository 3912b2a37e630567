"""``python -m wsp_env.cli``: the ``wsp-env`` console script."""

import sys

from wsp_env.cli import main

sys.exit(main())
