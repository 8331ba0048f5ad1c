"""The dependency direction of rbe_ros, read from the source with ast (docs/ARCHITECTURE.md):
scene model -> geometry -> rbe -> analysis (options, assembly -> validate, graph, steps ->
verdict -> analyses -> pipeline -> planning) -> io -> ros, cli. Each module imports only
its own or earlier layers (within analysis: its own or earlier ranks); the import graph
has no cycle; only rbe_ros.ros touches ROS; no rbe_ros module is imported inside a function
(that is how a cycle hides), but for the one listed with its reason."""
from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "rbe_ros"

#: Layers by module name prefix; the longest matching prefix decides. The interlocking
#: suite's generators use the geometry (a prism's signed volume): layer 1.
LAYERS = {"rbe_ros": 0, "rbe_ros.scene": 0, "rbe_ros.cell": 0, "rbe_ros.generators": 0,
          "rbe_ros.interlock": 1,
          "rbe_ros.deadline": 0, "rbe_ros.geometry": 1, "rbe_ros.rbe": 2, "rbe_ros.analysis": 3,
          "rbe_ros.io": 4, "rbe_ros.ros": 5, "rbe_ros.cli": 6}
#: Ranks inside analysis; a module not listed is an analysis (rank 3): it may use the
#: verdict, the graph and the steps, and the pipeline may use it.
ANALYSIS_RANKS = {"options": 0, "assembly": 0, "validate": 1, "graph": 1, "steps": 1,
                  "verdict": 2, "pipeline": 4, "planning": 5, "robust": 5, "lookahead": 5,
                  "executors": 5, "repair": 6, "cell_execution": 7}
ANALYSIS_DEFAULT = 3
#: Imports inside a function that are allowed, with the reason.
DEFERRED = {("rbe_ros.cli", "rbe_ros.ros.live"): "rclpy is loaded only for replay --live"}
ROS_PACKAGES = ("rclpy", "rosidl", "rbe_msgs", "builtin_interfaces", "std_msgs",
                "geometry_msgs", "visualization_msgs", "rcl_interfaces", "shape_msgs",
                "action_msgs")


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _resolve(module: str, path: Path, node: ast.ImportFrom) -> list[str]:
    """The rbe_ros modules an ``from ... import`` names (a submodule when a name is one)."""
    if node.level:
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        base = package[:len(package) - node.level + 1]
        target = ".".join(base + ([node.module] if node.module else []))
    else:
        target = node.module or ""
    if not target.startswith("rbe_ros"):
        return []
    found = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES]
    return found or [target]


def _imports(module: str, path: Path) -> list[tuple[str, bool, int]]:
    """(imported name, inside a function, line) of every import of ``module``."""
    tree = ast.parse(path.read_text())
    out = []

    def visit(node, deferred: bool):
        for child in ast.iter_child_nodes(node):
            inner = deferred or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef))
            if isinstance(child, ast.Import):
                out.extend((a.name, deferred, child.lineno) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level or (child.module or "").startswith("rbe_ros"):
                    out.extend((t, deferred, child.lineno) for t in _resolve(module, path, child))
                else:
                    out.append((child.module or "", deferred, child.lineno))
            visit(child, inner)

    visit(tree, False)
    return out


def _layer(module: str) -> tuple[int, int]:
    prefix = max((p for p in LAYERS if module == p or module.startswith(p + ".")), key=len)
    rank = 0
    if prefix == "rbe_ros.analysis" and module != prefix:
        rank = ANALYSIS_RANKS.get(module.split(".")[2], ANALYSIS_DEFAULT)
    return LAYERS[prefix], rank


def test_every_module_has_a_layer():
    roots = {m for m in MODULES if m.count(".") == 1 and not (PACKAGE / m.split(".")[1]).is_dir()}
    unknown = sorted(roots - set(LAYERS))
    assert not unknown, (f"{unknown}: a module at the package root needs a layer in "
                         "tests/test_layers.py (or belongs in a layer's package)")


def test_imports_go_down_the_layers():
    wrong = []
    for module, path in MODULES.items():
        for target, _, line in _imports(module, path):
            if not target.startswith("rbe_ros") or target == "rbe_ros":
                continue
            if (_layer(target) > _layer(module) and target != module
                    and not target.startswith(module + ".")
                    and (module, target) not in DEFERRED):
                wrong.append(f"{path.relative_to(PACKAGE.parent)}:{line}: {module} "
                             f"{_layer(module)} imports {target} {_layer(target)}")
    assert not wrong, "imports against the layer order:\n" + "\n".join(wrong)


def test_no_import_inside_a_function_but_the_listed_ones():
    found = {(module, target): line for module, path in MODULES.items()
             for target, deferred, line in _imports(module, path)
             if deferred and target.startswith("rbe_ros")}
    unlisted = sorted(f"{m}:{line} imports {t}" for (m, t), line in found.items()
                      if (m, t) not in DEFERRED)
    assert not unlisted, "imports inside functions:\n" + "\n".join(unlisted)
    assert set(DEFERRED) <= set(found), "a listed deferred import is gone: drop it from DEFERRED"


def test_the_import_graph_has_no_cycle():
    graph = {m: {t for t, _, _ in _imports(m, p) if t in MODULES and t != m}
             for m, p in MODULES.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(stack[stack.index(t):] + [t]))
            if t not in state:
                visit(t)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_only_rbe_ros_ros_touches_ros():
    wrong = [f"{m} imports {t}" for m, p in MODULES.items() if not m.startswith("rbe_ros.ros")
             for t, deferred, _ in _imports(m, p)
             if t.split(".")[0] in ROS_PACKAGES and (m, t) not in DEFERRED]
    assert not wrong, "\n".join(wrong)


def test_every_module_is_named_in_the_architecture():
    """docs/ARCHITECTURE.md names each module (its name in backticks, or its path)."""
    text = (PACKAGE.parent / "docs" / "ARCHITECTURE.md").read_text()
    unnamed = sorted(str(p.relative_to(PACKAGE.parent)) for m, p in MODULES.items()
                     if p.name != "__init__.py"
                     and f"`{p.stem}`" not in text and f"{p.stem}.py" not in text)
    assert not unnamed, f"{unnamed}: name them in docs/ARCHITECTURE.md (layer table or ranks)"
