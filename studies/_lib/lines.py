"""Where the ADE-lines study (``studies/ade_branches.py``) keeps each line it follows: the
name of the line's point in its sweep (its folder under ``OUT/ade_branches/sweep/points``),
by which the nonaxisymmetric study finds the lines it revolves into 3D."""


def line_name(v: float, name: str) -> str:
    """A line's point in the sweep (its folder's name)."""
    return f"v={v:g}_{name}"
