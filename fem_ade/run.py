"""``python -m fem_ade.run``: the command line of one run (:mod:`fem_ade.cli.run`, where the code
is)."""

import sys

from fem_ade.cli.run import main

if __name__ == "__main__":
    sys.exit(main())
