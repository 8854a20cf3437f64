"""``python -m fem_ade.branch``: branches by continuation (:mod:`fem_ade.campaigns.branch`, where
the code is)."""

import sys

from fem_ade.campaigns.branch import main

if __name__ == "__main__":
    sys.exit(main())
