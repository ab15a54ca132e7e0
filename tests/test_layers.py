"""The package's imports flow one way (core ← io ← sim ← analysis ← viz ← commands) and have no cycles.

Every ``import`` of every module is read with :mod:`ast`, at module level and inside functions alike (an
import hidden in a function still ties the modules together at run time).
"""

import ast
from pathlib import Path

import stablemarks

PACKAGE = Path(stablemarks.__file__).parent

CORE = {"errors", "geometry", "maps", "motion", "config", "frames", "health", "viewing", "vision", "planes",
        "landmarks", "pipeline",
        "estimation", "methods", "localizer", "online", "metrics", "reference"}
LAYERS = [CORE, {"io"}, {"sim"}, {"evaluation", "smoother", "bench", "noisefit"}, {"viz"}, {"commands", "cli"}]
"""Each layer may import its own and the layers before it, never a later one."""


def module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> set[str]:
    """The ``stablemarks`` modules ``path`` imports (resolved; ``from .x import y`` counts ``.x`` and, when it is
    a module, ``.x.y``)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.startswith("stablemarks")}
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[: len(base) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.startswith("stablemarks"):
                target = node.module
            else:
                continue
            out.add(target)
            for a in node.names:
                if (PACKAGE.parent / Path(*f"{target}.{a.name}".split("."))).with_suffix(".py").exists():
                    out.add(f"{target}.{a.name}")
    out.discard(name)
    return {m for m in out if m != "stablemarks"}


GRAPH = {module_name(p): imports_of(p) for p in PACKAGE.rglob("*.py")}


def layer(module: str) -> int:
    top = module.split(".")[1] if "." in module else ""
    for i, names in enumerate(LAYERS):
        if top in names:
            return i
    raise AssertionError(f"{module} is in no layer: add it to LAYERS")


def wrong_way(graph: dict[str, set[str]]) -> list[str]:
    """``"a → b"`` for every import of a later layer."""
    return sorted(f"{m} → {t}" for m, ts in graph.items() if m != "stablemarks" for t in ts if layer(t) > layer(m))


def find_cycles(graph: dict[str, set[str]]) -> list[str]:
    """Each module that reaches itself through the import graph, with one such path."""
    graph = {m: {t for t in ts if t in graph} for m, ts in graph.items() if m != "stablemarks"}
    cycles = []
    for start in sorted(graph):
        stack, seen = [(start, [start])], set()
        while stack:
            node, path = stack.pop()
            for nxt in sorted(graph.get(node, ())):
                if nxt == start:
                    cycles.append(" → ".join(path + [start]))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, path + [nxt]))
    return cycles


def test_no_module_imports_a_later_layer():
    assert wrong_way(GRAPH) == []


def test_the_core_imports_nothing_from_io_sim_viz_or_commands():
    outside = {"io", "sim", "viz", "commands", "cli", "evaluation", "smoother", "bench", "noisefit"}
    bad = [f"{m} → {t}" for m, ts in GRAPH.items() if m != "stablemarks" and layer(m) == 0
           for t in ts if t.split(".")[1] in outside]
    assert bad == []


def test_no_import_cycles():
    assert find_cycles(GRAPH) == []


def test_the_checks_catch_a_wrong_way_import_and_a_cycle():
    """The checks can fail: a core module importing the simulator, and two io modules importing each other."""
    bad = {**GRAPH, "stablemarks.geometry": GRAPH["stablemarks.geometry"] | {"stablemarks.sim.render"},
           "stablemarks.io.images": GRAPH["stablemarks.io.images"] | {"stablemarks.io.calibration"}}
    assert wrong_way(bad) == ["stablemarks.geometry → stablemarks.sim.render"]
    assert any(c.startswith("stablemarks.io.images → stablemarks.io.calibration") for c in find_cycles(bad))


def test_the_parser_resolves_relative_and_in_function_imports():
    assert "stablemarks.io.sources" in GRAPH["stablemarks.commands.run"]  # imported inside run()
    assert {"stablemarks.io.bags", "stablemarks.io.recorded"} <= GRAPH["stablemarks.io.sources"]
    assert "stablemarks.estimation.ekf" in GRAPH["stablemarks.estimation.association"]
