"""Entry point: ``python -m vpp_service``."""

import sys

from vpp_service.cli import main

sys.exit(main())
