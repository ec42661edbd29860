"""Settings of the contract suite.

``CONTRACT_EXAMPLES`` seeds are drawn per property and entry: 2 by default (the
``ci`` profile, well under the 90 s budget), 25 under ``HYPOTHESIS_PROFILE=thorough``.
Note for the coordinator: ``tests/conftest.py`` (i11pkg) loads the profile named by
``HYPOTHESIS_PROFILE``, so it must register ``thorough`` too, e.g.
``settings.register_profile("thorough", max_examples=500, deadline=None)``.
"""

from __future__ import annotations

import os

CONTRACT_EXAMPLES = 25 if os.environ.get("HYPOTHESIS_PROFILE") == "thorough" else 2
