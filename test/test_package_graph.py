"""The import graph between infinihand_ros's subpackages has no cycles, and core imports none.

Every module is parsed with ``ast`` (nothing is imported), so imports inside functions count too.
A node is a first-level subpackage (``core``, ``model``, ...) or a top-level module (``demo``);
an edge A -> B means some module of A imports B.
"""

import ast
from collections.abc import Iterator
from pathlib import Path

import networkx as nx

PACKAGE = 'infinihand_ros'
PACKAGE_DIR = Path(__file__).resolve().parents[1] / PACKAGE
#: The bottom layer: it imports no other subpackage.
BOTTOM = 'core'


def _module_name(path: Path, package_dir: Path) -> str:
    parts = path.relative_to(package_dir.parent).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def _node(module: str) -> str | None:
    """Return the graph node of an absolute module name, or None outside the package."""
    parts = module.split('.')
    if parts[0] != PACKAGE:
        return None
    return parts[1] if len(parts) > 1 else PACKAGE


def _imported_modules(path: Path, module: str) -> Iterator[tuple[str, int]]:
    """Yield (absolute module name, line) for every import in the file, at any depth."""
    package = module if path.name == '__init__.py' else module.rpartition('.')[0]
    for stmt in ast.walk(ast.parse(path.read_text(encoding='utf-8'), filename=str(path))):
        if isinstance(stmt, ast.Import):
            for alias in stmt.names:
                yield alias.name, stmt.lineno
        elif isinstance(stmt, ast.ImportFrom):
            base = stmt.module or ''
            if stmt.level:
                parts = package.split('.')
                base = '.'.join(parts[:len(parts) - stmt.level + 1] + ([base] if base else []))
            for alias in stmt.names:
                # `from infinihand_ros import synth` imports the subpackage itself.
                yield (f'{base}.{alias.name}' if base == PACKAGE else base), stmt.lineno


def _import_graph(package_dir: Path = PACKAGE_DIR) -> nx.DiGraph:
    """Return the subpackage graph; an edge keeps its imports as ``module:line -> module``."""
    graph = nx.DiGraph()
    for path in sorted(package_dir.rglob('*.py')):
        importer = _module_name(path, package_dir)
        source = _node(importer)
        graph.add_node(source)
        for imported, line in _imported_modules(path, importer):
            target = _node(imported)
            if target is None or target == source:
                continue
            if not graph.has_edge(source, target):
                graph.add_edge(source, target, imports=set())
            graph.edges[source, target]['imports'].add(f'{importer}:{line} -> {imported}')
    return graph


def _cycles(graph: nx.DiGraph) -> list[tuple[str, ...]]:
    """Return every elementary cycle, each rotated to start at its alphabetically first node."""
    rotated = set()
    for cycle in nx.simple_cycles(graph):
        start = cycle.index(min(cycle))
        rotated.add(tuple(cycle[start:] + cycle[:start]))
    return sorted(rotated)


def _describe(graph: nx.DiGraph, cycles: list[tuple[str, ...]]) -> str:
    """Return the cycles, then the imports behind each package edge they use."""
    edges = sorted({(source, target) for cycle in cycles
                    for source, target in zip(cycle, cycle[1:] + cycle[:1])})
    lines = [' -> '.join(cycle + cycle[:1]) for cycle in cycles]
    for source, target in edges:
        lines.append(f'{source} -> {target}:')
        lines.extend(f'  {item}' for item in sorted(graph.edges[source, target]['imports']))
    return '\n'.join(lines)


def test_parser_finds_every_kind_of_import(tmp_path: Path) -> None:
    """Imports in functions, relative imports and `from infinihand_ros import x` all count."""
    root = tmp_path / PACKAGE
    files = {
        '__init__.py': '',
        'demo.py': 'def main():\n    from infinihand_ros import synth\n',
        'core/__init__.py': '',
        'core/units.py': 'NS = 1\n',
        'synth/__init__.py': 'from .scene import make\n',
        'synth/scene.py': 'from ..core.units import NS\n\n\ndef make():\n'
                          '    import infinihand_ros.data.fmt\n',
        'data/__init__.py': '',
        'data/fmt.py': 'from infinihand_ros.synth import scene\nimport numpy\n',
    }
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    graph = _import_graph(root)
    assert set(graph.edges) == {('demo', 'synth'), ('synth', 'core'), ('synth', 'data'),
                                ('data', 'synth')}
    assert graph.edges['synth', 'core']['imports'] == {
        'infinihand_ros.synth.scene:1 -> infinihand_ros.core.units'}
    assert _cycles(graph) == [('data', 'synth')]


def test_graph_sees_the_subpackages() -> None:
    """The real package parses into its layers (guards against an empty graph)."""
    graph = _import_graph()
    assert {'core', 'mano', 'model', 'engine', 'demo'} <= set(graph.nodes)
    assert graph.has_edge('engine', 'core')


def test_no_package_cycles() -> None:
    """No subpackage imports, directly or indirectly, one that imports it back."""
    graph = _import_graph()
    cycles = _cycles(graph)
    assert not cycles, 'Package import cycles:\n' + _describe(graph, cycles)


def test_core_imports_no_other_subpackage() -> None:
    """`core` is the bottom layer: it imports nothing else from the package."""
    graph = _import_graph()
    imports = sorted(item for target in graph.successors(BOTTOM)
                     for item in graph.edges[BOTTOM, target]['imports'])
    assert not imports, f'{BOTTOM} imports other subpackages:\n' + '\n'.join(imports)
