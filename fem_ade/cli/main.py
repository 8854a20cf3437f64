"""``fem-ade COMMAND ...``: one console script for every command, the same as
``python -m fem_ade.COMMAND ...`` (run, sweep, branch, render, stability, switch)."""

from __future__ import annotations

import importlib
import sys

#: command -> the module whose ``main(argv)`` runs it
COMMANDS = {
    "run": "fem_ade.cli.run",
    "sweep": "fem_ade.campaigns.sweep",
    "branch": "fem_ade.campaigns.branch",
    "render": "fem_ade.plots.render",
    "stability": "fem_ade.campaigns.stability",
    "switch": "fem_ade.cli.switch",
}

USAGE = "usage: fem-ade {" + ",".join(COMMANDS) + "} ...   (fem-ade COMMAND --help for its options)"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if not args or args[0] in {"-h", "--help"}:
        print(USAGE)
        return 0 if args else 2
    if args[0] not in COMMANDS:
        print(f"fem-ade: unknown command {args[0]!r}\n{USAGE}", file=sys.stderr)
        return 2
    return importlib.import_module(COMMANDS[args[0]]).main(args[1:])


if __name__ == "__main__":
    sys.exit(main())
