"""The shape of the code: layers that point one way, one home per testbed, no import circle, public
modules that say what they export (docs/architecture.md)."""

from __future__ import annotations

import ast
import importlib
import inspect
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGES = ("coordinator", "services", "sim")
#: which top-level package may import which (besides itself)
ALLOWED = {"coordinator": {"services"}, "services": set(), "sim": {"services"}}
#: the testbeds: each has its node side in services/NAME/ and its world in sim/NAME/
TESTBEDS = ("catching", "mobile")
#: the worlds ``petrobot sim`` runs, each from its package's process module: the testbeds' and the
#: ROS 2 demo's (sim/ros2/: a Zenoh router and a stand-in robot). ROS 2 is no testbed: services/ros2/
#: is the framework's reach to any ROS 2 robot, which a node of any testbed may use.
WORLDS = (*TESTBEDS, "ros2")


def _door(module: str) -> bool:
    """The demo and sim commands: the only coordinator modules that reach ``sim`` and the testbeds
    (``petrobot sim``, ``petrobot demo``)."""
    return module == "coordinator.commands.sim" or module.startswith("coordinator.commands.demo")


def _allowed(module: str) -> set[str]:
    if _door(module):
        return {"services", "sim"}
    return ALLOWED[module.split(".")[0]]


def _testbed(module: str) -> str | None:
    """The testbed a module belongs to (``services.catching.vision`` → ``catching``), or ``None``
    for the framework."""
    parts = module.split(".")
    return parts[1] if parts[0] in ("services", "sim") and len(parts) > 1 and parts[1] in TESTBEDS else None


def _modules() -> dict[str, Path]:
    found = {}
    for pkg in PACKAGES:
        for path in sorted((ROOT / pkg).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Project modules imported by one module, anywhere in it (functions included, and imports for
    annotations only, under ``if TYPE_CHECKING:``: a circle of types is a circle of design)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = name.split(".") if is_pkg else name.split(".")[:-1]
                base = base[: len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            targets = [f"{mod}.{a.name}" if f"{mod}.{a.name}" in MODULES else mod for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in MODULES:
                target = target.rpartition(".")[0]
            if target and target != name:
                out.add(target)
    return out


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def test_layers_point_one_way_services_import_neither_coordinator_nor_sim():
    upward = [(a, b) for a, targets in GRAPH.items() for b in targets
              if b.split(".")[0] != a.split(".")[0] and b.split(".")[0] not in _allowed(a)]
    assert upward == [], f"imports against the layers: {upward}"


def test_every_testbed_has_its_node_side_and_its_world_in_a_package_of_its_own():
    for testbed in TESTBEDS:
        assert f"services.{testbed}" in MODULES and f"sim.{testbed}" in MODULES, testbed


def test_testbed_packages_import_the_framework_and_never_each_other():
    crossing = [(a, b) for a, targets in GRAPH.items() for b in targets
                if _testbed(a) is not None and _testbed(b) not in (None, _testbed(a))]
    assert crossing == [], f"a testbed imports another: {crossing}"


def test_the_framework_imports_no_testbed_and_only_the_demo_and_sim_commands_reach_them():
    into = [(a, b) for a, targets in GRAPH.items() for b in targets
            if _testbed(a) is None and not _door(a) and _testbed(b) is not None]
    assert into == [], f"the framework imports a testbed: {into}"


def _world(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "sim" and len(parts) > 1 and parts[1] in WORLDS else None


def test_worlds_import_no_other_world_and_petrobot_sim_only_dispatches_to_their_processes():
    crossing = [(a, b) for a, targets in GRAPH.items() for b in targets
                if _world(a) is not None and _world(b) not in (None, _world(a))]
    assert crossing == [], f"a world imports another: {crossing}"
    assert all(f"sim.{world}.process" in MODULES for world in WORLDS)
    reached = sorted(b for b in GRAPH["coordinator.commands.sim"] if b.startswith("sim"))
    assert reached == sorted(f"sim.{world}.process" for world in WORLDS), \
        "petrobot sim parses and dispatches; each world runs from its own sim.NAME.process"


def _strongly_connected(graph: dict[str, set[str]]) -> list[list[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []
    counter = [0]

    def visit(v: str) -> None:  # Tarjan's algorithm, recursive (a few hundred modules)
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
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
            out.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_import_graph_has_no_circle():
    # a package's __init__ re-exporting its submodules is not a circle: drop edges from a
    # submodule to its own parent package's __init__ only when the parent merely re-exports
    graph: dict[str, set[str]] = defaultdict(set)
    for a, targets in GRAPH.items():
        for b in targets:
            if a.startswith(b + "."):
                continue  # a submodule importing its own package (the package imports it: re-export)
            graph[a].add(b)
    circles = [sorted(c) for c in _strongly_connected(dict(graph)) if len(c) > 1]
    assert circles == [], f"import circles: {circles}"


def test_a_node_process_imports_nothing_from_sim_or_coordinator():
    hide = (
        "import sys\n"
        "class Hide:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name.split('.')[0] in ('sim', 'coordinator'):\n"
        "            raise ImportError(f'{name} is hidden: a node must not need it')\n"
        "sys.meta_path.insert(0, Hide())\n"
        "import importlib, pkgutil, services\n"
        "for m in pkgutil.walk_packages(services.__path__, 'services.'):\n"
        "    if not m.name.endswith('__main__'):\n"
        "        importlib.import_module(m.name)\n"
        "print('ok')\n"
    )
    done = subprocess.run([sys.executable, "-c", hide], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]


PUBLIC = sorted(n for n in MODULES if not any(p.startswith("_") for p in n.split(".")))


@pytest.mark.parametrize("name", PUBLIC)
def test_every_public_module_declares_what_it_exports(name: str):
    module = importlib.import_module(name)
    exported = getattr(module, "__all__", None)
    assert exported is not None, f"{name} has no __all__"
    missing = [n for n in exported if not hasattr(module, n)]
    assert missing == [], f"{name}.__all__ names what it does not define: {missing}"
    defined_here = [n for n, obj in vars(module).items()
                    if not n.startswith("_") and (inspect.isclass(obj) or inspect.isfunction(obj))
                    and getattr(obj, "__module__", None) == name]
    unlisted = sorted(set(defined_here) - set(exported))
    assert unlisted == [], f"{name} defines public names not in __all__: {unlisted}"
