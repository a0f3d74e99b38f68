"""``python -m hrlsac_cli``: the ``hrlsac`` command without the console script."""
import sys

from hrlsac_cli import main

sys.exit(main())
