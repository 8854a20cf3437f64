"""The architecture's promises (issues 9 and 41): subpackages that are layers and import only
downward, a backend-blind loop and run folder, one registry that the backends and the CLI agree
with, consistent directly built backends, parameters that re-derive what they derived."""

import ast
import inspect
import re
from pathlib import Path

import pytest

from fem_ade.backends.base import backend_class
from fem_ade.cli.run import build_parser
from fem_ade.model.params import Params
from fem_ade.registry import BACKENDS, CONSTRAINTS, SCHEMES

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


@pytest.mark.parametrize("module", ["engine/loop.py", "engine/trackers.py", "engine/runs.py",
                                    "engine/folder.py", "engine/execute.py"])
def test_loop_and_run_folder_know_no_backend(module):
    imports = _imports(PACKAGE / module)
    assert not any(m.startswith(("fem_ade.backends.fem", "spectral_ref")) for m in imports), imports
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


def _module_files(packages=("fem_ade", "spectral_ref", "sharp_ref")) -> dict[str, Path]:
    """Each module's dotted name → its file, in ``packages`` (a package is its __init__)."""
    root = PACKAGE.parent
    files = {}
    for pkg in packages:
        for path in sorted((root / pkg).rglob("*.py")):
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            files[".".join(parts)] = path
    return files


def _module_graph() -> dict[str, set[str]]:
    """Every module of fem_ade, spectral_ref and sharp_ref → the modules of the three it
    imports, at the top or inside a function (a lazy import is still a dependency)."""
    files = _module_files()
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


#: fem_ade's subpackages, lowest first: a module imports only from its own layer and the ones
#: below it (docs/architecture.md, "The layers"); the top-level ``fem_ade`` package (its
#: ``__version__`` and lazy names) and the five ``python -m fem_ade.COMMAND`` entry modules
#: stand above them all
LAYERS = ("registry", "model", "analysis", "scenes", "store", "backends", "plots", "engine",
          "campaigns", "cli")
#: the layers that know no backend: what they need of one goes through
#: fem_ade.backends.base (the protocol and the registry's lookup)
BACKEND_BLIND = ("model", "analysis", "scenes", "store", "engine")


def _layer(module: str) -> int | None:
    """The index of a fem_ade module's layer in LAYERS (the top: len(LAYERS)); None outside."""
    parts = module.split(".")
    if parts[0] != "fem_ade":
        return None
    if len(parts) > 1 and parts[1] in LAYERS:
        return LAYERS.index(parts[1])
    return len(LAYERS)


def test_the_folder_tree_is_the_layers():
    """Every module of fem_ade lives in one of LAYERS' subpackages, except the package itself,
    the registry and the five command entry modules, which only call their layer's main."""
    top = {p.stem for p in PACKAGE.glob("*.py")}
    assert top == {"__init__", "registry", "run", "sweep", "branch", "render", "stability",
                   "switch"}, top
    dirs = {p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert dirs == set(LAYERS) - {"registry"}, dirs
    for name in ("run", "sweep", "branch", "render", "stability", "switch"):
        tree = ast.parse((PACKAGE / f"{name}.py").read_text())
        defs = [n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))]
        assert not defs, f"fem_ade/{name}.py is an entry module: it defines nothing"


def _layer_violations(graph: dict[str, set[str]]) -> tuple[list[str], list[str]]:
    """(imports upward, backend imports in a backend-blind layer) of a module graph."""
    up, blind = [], []
    for mod, deps in graph.items():
        here = _layer(mod)
        if here is None or here == len(LAYERS):
            continue
        for dep in deps:
            there = _layer(dep)
            if dep != "fem_ade" and there is not None and there > here:
                up.append(f"{mod} -> {dep}")
            if LAYERS[here] in BACKEND_BLIND and dep.startswith(
                    ("fem_ade.backends.fem", "spectral_ref")):
                blind.append(f"{mod} -> {dep}")
    return sorted(up), sorted(blind)


def test_layers_import_only_downward():
    """A module imports from its own layer or a lower one (lazy imports included), and the
    backend-blind layers never import the FEM backend (or the spectral one)."""
    up, blind = _layer_violations(_module_graph())
    assert not up, "imports upward: " + "; ".join(up)
    assert not blind, "a backend-blind layer imports a backend: " + "; ".join(blind)


def test_a_layer_violation_is_caught():
    """The two leaks this move removed, put back, are caught: analysis.axishape reading a
    saved field through the FEM's tensor space, and a store module calling the engine."""
    graph = _module_graph()
    graph["fem_ade.analysis.axishape"] |= {"fem_ade.backends.fem.tensor"}
    graph["fem_ade.store.output"] |= {"fem_ade.engine.runs"}
    up, blind = _layer_violations(graph)
    assert up == ["fem_ade.analysis.axishape -> fem_ade.backends.fem.tensor",
                  "fem_ade.store.output -> fem_ade.engine.runs"], up
    assert blind == ["fem_ade.analysis.axishape -> fem_ade.backends.fem.tensor"], blind


def _private_imports(source: str, module: str) -> list[str]:
    """``from fem_ade.X import _name`` in ``source`` (of ``module``) where X is another module:
    a name private to one module used by another."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ImportFrom) and not node.level \
                and (node.module or "").startswith("fem_ade") and node.module != module:
            out += [f"{module} <- {node.module}.{a.name}" for a in node.names
                    if a.name.startswith("_") and not a.name.startswith("__")]
    return out


def test_no_module_imports_anothers_private_names():
    """What one module uses of another is public there (the global dot product, a folder's
    identity difference, the JSON conversion were imported by their private names); and a
    private import put back is caught."""
    found = [leak for module, path in _module_files(("fem_ade",)).items()
             for leak in _private_imports(path.read_text(), module)]
    assert found == [], found
    leak = "def f():\n    from fem_ade.backends.fem.solve import _ALLREDUCE\n"
    assert _private_imports(leak, "fem_ade.backends.fem.newton") == [
        "fem_ade.backends.fem.newton <- fem_ade.backends.fem.solve._ALLREDUCE"]


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
    allowed = {"fem_ade.backends.base", "fem_ade.store.xdmf", "fem_ade.model.params",
               "fem_ade.model.constraints", "fem_ade.backends.threads"}
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
    """How a run ended is fem_ade.store.status's Status; which statuses count as ended or as having
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
    "fem_ade/engine/loop.py:run_loop": (103, "the loop: one place where a step's outcome "
                                             "(accept, retry, diverge, stop, interrupt)"),
    "fem_ade/cli/run.py:build_parser": (96, "argparse: one option per statement"),
    "fem_ade/campaigns/sweep_file.py:load_sweep": (65, "each mistake in a sweep file: its error"),
    "fem_ade/scenes/catalogue.py:scene_from_mapping": (72, "each mistake in a TOML scene"),
    "studies/_lib/limit_eps.py:eps_figures": (68, "a matplotlib figure, panel by panel"),
    "fem_ade/plots/history.py:render_history": (68, "a matplotlib figure, panel by panel"),
    "fem_ade/plots/sweep_plot.py:phase_diagram": (65, "a matplotlib figure, layer by layer"),
    "fem_ade/backends/fem/petsc.py:__init__": (62, "the distributed set-up, in PETSc's order"),
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


# -- a physics term: one record per backend, and a recipe that lists every file it touches ------
#: the ADE term's names in code: its scalar parts, its weak forms and spectral functions, its
#: records, its third implementation (``\b``: ``reduced_area_difference`` is another thing)
ADE_NAMES = re.compile(r"\b(ade_energy|ade_modulus|ade_force_coefficient|area_difference"
                       r"(?:_gradient(?:_linear)?)?|AreaDifference(?:Term)?|NaiveADE)\b")
#: files every term touches that name no code of the ADE term, and why
UNNAMED = {"docs/model.md": "the maths of every term (§2–§5, §9), without code names",
           "tests/test_newton.py": "its cases switch the effects on by name, with parameters"}
RECIPE = "## How to add a physics term, end to end"


def _files_naming_the_ade_term(root: Path) -> set[str]:
    """The repository's source and documentation files (fem_ade, spectral_ref, sharp_ref,
    tests, the studies' scripts, docs, README.md) that name the ADE term in code, this file
    aside (it spells the names to look for)."""
    paths = [*(root / "fem_ade").rglob("*.py"), *(root / "spectral_ref").rglob("*.py"),
             *(root / "sharp_ref").rglob("*.py"), *(root / "tests").glob("*.py"),
             *(root / "studies").glob("*.py"), *(root / "docs").glob("*.md"), root / "README.md"]
    return {str(p.relative_to(root)) for p in paths
            if p.name != Path(__file__).name and ADE_NAMES.search(p.read_text())}


def _recipe_tables(text: str) -> dict[str, list[str]]:
    """The recipe's tables of files by their ``###`` heading: the backticked path that opens
    each row."""
    section = text[text.index(RECIPE) + len(RECIPE):]
    section = section[:section.find("\n## ")] if "\n## " in section else section
    tables, heading = {}, None
    for line in section.splitlines():
        if line.startswith("### "):
            heading = line[4:].strip()
            tables[heading] = []
        elif heading and (m := re.match(r"\|\s*`([\w./-]+\.\w+)`\s*\|", line)):
            tables[heading].append(m.group(1))
    return tables


def _recipe_mismatch(listed, found) -> tuple[set[str], set[str]]:
    """(files a term touches that the recipe misses, files it lists that no term touches)."""
    return set(found) - set(listed), set(listed) - set(found)


def test_the_recipe_lists_every_file_a_term_touches():
    """docs/architecture.md's recipe lists exactly the files that name the ADE term in code,
    plus UNNAMED; every file it names (in both of its tables) exists."""
    root = PACKAGE.parent
    tables = _recipe_tables((root / "docs" / "architecture.md").read_text())
    every = tables["Every file a term touches"]
    assert len(every) == len(set(every)), every
    found = _files_naming_the_ade_term(root) | set(UNNAMED)
    missed, extra = _recipe_mismatch(every, found)
    assert not missed, f"the recipe misses {sorted(missed)}"
    assert not extra, f"the recipe lists files that name no term: {sorted(extra)}"
    for path in every + tables["Files some terms touch"]:
        assert (root / path).is_file(), path


def test_a_recipe_that_misses_a_file_fails(tmp_path):
    """The control: a file dropped from the recipe's list is caught, and so is a file that
    starts to name the ADE term (the scan sees it)."""
    root = PACKAGE.parent
    every = _recipe_tables((root / "docs" / "architecture.md").read_text())[
        "Every file a term touches"]
    found = _files_naming_the_ade_term(root) | set(UNNAMED)
    assert _recipe_mismatch(every[1:], found) == ({every[0]}, set())
    for sub in ("fem_ade", "spectral_ref", "sharp_ref", "tests", "studies", "docs"):
        (tmp_path / sub).mkdir()
    (tmp_path / "README.md").write_text("no term here")
    (tmp_path / "fem_ade" / "new.py").write_text("G = p.ade_energy(dA)\n")
    (tmp_path / "fem_ade" / "shape.py").write_text("x = reduced_area_difference(dA, A, D)\n")
    assert _files_naming_the_ade_term(tmp_path) == {"fem_ade/new.py"}


def test_each_backend_has_a_record_of_every_global_term():
    """The model's TERMS, the FEM's records and the spectral reference's (written apart) name
    the same terms, in the same order, with the same functionals."""
    import spectral_ref.solver as spectral
    from fem_ade.backends.fem.terms import GLOBAL_TERMS
    from fem_ade.model.params import HISTORY_COLUMNS, TERMS

    model = [(t.effect, t.functional, t.penalty) for t in TERMS]
    assert [(t.effect, t.functional, t.model.penalty) for t in GLOBAL_TERMS] == model
    assert [(t.effect, t.key, t.penalty) for t in spectral.TERMS] == model
    assert HISTORY_COLUMNS == ("step", "t", "E", "W", "G", "V", "A", "dA")


#: modules of more than LONG_MODULE lines in fem_ade/, spectral_ref/, sharp_ref/ and studies/
#: (its _lib and teaching/ too; studies/results holds outputs), each with the one-sentence
#: reason it is not split, or "split pending" where there is none yet: the list may only
#: shrink, and a module that is no longer long must leave it (issue 41)
LONG_MODULE = 600
LONG_MODULES = {
    "studies/gallery.py": "one study's catalogue of cases (thirteen scenes x the variants x "
                          "two backends) with the plan, archive, verdicts and report that "
                          "read only it (its docstring)",
    "studies/constraints_study.py": "one study's cases (three scenes x four ways of holding V "
                                    "and A) through every step they take, none of which "
                                    "another study uses (its docstring)",
}


def _module_lengths(root: Path) -> dict[str, int]:
    """Each module's lines, by its path from ``root``, in the folders LONG_MODULES covers."""
    paths = [p for top in ("fem_ade", "spectral_ref", "sharp_ref", "studies")
             for p in (root / top).rglob("*.py")
             if not p.relative_to(root).as_posix().startswith("studies/results/")]
    return {p.relative_to(root).as_posix(): len(p.read_text().splitlines())
            for p in sorted(paths)}


def _long_module_faults(lengths: dict[str, int], listed: dict[str, str]) -> list[str]:
    """What breaks the rule: a long module not listed, a listed one that is not long (or
    gone), a reason that is not one sentence."""
    faults = [f"{m}: {n} lines, not in LONG_MODULES" for m, n in lengths.items()
              if n > LONG_MODULE and m not in listed]
    faults += [f"{m}: listed but {lengths.get(m, 'no')} lines: remove it from LONG_MODULES"
               for m in listed if lengths.get(m, 0) <= LONG_MODULE]
    faults += [f"{m}: its reason is not one sentence" for m, why in listed.items()
               if not why or ". " in why.rstrip(".")]
    return faults


def test_modules_are_short_or_say_why():
    """No module is longer than LONG_MODULE lines unless LONG_MODULES gives its reason, and
    every module listed there is still that long (so that the list cannot rot)."""
    assert _long_module_faults(_module_lengths(PACKAGE.parent), LONG_MODULES) == []


def test_a_long_module_not_listed_is_caught(tmp_path):
    """The control: in a tree of its own, an over-long module not listed, a listed one
    that shrank, and one under studies/results (outputs, not counted)."""
    for path, lines in {"fem_ade/big.py": LONG_MODULE + 1, "fem_ade/small.py": LONG_MODULE,
                        "studies/_lib/ok.py": 10,
                        "studies/results/made.py": 2 * LONG_MODULE}.items():
        (tmp_path / path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / path).write_text("x = 1\n" * lines)
    lengths = _module_lengths(tmp_path)
    assert lengths == {"fem_ade/big.py": LONG_MODULE + 1, "fem_ade/small.py": LONG_MODULE,
                       "studies/_lib/ok.py": 10}
    faults = _long_module_faults(lengths, {"fem_ade/small.py": "it was long"})
    assert faults == [f"fem_ade/big.py: {LONG_MODULE + 1} lines, not in LONG_MODULES",
                      f"fem_ade/small.py: listed but {LONG_MODULE} lines: remove it from "
                      "LONG_MODULES"], faults
    assert _long_module_faults({"fem_ade/big.py": LONG_MODULE + 1},
                               {"fem_ade/big.py": "one. two"}) == [
        "fem_ade/big.py: its reason is not one sentence"]
