"""The package layout holds: imports run one way, the runtime never imports the lab, no circles, no private names across modules."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("city", "bus", "agents", "predictor", "coordinator")
#: What each package may import besides itself: coordinator -> predictor/agents -> bus -> city.
ALLOWED = {
    "city": set(),
    "bus": {"city"},
    "agents": {"bus", "city"},
    "predictor": {"bus", "city"},
    "coordinator": {"predictor", "agents", "bus", "city"},
}
LAB = ("coordinator.experiments", "coordinator.cli")
#: Imports across the layers that are allowed, each with why.
EXCEPTIONS = {
    ("agents.forecast_providers", "predictor.forecaster"):
        "the in-process `model` forecast loads a trained predictor lazily; agent processes get forecasts over the bus",
}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}


def imports(path: Path, name: str) -> list[tuple[str, list[str], int]]:
    """``(module, names, line)`` of every import in the file, lazy ones included."""
    out = []
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(a.name, [], node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1] + ([base] if base else []))
            out.append((base, [a.name for a in node.names], node.lineno))
    return out


def resolve(target: str, names: list[str], known: dict[str, Path]) -> list[str]:
    """The project modules an import statement loads (``from pkg import mod`` loads ``pkg.mod``)."""
    found = [f"{target}.{n}" for n in names if f"{target}.{n}" in known]
    return found or ([target] if target in known else [])


MODULES = modules()


def test_packages_import_one_way() -> None:
    bad = []
    for name, path in MODULES.items():
        own = name.split(".")[0]
        for target, _names, line in imports(path, name):
            top = target.split(".")[0]
            if top in PACKAGES and top != own and top not in ALLOWED[own] and (name, target) not in EXCEPTIONS:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not bad, "\n".join(bad)


def test_runtime_imports_nothing_of_the_lab() -> None:
    bad = []
    for name, path in MODULES.items():
        if name.startswith(LAB):
            continue
        for target, _names, line in imports(path, name):
            if target.startswith(LAB):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not bad, "\n".join(bad)


def test_no_import_circles() -> None:
    graph = nx.DiGraph()
    for name, path in MODULES.items():
        graph.add_node(name)
        for target, names, _line in imports(path, name):
            for dep in resolve(target, names, MODULES):
                if dep != name and not name.startswith(dep + "."):  # a module's own package __init__ is no circle
                    graph.add_edge(name, dep)
    cycles = [c for c in nx.simple_cycles(graph) if not all(m.startswith(c[0].split(".")[0] + ".cli") for m in c)]
    assert not cycles, "\n".join(" -> ".join(c) for c in cycles[:10])


def test_no_private_name_imported_across_modules() -> None:
    bad = []
    for name, path in MODULES.items():
        for target, names, line in imports(path, name):
            if target.split(".")[0] not in PACKAGES:
                continue
            for n in names:
                private = n.startswith("_") and not n.startswith("__")
                own_private_module = f"{target}.{n}" in MODULES and target == name.rpartition(".")[0]
                if private and not own_private_module:
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports {n} from {target}")
    assert not bad, "\n".join(bad)


def test_argparse_lives_only_in_the_cli() -> None:
    bad = [f"{path.relative_to(ROOT)}:{line}" for name, path in MODULES.items() if not name.startswith("coordinator.cli")
           for target, _names, line in imports(path, name) if target == "argparse"]
    assert not bad, "argparse outside coordinator/cli: " + ", ".join(bad)
