"""Settings of the contract suite.

``CONTRACT_EXAMPLES`` seeds are drawn per property and entry: 2 by default (the
``ci`` profile, well under the 90 s budget), 25 under ``HYPOTHESIS_PROFILE=thorough``.
``tests/conftest.py`` loads the hypothesis profile named by ``HYPOTHESIS_PROFILE``
and registers ``thorough`` beside ``ci``.
"""

from __future__ import annotations

import os

CONTRACT_EXAMPLES = 25 if os.environ.get("HYPOTHESIS_PROFILE") == "thorough" else 2
