"""The architecture's promises (issue 9): a backend-blind loop and run folder, one registry that
the backends and the CLI agree with, consistent directly built backends, parameters that
re-derive what they derived."""

import ast
import inspect
from pathlib import Path

import pytest

from fem_ade.backend import backend_class
from fem_ade.model import Params
from fem_ade.registry import BACKENDS, CONSTRAINTS, SCHEMES
from fem_ade.run import build_parser

PACKAGE = Path(__file__).resolve().parents[1] / "fem_ade"


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            out.add(("." * node.level) + (node.module or ""))
        elif isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
    return out


@pytest.mark.parametrize("module", ["loop.py", "runs.py"])
def test_loop_and_run_folder_know_no_backend(module):
    imports = _imports(PACKAGE / module)
    assert not any(m.startswith((".fem", "fem_ade.fem", "spectral_ref")) for m in imports), imports
    source = (PACKAGE / module).read_text()
    for option in {o.name for spec in BACKENDS.values() for o in spec.options}:
        assert f'"{option}"' not in source, f"{module} reads the backend option {option!r}"


@pytest.mark.parametrize("name", list(BACKENDS))
def test_registry_matches_the_backend_classes(name):
    cls = backend_class(name)
    assert cls.name == name
    accepted = inspect.signature(cls.__init__).parameters
    for option in BACKENDS[name].options:
        assert option.name in accepted, f"{name} does not take its option {option.name!r}"
        assert accepted[option.name].default == option.default


def test_cli_choices_come_from_the_registry():
    actions = {a.dest: a for a in build_parser().options}
    assert tuple(actions["backend"].choices) == tuple(BACKENDS)
    assert tuple(actions["scheme"].choices) == tuple(SCHEMES)
    assert tuple(actions["constraints"].choices) == tuple(CONSTRAINTS)
    for spec in BACKENDS.values():
        for o in spec.options:
            assert actions[o.name].choices == o.choices


def test_params_rederive_what_they_derived():
    p = Params(eps=0.04, alpha=0.03, beta=0.5)
    q = p.with_(eps=0.02, beta=0.4)
    assert q.D == pytest.approx(2 * 0.02 / 3) and q.A0 == 0.4
    r = Params(eps=0.04, alpha=0.03, beta=0.5, D=0.01, A0=0.7).with_(eps=0.02, beta=0.4)
    assert r.D == 0.01 and r.A0 == 0.7  # given, not derived: kept
    assert p.for_constraints("exact").effects == p.effects - {"volume", "area"}
    assert p.for_constraints("penalty") is p


def test_readme_and_ci_run_the_same_tests():
    """The README's second set-up command ends with the test command that .ci/run runs."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    readme = (root / "README.md").read_text().splitlines()
    commands = [line.strip() for line in readme[:12] if line.startswith("    python3 -m venv")]
    assert len(commands) == 2, commands
    test_command = commands[1].split("&&")[-1].strip()
    ci = [line.strip() for line in (root / ".ci" / "run").read_text().splitlines()
          if "-m pytest" in line and not line.lstrip().startswith("#")]
    assert ci == [test_command], (ci, test_command)
    assert "fem_ade.run torus" in commands[0]


def _module_graph() -> dict[str, set[str]]:
    """Every module of fem_ade, spectral_ref and sharp_ref → the modules of the three it
    imports, at the top or inside a function (a lazy import is still a dependency)."""
    root = PACKAGE.parent
    files = {}
    for pkg in ("fem_ade", "spectral_ref", "sharp_ref"):
        for path in (root / pkg).rglob("*.py"):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            files[".".join(parts)] = path
    graph = {}
    for name, path in files.items():
        is_pkg = path.name == "__init__.py"
        base = name.split(".") if is_pkg else name.split(".")[:-1]
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            targets = []
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    head = base[: len(base) - node.level + 1]
                    mod = ".".join(head + ([node.module] if node.module else []))
                else:
                    mod = node.module or ""
                subs = [f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in files]
                targets = subs or [mod]  # `from . import sub` needs sub, not the package
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            deps.update(t for t in targets if t in files and t != name)
        graph[name] = deps
    return graph


def test_no_import_circles():
    """No module reaches itself through imports (lazy ones included): each layer stands on
    the ones below it."""
    graph = _module_graph()
    state, stack, cycles = {}, [], []

    def visit(node):
        state[node] = "open"
        stack.append(node)
        for dep in sorted(graph[node]):
            if state.get(dep) == "open":
                cycles.append(stack[stack.index(dep):] + [dep])
            elif dep not in state:
                visit(dep)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node)
    assert not cycles, "import circles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_spectral_reference_shares_no_physics():
    """spectral_ref imports from fem_ade only what holds no physics (the backend base, the
    targets' ramp, output helpers, the thread settings), so that an error in the FEM's
    physics cannot hide in a comparison with it."""
    graph = _module_graph()
    allowed = {"fem_ade.backend", "fem_ade.xdmf", "fem_ade.model", "fem_ade.constraints",
               "fem_ade.threads"}
    used = {d for d in graph["spectral_ref.solver"] if d.startswith("fem_ade")}
    assert used <= allowed, used
    source = (PACKAGE.parent / "spectral_ref" / "solver.py").read_text()
    imported = {a.name for node in ast.walk(ast.parse(source))
                if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fem_ade")
                for a in node.names}
    assert imported <= {"BackendBase", "fft_workers", "ModelError", "ConstraintError",
                        "closed_grid_values", "grid_mesh"}, imported


def test_sharp_reference_imports_nothing_of_the_phase_field():
    """sharp_ref (the axisymmetric sharp membrane) stands on numpy and scipy alone: nothing
    of fem_ade or spectral_ref, lazily or not."""
    graph = _module_graph()
    mods = [m for m in graph if m.startswith("sharp_ref")]
    assert len(mods) >= 3, mods
    used = {d for m in mods for d in graph[m] if not d.startswith("sharp_ref")}
    assert not used, used
    for m in mods:
        path = PACKAGE.parent / (m.replace(".", "/") + ".py")
        if not path.is_file():
            path = PACKAGE.parent / m.replace(".", "/") / "__init__.py"
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and not node.level:
                assert node.module.split(".")[0] in {"numpy", "scipy", "__future__", "math",
                                                      "argparse", "json", "sys", "dataclasses",
                                                      "warnings", "threadpoolctl"}, (m, node.module)
            elif isinstance(node, ast.Import):
                for a in node.names:
                    assert a.name.split(".")[0] in {"numpy", "scipy", "math", "argparse",
                                                    "json", "sys", "warnings", "signal",
                                                    "threadpoolctl"}, (m, a.name)


def test_one_definition_of_the_run_status():
    """How a run ended is fem_ade.status's Status; which statuses count as ended or as having
    a result is defined there only (the sweep, its plots and the gallery once had three
    different 'finished' sets)."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    names = ("completed", "steady", "max_steps", "diverged", "interrupted")
    one = "(" + "|".join(names) + ")"
    together = re.compile(r'[(\[{]\s*"' + one + r'"\s*,\s*"' + one + '"')
    found = [f"{p.relative_to(root)}:{text.count(chr(10), 0, m.start()) + 1}"
             for p in [*(root / "fem_ade").rglob("*.py"), *(root / "studies").rglob("*.py")]
             if p.name != "status.py"
             for text in [p.read_text()] for m in together.finditer(text)]
    assert not found, found


#: functions of more than LONG lines of code (docstring not counted) in fem_ade/ and studies/,
#: with the reason each is not split, or "debt" where there is none yet: the list may only
#: shrink, and none of them grow
LONG = 60
LONG_FUNCTIONS = {
    "fem_ade/loop.py:run_loop": (103, "the loop: one place where a step's outcome (accept, "
                                      "retry, diverge, stop, interrupt) is decided"),
    "fem_ade/run.py:build_parser": (96, "argparse: one option per statement"),
    "fem_ade/sweep.py:load_sweep": (65, "each mistake in a sweep file: its one-line error"),
    "fem_ade/scenes.py:scene_from_mapping": (72, "each mistake in a TOML scene: its error"),
    "studies/sharp_limit.py:eps_figures": (68, "a matplotlib figure, panel by panel"),
    "fem_ade/render.py:render_history": (68, "a matplotlib figure, panel by panel"),
    "fem_ade/sweep_plot.py:phase_diagram": (65, "a matplotlib figure, layer by layer"),
    "fem_ade/fem/petsc.py:__init__": (62, "the distributed set-up, in PETSc's order"),
}


def test_functions_are_short_or_say_why():
    """No function of fem_ade/ or studies/ is longer than LONG lines of code unless it is
    listed in LONG_FUNCTIONS with its reason; a listed one does not grow."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    found = {}
    for p in [*(root / "fem_ade").rglob("*.py"), *(root / "studies").rglob("*.py")]:
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                first = node.body[0]
                doc = (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                       and isinstance(first.value.value, str))
                start = first.end_lineno + 1 if doc else node.lineno
                length = node.end_lineno - start + 1
                if length > LONG:
                    found[f"{p.relative_to(root)}:{node.name}"] = length
    new = {k: v for k, v in found.items() if k not in LONG_FUNCTIONS}
    assert not new, f"longer than {LONG} lines, not listed with a reason: {new}"
    grown = {k: (v, LONG_FUNCTIONS[k][0]) for k, v in found.items() if v > LONG_FUNCTIONS[k][0]}
    assert not grown, f"grew (now, listed): {grown}"
