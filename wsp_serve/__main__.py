"""`python -m wsp_serve module:callable --port P`: serve a model (see `wsp_serve.server`)."""

import sys

from wsp_serve.server import main

sys.exit(main())
