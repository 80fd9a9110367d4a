"""The layering the design fixes, checked on the source (every import, including those inside functions).

odometry.shared <- odometry <- loops, graph (which see only odometry.shared) <- vslam; no cycles between modules.
The command line is the top: nothing imports vslam.cli but `python -m vslam`. Names starting with `_` stay inside
their module.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("odometry", "loops", "graph", "vslam")


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module_name(f): f for p in PACKAGES for f in sorted((ROOT / p).rglob("*.py"))}


MODULES = _modules()


def _imports(name: str, path: Path) -> list[tuple[str, str, int]]:
    """(imported module, imported name or '', line) for every import statement of a module."""
    out = []
    is_package = path.name == "__init__.py"
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out += [(a.name, "", node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            out += [(module, a.name, node.lineno) for a in node.names]
    return out


def _target(module: str, imported: str) -> str | None:
    """The project module an import statement loads (a submodule when `from pkg import submodule`)."""
    if imported and f"{module}.{imported}" in MODULES:
        return f"{module}.{imported}"
    while module and module not in MODULES:
        module = module.rpartition(".")[0]
    return module or None


def _edges() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {m: set() for m in MODULES}
    for name, path in MODULES.items():
        for module, imported, _ in _imports(name, path):
            t = _target(module, imported)
            if t is not None and t != name:
                edges[name].add(t)
    return edges


def _violations(select, forbid) -> list[str]:
    bad = []
    for name, path in MODULES.items():
        if not select(name):
            continue
        for module, imported, line in _imports(name, path):
            if module.split(".")[0] in PACKAGES and forbid(name, module):
                bad.append(f"{path.relative_to(ROOT)}:{line}: imports {module}")
    return bad


def test_foundation_packages_never_import_vslam():
    assert _violations(lambda m: not m.startswith("vslam"), lambda m, t: t.split(".")[0] == "vslam") == []


def test_shared_primitives_import_nothing_above_them():
    assert _violations(lambda m: m.startswith("odometry.shared"),
                       lambda m, t: not t.startswith("odometry.shared")) == []


@pytest.mark.parametrize("package", ["loops", "graph"])
def test_loops_and_graph_see_only_the_shared_layer_of_odometry(package):
    assert _violations(lambda m: m.split(".")[0] == package,
                       lambda m, t: t.split(".")[0] == "odometry" and not t.startswith("odometry.shared")) == []


def test_no_import_cycle_between_modules():
    edges = _edges()
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def visit(v: str) -> None:   # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    assert cycles == []


def test_only_the_entry_point_imports_the_cli():
    assert _violations(lambda m: not m.startswith("vslam.cli") and m != "vslam.__main__",
                       lambda m, t: t == "vslam.cli" or t.startswith("vslam.cli.")) == []


# Private names another part of the restructure still imports; each entry names its owner. Remove when fixed.
KNOWN_PRIVATE_IMPORTS: set[str] = set()


def _private_imports(modules: dict[str, Path]) -> list[str]:
    """`from project.module import _name` and imports of `_module`s (dunder names such as __init__ excepted)."""
    def private(part: str) -> bool:
        return part.startswith("_") and not part.startswith("__")

    bad = []
    for name, path in modules.items():
        for module, imported, _line in _imports(name, path):
            if module.split(".")[0] not in PACKAGES:
                continue
            if private(imported) or any(private(part) for part in module.split(".")):
                base = ROOT if path.is_relative_to(ROOT) else path.parents[len(name.split(".")) - 1]
                bad.append(f"{path.relative_to(base).as_posix()}: {imported or module} from {module}")
    return sorted(set(bad))


def test_no_private_name_is_imported_across_modules():
    assert [b for b in _private_imports(MODULES) if b not in KNOWN_PRIVATE_IMPORTS] == []


def test_private_import_check_sees_names_and_modules(tmp_path):
    (tmp_path / "vslam").mkdir()
    path = tmp_path / "vslam" / "probe.py"
    path.write_text("from vslam.bench._common import median\nfrom vslam.pipeline.outputs import _evaluate\n"
                    "from vslam.cli import __name__\nimport numpy._core\n")
    assert _private_imports({"vslam.probe": path}) == ["vslam/probe.py: _evaluate from vslam.pipeline.outputs",
                                                        "vslam/probe.py: median from vslam.bench._common"]


def test_the_checks_see_function_local_imports(tmp_path):
    src = "def f():\n    from vslam.paths import shared_data_dir\n    return shared_data_dir\n"
    path = tmp_path / "probe.py"
    path.write_text(src)
    assert _imports("loops.probe", path) == [("vslam.paths", "shared_data_dir", 2)]


# One configuration mechanism: every *Params / *Config dataclass is an odometry.shared.config.Config, which alone
# provides from_dict/to_dict/load/dump/replace/preset; no class keeps a copy or a with_-style helper of its own.
NOT_CONFIGS = {"TrainedParams"}   # learned arrays read from a .npz file, not tunables
CONFIG_PLUMBING = {"from_dict", "to_dict", "load", "dump", "dumps", "replace", "preset", "with_overrides"}


def _classes():
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef):
                bases = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
                methods = {n.name for n in node.body if isinstance(n, ast.FunctionDef)}
                yield f"{path.relative_to(ROOT)}:{node.lineno}", node.name, bases, methods


def test_every_params_and_config_class_uses_the_one_config_mechanism():
    bad = []
    for where, cls, bases, methods in _classes():
        if where.startswith("odometry/shared/config.py"):
            continue
        if cls.endswith(("Params", "Config")) and cls not in NOT_CONFIGS and "Config" not in bases:
            bad.append(f"{where}: {cls} does not inherit odometry.shared.config.Config")
        if "Config" in bases and methods & CONFIG_PLUMBING:
            bad.append(f"{where}: {cls} defines its own {', '.join(sorted(methods & CONFIG_PLUMBING))}")
        if methods & {"with_", "with_height"}:
            bad.append(f"{where}: {cls} has a with_-style copy helper (use replace)")
    assert bad == []


# one home per shared numerical concept: no module but its home defines these functions or calls the popcount
SHARED_DEFINITIONS = {"hamming_matrix": "loops.hamming", "roc_curve": "loops.curves", "auc": "loops.curves",
                      "tpr_at_fpr": "loops.curves", "pr_curve": "loops.curves", "find_consensus": "odometry.shared.ransac"}


def test_shared_kernels_have_one_definition():
    bad = []
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef) and SHARED_DEFINITIONS.get(node.name, name) != name:
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: defines {node.name} "
                           f"(its home is {SHARED_DEFINITIONS[node.name]})")
            if (isinstance(node, ast.Attribute) and node.attr == "bitwise_count" and name != "loops.hamming"):
                bad.append(f"{path.relative_to(ROOT)}:{node.lineno}: popcount outside loops.hamming")
    assert bad == []
