"""``python -m fem_ade.switch``: from a bifurcation of an axisymmetric branch to its 3D state
(:mod:`fem_ade.campaigns.switch`, where the code is)."""

import sys

from fem_ade.campaigns.switch import main

if __name__ == "__main__":
    sys.exit(main())
