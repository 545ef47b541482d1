"""``python -m mjcodesign.cli``: the ``mjcodesign`` command."""

import sys

from mjcodesign.cli.main import main

sys.exit(main())
