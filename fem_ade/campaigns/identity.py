"""What a branch folder's ``branch.json`` says the branch is — its identity — read in the
current format whichever fem_ade wrote it: the one place that knows how older branch folders
counted ``n`` (:mod:`fem_ade.campaigns.branch` writes and compares identities; the stability
of a branch point, :mod:`fem_ade.campaigns.stability`, reads one)."""

from __future__ import annotations

import json
from pathlib import Path

from fem_ade.backends.fem.axisym import DEFAULT_ORDER
from fem_ade.engine.config import RUN_FORMAT
from fem_ade.model.params import is_int


def upgraded_identity(stored):
    """A branch.json's identity as the current code writes it: one made before ``format``
    (:data:`fem_ade.engine.config.RUN_FORMAT`) counted ``n`` in cells of order p, n·p
    nodes per L. What is no identity is returned as it is."""
    if not isinstance(stored, dict) or not isinstance(stored.get("options"), dict):
        return stored
    order = stored["options"].get("order", DEFAULT_ORDER)
    if "format" not in stored and is_int(stored.get("n"), 1) and is_int(order, 1):
        stored = {**stored, "n": stored["n"] * order, "format": RUN_FORMAT}
    return stored


def read_identity(folder: str | Path) -> dict:
    """The identity of the branch in ``folder`` (its branch.json, :func:`upgraded_identity`);
    OSError or ValueError where it has none readable."""
    return upgraded_identity(json.loads((Path(folder) / "branch.json").read_text()))


def same_identity(stored, identity: dict) -> bool:
    """Whether a branch.json's identity is ``identity`` (a branch as the current code
    writes it): equal once upgraded, where a folder made before a backend option's default
    was written out (``order``) counts as having that default."""
    stored = upgraded_identity(stored)
    if stored == identity:
        return True
    if not isinstance(stored, dict) or not isinstance(stored.get("options"), dict):
        return False
    filled = {**stored, "options": {"order": DEFAULT_ORDER, **stored["options"]}}
    return filled == identity
