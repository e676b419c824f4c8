"""``python -m services.node NAME ...``: run one node (see :mod:`services.node.cli`)."""

import sys

from services.node.cli import main

sys.exit(main())
