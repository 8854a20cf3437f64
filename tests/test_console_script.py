"""``fem-ade COMMAND`` is ``python -m fem_ade.COMMAND`` (issue 41): the same output and exit
codes, for every command, in process and as the installed console script."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fem_ade.cli.main import COMMANDS, main


def _script():
    found = Path(sys.executable).with_name("fem-ade")
    return str(found) if found.exists() else shutil.which("fem-ade")


def test_every_command_is_a_python_m_entry_module():
    root = Path(__file__).resolve().parents[1] / "fem_ade"
    assert set(COMMANDS) == {"run", "sweep", "branch", "render", "stability",
                             "switch"}
    for name, module in COMMANDS.items():
        assert f"from {module} import main" in (root / f"{name}.py").read_text()


def test_help_and_unknown_command(capsys):
    assert main(["--help"]) == 0 and "fem-ade {run,sweep,branch,render,stability,switch}" in \
        capsys.readouterr().out
    assert main([]) == 2
    assert main(["simulate"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fem-ade: unknown command 'simulate'"), err


@pytest.mark.parametrize("args", [["run", "--list"], ["stability", "/nonexistent/folder"],
                                  ["render", "/nonexistent/folder"]])
def test_the_console_script_is_the_module(args):
    script = _script()
    if script is None:
        pytest.skip("fem-ade is not installed (pip install -e . installs it)")
    a = subprocess.run([script, *args], capture_output=True, text=True, timeout=120)
    b = subprocess.run([sys.executable, "-m", f"fem_ade.{args[0]}", *args[1:]],
                       capture_output=True, text=True, timeout=120)
    assert (a.returncode, a.stdout, a.stderr) == (b.returncode, b.stdout, b.stderr)
    assert a.returncode == (0 if args[1] == "--list" else 2)
