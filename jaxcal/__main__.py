"""`python -m jaxcal`: the command line, as the `jaxcal` script."""

import sys

from ._cli import main

sys.exit(main())
