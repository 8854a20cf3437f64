"""``python -m fem_ade.switch``: from a bifurcation of an axisymmetric branch to its 3D state
(:mod:`fem_ade.cli.switch`; the code: :mod:`fem_ade.campaigns.switch`, the flow's run, and
:mod:`fem_ade.campaigns.switch_branch`, the branch followed in 3D)."""

import sys

from fem_ade.cli.switch import main

if __name__ == "__main__":
    sys.exit(main())
