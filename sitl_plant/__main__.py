"""``python -m sitl_plant``: the same as the ``sitl-plant`` console script."""

import sys

from .cli import main

sys.exit(main())
