"""``python -m gateway.cli``: the ``dji-gateway`` console script without the installed script.

Owns nothing but the hand-over to :func:`gateway.cli.main`.
"""

from __future__ import annotations

import sys

from gateway.cli import main

sys.exit(main())
