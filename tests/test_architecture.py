"""The shape of the code base, kept so: small modules, kernels that take records instead of dozens of
loose arrays, no reaching into another module's private names, and the layering of docs/architecture.md."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "finkensim"
SOURCES = sorted(PACKAGE.rglob("*.py"))
MAX_LINES = 500
MAX_PARAMS = 16
#: numba kernels anywhere and every function of the engine (finkensim/swarm/) take a handful of records
#: (docs/architecture.md, "The engine")
MAX_ENGINE_PARAMS = 10


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(), filename=str(path))


def _rel(path: Path) -> str:
    return str(path.relative_to(PACKAGE.parent))


def test_modules_are_small():
    long = {_rel(p): n for p in SOURCES if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines: {long}"


def test_functions_take_at_most_16_parameters():
    wide = []
    for p in SOURCES:
        for node in ast.walk(_tree(p)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                a = node.args
                n = len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)
                if n > MAX_PARAMS:
                    wide.append(f"{_rel(p)}:{node.lineno} {node.name} ({n})")
    assert not wide, f"functions with more than {MAX_PARAMS} parameters: {wide}"


def _n_params(node) -> int:
    a = node.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


#: what compiles a Python function with numba: its decorators, and the package's own wrapper that re-jits one
#: (``kernels/outline.py``)
COMPILERS = {"njit", "jit", "vectorize", "guvectorize", "cfunc", "stencil", "outlined"}


def _callee_name(node) -> str:
    """The bare name a decorator or call refers to: ``njit``, ``numba.njit`` and ``njit(cache=True)`` all give njit."""
    if isinstance(node, ast.Call):
        node = node.func
    if isinstance(node, ast.Attribute):
        return node.attr
    return node.id if isinstance(node, ast.Name) else ""


def _compiled_functions(tree: ast.Module) -> list:
    """Functions numba compiles: decorated with a :data:`COMPILERS` name, or passed by name to one
    (``f_outlined = outlined(f)``, ``njit(cache=True)(f)``)."""
    passed = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and _callee_name(node) in COMPILERS | {""}:
            outer = node.func if isinstance(node.func, ast.Call) else node
            if _callee_name(outer) in COMPILERS:
                passed |= {a.id for a in node.args if isinstance(a, ast.Name)}
    return [node for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and (any(_callee_name(d) in COMPILERS for d in node.decorator_list) or node.name in passed)]


def test_numba_kernels_take_at_most_10_parameters():
    """Every numba-compiled function of the package takes a handful of records and arrays (docs/architecture.md,
    "The engine"), not dozens of loose ones; plain Python API functions with keyword options keep the 16 ceiling."""
    wide = []
    found = 0
    for p in SOURCES:
        for node in _compiled_functions(_tree(p)):
            found += 1
            if (n := _n_params(node)) > MAX_ENGINE_PARAMS:
                wide.append(f"{_rel(p)}:{node.lineno} {node.name} ({n})")
    assert found > 100, f"only {found} compiled functions found: the detection of numba decorators broke"
    assert not wide, f"numba kernels with more than {MAX_ENGINE_PARAMS} parameters: {wide}"


def test_engine_functions_take_at_most_10_parameters():
    wide = []
    for p in sorted((PACKAGE / "swarm").glob("*.py")):
        for node in ast.walk(_tree(p)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                if (n := _n_params(node)) > MAX_ENGINE_PARAMS:
                    wide.append(f"{_rel(p)}:{node.lineno} {node.name} ({n})")
    assert not wide, f"engine functions with more than {MAX_ENGINE_PARAMS} parameters: {wide}"


def test_no_module_imports_another_modules_private_names():
    bad = []
    for p in SOURCES:
        for node in ast.walk(_tree(p)):
            if isinstance(node, ast.ImportFrom) and node.module is not None or isinstance(node, ast.ImportFrom) and node.level:
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        bad.append(f"{_rel(p)}:{node.lineno} {alias.name}")
    assert not bad, f"private names imported across modules: {bad}"


# lower layers never import upper ones (docs/architecture.md, "Layers")
LAYERS = [
    ("config", "configfields", "arrays", "kernels", "budget", "atomic", "filekinds", "numba_cache", "compiletime", "lazy"),
    ("arena", "copters", "sensors"),
    ("world", "behaviours"),
    ("swarm",),
    ("flightlog", "metrics", "analysis", "default_scenario"),
    ("scenario", "episode", "determinism", "viz", "precompile"),
    ("sweep", "gap"),
    ("envs", "tune", "importing", "checkfiles", "datasets", "testing", "plugin_checkers"),  # check reads study files and recordings too
    ("cli", "cliargs", "precompile_cli", "gapvalidate_cli"),
]
_LEVEL = {name: i for i, names in enumerate(LAYERS) for name in names}


def _top(module: str) -> str:
    return module.split(".")[0]


@pytest.mark.parametrize("path", SOURCES, ids=_rel)
def test_imports_follow_the_layers(path):
    rel = path.relative_to(PACKAGE)
    here = _top(str(rel.with_suffix("")).replace("/", "."))
    if here not in _LEVEL:
        return  # __init__ and modules outside the layer map
    for node in ast.walk(_tree(path)):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level == 0 and (node.module or "").startswith("finkensim."):
            target = _top(node.module[len("finkensim."):])
        elif node.level > 0:  # relative to the module's package, at any depth (gap/model/replay.py: ...config)
            package = list(rel.parts[:-1])
            base = package[:len(package) - (node.level - 1)] + ([node.module] if node.module else [])
            if not base:
                continue
            target = base[0]
        else:
            continue
        if target in _LEVEL and target != here:
            assert _LEVEL[target] <= _LEVEL[here], f"{rel}:{node.lineno} imports {target} from a lower layer ({here})"


def test_no_two_compilations_of_one_function_differ_in_options():
    """numba's on-disk cache files its entries under the Python function (its file and line), not under the
    compile options: two ``njit`` dispatchers of the same ``py_func`` with different code-changing options
    (``parallel``, ``fastmath``, …) share one cache entry, and a warm cache then hands one the other's machine
    code — a ``parallel=True`` kernel silently ran on one thread that way. Re-jitting with the same options (the
    outlined copies of ``inline="always"`` kernels) is fine."""
    import importlib
    import pkgutil

    from numba.core.registry import CPUDispatcher

    import finkensim

    code_options = ("parallel", "fastmath", "error_model", "boundscheck", "nogil", "looplift")
    seen: dict[int, tuple[str, dict]] = {}
    clashes = []
    for mod in pkgutil.walk_packages(finkensim.__path__, "finkensim."):
        try:
            m = importlib.import_module(mod.name)
        except ImportError:  # an optional extra that is not installed
            continue
        for name, obj in vars(m).items():
            if not isinstance(obj, CPUDispatcher):
                continue
            opts = {k: obj.targetoptions.get(k) for k in code_options}
            key = id(obj.py_func)
            if key in seen and seen[key][1] != opts:
                clashes.append(f"{mod.name}.{name} {opts} vs {seen[key][0]} {seen[key][1]}")
            seen.setdefault(key, (f"{mod.name}.{name}", opts))
    assert seen, "no numba dispatchers found"
    assert not clashes, f"one function compiled with different options (they share a cache entry): {clashes}"


def test_fits_see_the_diagnosis_only_through_the_fit_objective():
    """The effects and their fits read a diagnosis through ``FitObjective`` (gap/attribute/objective.py): they import
    nothing of gap/diagnosis.py and call no private member of the diagnosis they are given (the old
    ``diagnose <-> fits`` cycle, docs/architecture.md, "An effect for the gap diagnosis")."""
    bad = []
    for name in ("fits", "effects", "effects_radio", "objective", "parsimony"):
        path = PACKAGE / "gap" / "attribute" / f"{name}.py"
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[-1] == "diagnosis":
                bad.append(f"{_rel(path)}:{node.lineno} imports {node.module}")
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "diag"
                    and node.attr.startswith("_") and not node.attr.startswith("__")):
                bad.append(f"{_rel(path)}:{node.lineno} diag.{node.attr}")
    assert not bad, f"fits reaching past FitObjective: {bad}"


#: the stages of gap/ in pipeline order (docs/architecture.md, "The gap diagnosis, by stage"): a module imports only
#: from its own stage or an earlier one; gap/__init__.py (the package's public names) is above them all
GAP_STAGES = [("model",), ("detect",), ("attribute",), ("quantify",), ("report",), ("diagnosis", "pipeline", "warmup"),
              ("validation",)]
_GAP_STAGE = {name: i for i, names in enumerate(GAP_STAGES) for name in names}
GAP = PACKAGE / "gap"


def _gap_imports(path: Path) -> list[tuple[int, str]]:
    """(line, stage) of every import of a gap/ module in ``path``: relative at any depth, absolute
    (``finkensim.gap.…``), at module level or inside a function, ``from .. import diagnosis`` included."""
    package = list(path.relative_to(PACKAGE).parts[:-1])
    out = []
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                if node.level - 1 > len(package):
                    continue
                base = package[:len(package) - (node.level - 1)] + (node.module.split(".") if node.module else [])
            elif (node.module or "").startswith("finkensim."):
                base = node.module.split(".")[1:]
            else:
                continue
            if base[:1] != ["gap"]:
                continue
            targets = base[1:2] or [a.name for a in node.names]
        elif isinstance(node, ast.Import):
            targets = [a.name.split(".")[2] for a in node.names if a.name.startswith("finkensim.gap.")]
        else:
            continue
        out += [(node.lineno, t) for t in targets if t in _GAP_STAGE]
    return out


def test_gap_imports_follow_the_stages():
    """Imports inside gap/ flow one way: model ← detect ← attribute ← quantify ← report ← diagnosis, pipeline ←
    validation; a piece two stages share lives in the earlier one (docs/architecture.md)."""
    bad, checked = [], 0
    for path in sorted(GAP.rglob("*.py")):
        rel = path.relative_to(GAP)
        here = rel.parts[0] if len(rel.parts) > 1 else rel.stem
        if here == "__init__":
            continue
        assert here in _GAP_STAGE, f"gap/{rel}: not in a stage of GAP_STAGES (add it, and to docs/architecture.md)"
        for line, target in _gap_imports(path):
            checked += 1
            if _GAP_STAGE[target] > _GAP_STAGE[here]:
                bad.append(f"gap/{rel}:{line} ({here}) imports {target}")
    assert checked > 50, f"only {checked} imports inside gap/ found: the import detection broke"
    assert not bad, f"imports against the stage order of gap/: {bad}"
