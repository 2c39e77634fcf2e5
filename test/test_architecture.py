# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""The rules of docs/architecture.md, read from the package's source (AST, nothing is
imported): the core never imports ROS, the ROS wing holds no physics, no import circles, the
physics in one subpackage, one home per public name, no file too long, no two modules of a
folder named alike."""

from __future__ import annotations

import ast
import graphlib
import re
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / 'worm_gear_sim'
ROOT = 'worm_gear_sim'
WING = f'{ROOT}.ros'
DYNAMICS = f'{ROOT}.dynamics'
#: Top-level packages of ROS 2 (client library, messages, launch); only the wing uses them.
ROS_PACKAGES = {'rclpy', 'rcl_interfaces', 'rosgraph_msgs', 'builtin_interfaces', 'std_msgs',
                'std_srvs',
                'sensor_msgs', 'diagnostic_msgs', 'geometry_msgs', 'launch', 'launch_ros',
                'ament_index_python', 'rosidl_runtime_py', 'rmw', 'unique_identifier_msgs'}
#: The physics: the model (model, its equations and their packed layout), their integration
#: (integrator) and compilation (numba).  The wing gets the model's results through the
#: core's modules, never from these.
PHYSICS = {f'{DYNAMICS}.model', f'{DYNAMICS}.equations', f'{DYNAMICS}.layout',
           f'{DYNAMICS}.integrator', 'numba', 'scipy'}
#: Imports deferred into a function that close a loop on purpose; everything else is acyclic.
DEFERRED_BACK_EDGES: set[tuple[str, str]] = set()


@dataclass(frozen=True)
class Import:
    source: str        # importing module
    target: str        # imported module (dotted; a package's module when it is one)
    line: int
    deferred: bool     # inside a function (runs when called, not at import)
    names: tuple[str, ...] = ()


def _module_name(path: Path) -> str:
    rel = path.relative_to(PACKAGE.parent).with_suffix('')
    parts = list(rel.parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def _is_module(dotted: str) -> bool:
    rel = Path(*dotted.split('.'))
    base = PACKAGE.parent / rel
    return base.with_suffix('.py').is_file() or (base / '__init__.py').is_file()


def _type_checking_block(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and 'TYPE_CHECKING' in ast.unparse(node.test)


def _imports(path: Path) -> list[Import]:
    module = _module_name(path)
    is_pkg = path.name == '__init__.py'
    tree = ast.parse(path.read_text(), str(path))
    out: list[Import] = []

    def visit(node: ast.AST, deferred: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking_block(child):
                continue               # not executed: static analysers only
            inner = deferred or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                    ast.Lambda))
            if isinstance(child, ast.Import):
                for a in child.names:
                    out.append(Import(module, a.name, child.lineno, deferred))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = module.split('.')
                    base = base[:len(base) - child.level + (1 if is_pkg else 0)]
                    target = '.'.join(base + ([child.module] if child.module else []))
                else:
                    target = child.module or ''
                names = tuple(a.name for a in child.names)
                subs = [f'{target}.{n}' for n in names if _is_module(f'{target}.{n}')]
                for s in subs:
                    out.append(Import(module, s, child.lineno, deferred))
                if len(subs) < len(names):
                    out.append(Import(module, target, child.lineno, deferred, names))
            visit(child, inner)

    visit(tree, False)
    return out


def _all_imports() -> list[Import]:
    return [i for p in sorted(PACKAGE.rglob('*.py')) for i in _imports(p)]


def _in_wing(module: str) -> bool:
    return module == WING or module.startswith(WING + '.')


def _internal(target: str) -> bool:
    return target == ROOT or target.startswith(ROOT + '.')


IMPORTS = _all_imports()


def test_the_graph_is_read():
    """The reader sees the imports it must judge (guards against a silent, empty graph)."""
    sources = {i.source for i in IMPORTS}
    assert {f'{DYNAMICS}.simulation', f'{ROOT}.cli', f'{WING}.node'} <= sources
    edges = {(i.source, i.target) for i in IMPORTS}
    assert (f'{DYNAMICS}.stepping', f'{DYNAMICS}.integrator') in edges
    assert (f'{ROOT}.config.usable', f'{DYNAMICS}.usability') in edges


def test_core_never_imports_ros():
    bad = [f'{i.source}:{i.line} imports {i.target}' for i in IMPORTS
           if not _in_wing(i.source)
           and (i.target.split('.')[0] in ROS_PACKAGES or _in_wing(i.target))]
    assert not bad, 'the core must not import ROS:\n' + '\n'.join(bad)


CLI = f'{ROOT}.cli'


def _in_cli(module: str) -> bool:
    return module == CLI or module.startswith(CLI + '.')


def test_ros_never_imports_the_command_line():
    """The ROS wing and the command line are two faces of the core: neither imports the
    other, deferred imports included (what both show, a report writer, a table, shared
    options, lives in the core beside its domain)."""
    assert any(_in_cli(i.source) for i in IMPORTS) and any(_in_wing(i.source) for i in IMPORTS)
    bad = [f'{i.source}:{i.line} imports {i.target}' for i in IMPORTS
           if (_in_wing(i.source) and _in_cli(i.target))
           or (_in_cli(i.source) and _in_wing(i.target))]
    assert not bad, 'one face imports the other:\n' + '\n'.join(bad)


def test_ros_wing_holds_no_physics():
    """The wing reaches the model only through the core's modules: no equations, no
    integrator, no numba/scipy, no packed-parameter indices."""
    bad = []
    for i in IMPORTS:
        if not _in_wing(i.source):
            continue
        root = i.target.split('.')[0]
        if i.target in PHYSICS or root in PHYSICS:
            bad.append(f'{i.source}:{i.line} imports {i.target}')
        bad += [f'{i.source}:{i.line} takes {n} (packed layout) from {i.target}'
                for n in i.names if re.fullmatch(r'P_[A-Z0-9_]+', n)]
    assert not bad, 'physics in the ROS wing:\n' + '\n'.join(bad)


def _cycle(edges: set[tuple[str, str]]) -> list[str]:
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
    try:
        tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        return list(exc.args[1])
    return []


@pytest.mark.parametrize('deferred', [False, True], ids=['at-import', 'with-deferred'])
def test_no_import_circles(deferred):
    """No circle among the package's modules: none at import time, and none through imports
    deferred into functions either, except the back edges listed (each with its reason)."""
    edges = {(i.source, i.target) for i in IMPORTS
             if _internal(i.target) and i.target != i.source
             and (deferred or not i.deferred)}
    if deferred:
        assert DEFERRED_BACK_EDGES <= edges, 'a listed back edge is gone: drop it from the list'
        edges -= DEFERRED_BACK_EDGES
    cycle = _cycle(edges)
    assert not cycle, 'import circle: ' + ' -> '.join(cycle)


def _folder(module: str) -> str:
    """The package's folder a module sits in (``<root>`` for the face and its helpers;
    ``__main__``, the entry point, on the top floor by itself)."""
    if module == f'{ROOT}.__main__':
        return '__main__'
    parts = module.split('.')
    return parts[1] if len(parts) > 2 or _is_package(module) and len(parts) == 2 else '<root>'


def _is_package(dotted: str) -> bool:
    return (PACKAGE.parent / Path(*dotted.split('.')) / '__init__.py').is_file()


def test_no_circle_between_folders():
    """The folders stand on floors (docs/architecture.md): no import, deferred ones
    included, runs from a folder to one that imports it back, directly or around."""
    assert _folder(f'{ROOT}.dynamics.model') == 'dynamics'
    assert _folder(f'{ROOT}.dynamics') == 'dynamics' and _folder(ROOT) == '<root>'
    edges = {(_folder(i.source), _folder(i.target)) for i in IMPORTS
             if _internal(i.target) and _folder(i.source) != _folder(i.target)}
    assert ('realtime', 'dynamics') in edges, 'the folder graph misses its edges'
    cycle = _cycle(edges)
    assert not cycle, 'folders import each other: ' + ' -> '.join(cycle)


#: What the package root may hold: the public face and the entry point.
ROOT_MODULES = {'__init__.py', '__main__.py'}


def test_the_root_holds_the_face_only():
    """Every module lives in a folder that names its job; at the root only the face
    (``__init__``: the public names) and ``__main__``, or a private helper (``_name.py``)."""
    loose = sorted(p.name for p in PACKAGE.glob('*.py')
                   if p.name not in ROOT_MODULES and not p.name.startswith('_'))
    assert not loose, f'modules at the package root: {loose}'


def test_no_issue_numbers_in_the_code():
    """Code explains itself; the tracker's numbers belong in commit messages."""
    pattern = re.compile(r'\bissues? ?\d+(\.\d+)?', re.IGNORECASE)
    root = PACKAGE.parent
    files = [p for d in (PACKAGE, root / 'test', root / 'benchmarks', root / 'launch')
             for p in sorted(d.rglob('*.py'))] + sorted((root / 'scripts').glob('*'))
    bad = [f'{p.relative_to(root)}:{n}: {line.strip()}' for p in files if p.is_file()
           for n, line in enumerate(p.read_text().splitlines(), 1) if pattern.search(line)]
    assert not bad, 'issue numbers in the code:\n' + '\n'.join(bad)


#: Where the kernel's packed parameter vector is made and read by index: the model
#: (``pack_parameters`` and :class:`DriveModel` in model, the ``P_*`` layout in layout, the
#: equations that read it), its inverse (the same equations solved for theta1) and the
#: integrator (with its step's pieces, the set-valued friction trials and the variable
#: step, which sets the step's inertias and load).
PACKED_LAYOUT_OWNERS = {f'{ROOT}/dynamics/model.py', f'{ROOT}/dynamics/layout.py',
                        f'{ROOT}/dynamics/equations.py', f'{ROOT}/dynamics/inverse.py',
                        f'{ROOT}/dynamics/integrator.py', f'{ROOT}/dynamics/newmark.py',
                        f'{ROOT}/dynamics/set_valued.py', f'{ROOT}/dynamics/adaptive.py',
                        f'{ROOT}/dynamics/step_control.py'}
#: What names the packed layout: its indices and the function that fills it.
PACKED_LAYOUT_NAME = re.compile(r'\b(P_[A-Z][A-Z0-9_]*|N_PARAMS|pack_parameters)\b')


def _sources_outside_the_model() -> list[Path]:
    """The package's and the benchmarks' modules, model and integrator aside."""
    root = PACKAGE.parent
    files = sorted(PACKAGE.rglob('*.py')) + sorted((root / 'benchmarks').rglob('*.py'))
    return [p for p in files if str(p.relative_to(root)) not in PACKED_LAYOUT_OWNERS]


def test_packed_layout_is_private_to_the_model():
    """Outside model and integrator (the package and the benchmarks), code builds a
    DriveModel and reads quantities by name (Config, Derived, DriveModel properties), passes
    ``model.p`` on to the compiled functions, and never names a ``P_*`` index or calls
    ``pack_parameters`` (a packed vector made twice is a model built twice)."""
    root = PACKAGE.parent
    files = _sources_outside_the_model()
    assert any(p.name == 'usability.py' for p in files) and any(
        p.parent.name == 'benchmarks' for p in files), 'the scan misses the modules it judges'
    bad = [f'{p.relative_to(root)}:{n}: {line.strip()}' for p in files
           for n, line in enumerate(p.read_text().splitlines(), 1)
           if PACKED_LAYOUT_NAME.search(line)]
    assert not bad, 'the packed layout outside the model:\n' + '\n'.join(bad)


def test_the_layout_rule_sees_a_reader():
    """The pattern catches the forms a reader would take (guards against a rule that
    silently matches nothing)."""
    for text in ('from .model import P_KW', 'p[P_WORM_X0]', 'pack_parameters(cfg)',
                 'np.zeros(N_PARAMS)'):
        assert PACKED_LAYOUT_NAME.search(text), text
    for text in ('DriveModel(cfg).p', 'model.output_per_input', 'AUX_WN', 'P_J'.lower()):
        assert not PACKED_LAYOUT_NAME.search(text), text


#: The drive's physics: one subpackage, nothing of it left at the package root.
PHYSICS_MODULES = ('model', 'equations', 'layout', 'inverse', 'integrator', 'modal',
                   'stepping', 'simulation', 'trajectory', 'profiles', 'load', 'usability')
#: Longest file of the package and the benchmarks, and of the node (the wing stays thin).
MAX_LINES = 600
MAX_NODE_LINES = 500


def test_the_physics_lives_in_dynamics():
    """Each physics module is in ``dynamics/`` and nowhere else; ``dynamics/__init__.py``
    exports nothing (the public names have one home: the package root)."""
    for name in PHYSICS_MODULES:
        assert (PACKAGE / 'dynamics' / f'{name}.py').is_file(), name
        assert not (PACKAGE / f'{name}.py').exists(), f'{name}.py at the package root'
    init = ast.parse((PACKAGE / 'dynamics' / '__init__.py').read_text())
    assert all(isinstance(n, ast.Expr) for n in init.body), 'dynamics/__init__.py defines code'


def _source_files() -> list[Path]:
    root = PACKAGE.parent
    return sorted(PACKAGE.rglob('*.py')) + sorted((root / 'benchmarks').rglob('*.py'))


def test_no_file_is_too_long():
    """No module of the package or the benchmarks over MAX_LINES lines; the node (the ROS
    wing's biggest room) under MAX_NODE_LINES."""
    root = PACKAGE.parent
    lengths = {p.relative_to(root).as_posix(): len(p.read_text().splitlines())
               for p in _source_files()}
    assert len(lengths) > 50, 'the scan misses the files it judges'
    bad = [f'{p}: {n} lines' for p, n in lengths.items() if n > MAX_LINES]
    assert not bad, f'files over {MAX_LINES} lines:\n' + '\n'.join(bad)
    node = lengths[f'{ROOT}/ros/node.py']
    assert node <= MAX_NODE_LINES, f'ros/node.py: {node} lines (at most {MAX_NODE_LINES})'


#: Longest plain-Python function or method (a numba kernel, decorated ``@njit``/``@jit``,
#: is judged by its speed, not here): past it, a function becomes named steps.
MAX_FUNCTION_LINES = 80


def _compiled(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    """Decorated by numba's ``njit``/``jit`` (bare, called, or as ``numba.njit``)."""
    for d in fn.decorator_list:
        target = d.func if isinstance(d, ast.Call) else d
        name = target.attr if isinstance(target, ast.Attribute) else \
            target.id if isinstance(target, ast.Name) else ''
        if name in ('njit', 'jit'):
            return True
    return False


def _long_functions(limit: int) -> dict[str, int]:
    """'path:qualified name' -> lines (the ``def`` line through the last), of each plain
    function or method of the package longer than ``limit``."""
    root = PACKAGE.parent
    out: dict[str, int] = {}

    def visit(node: ast.AST, prefix: str, path: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                n = child.end_lineno - child.lineno + 1
                if n > limit and not _compiled(child):
                    out[f'{path}:{name}'] = n
                visit(child, name + '.', path)
            elif isinstance(child, ast.ClassDef):
                visit(child, prefix + child.name + '.', path)
            else:
                visit(child, prefix, path)

    for p in sorted(PACKAGE.rglob('*.py')):
        visit(ast.parse(p.read_text()), '', p.relative_to(root).as_posix())
    return out


def test_no_plain_function_is_too_long():
    """No plain-Python function or method of the package over MAX_FUNCTION_LINES lines."""
    assert _long_functions(20), 'the scan misses the functions it judges'
    long = _long_functions(MAX_FUNCTION_LINES)
    bad = [f'{k}: {n} lines' for k, n in sorted(long.items())]
    assert not bad, (f'functions over {MAX_FUNCTION_LINES} lines (split them into named '
                     'steps):\n' + '\n'.join(bad))


def test_the_length_rule_sees_kernels_and_methods():
    """The scan tells a numba kernel from plain code and names a method by its class."""
    tree = ast.parse('@njit(cache=True)\ndef k(): pass\n@numba.jit\ndef j(): pass\n'
                     '@functools.cache\ndef f(): pass\n')
    assert [_compiled(f) for f in tree.body] == [True, True, False]
    assert any('.' in k.split(':')[1] for k in _long_functions(20)), 'no method scanned'


def _alike(a: str, b: str) -> bool:
    """``b`` is ``a`` in the plural or with a suffix (``model`` / ``models``,
    ``model`` / ``model_check``): two names a reader mistakes for each other."""
    return a != b and (b in (a + 's', a + 'es') or b.startswith(a + '_'))


def test_no_two_modules_of_a_folder_are_named_alike():
    """In one folder, no module is another's name in the plural or with a suffix
    (``trajectory`` beside ``trajectories``, ``model`` beside ``model_check``)."""
    assert _alike('trajectory', 'trajectorys') and _alike('model', 'model_check')
    assert _alike('process', 'processes') and not _alike('model', 'modal')
    folders: dict[Path, list[str]] = {}
    for p in sorted(PACKAGE.rglob('*.py')):
        if p.name != '__init__.py':
            folders.setdefault(p.parent, []).append(p.stem)
    for p in sorted(PACKAGE.rglob('__init__.py')):   # a subpackage is a name in its parent
        if p.parent != PACKAGE:
            folders.setdefault(p.parent.parent, []).append(p.parent.name)
    bad = [f'{d.relative_to(PACKAGE.parent)}: {a}, {b}' for d, names in folders.items()
           for a in names for b in names if _alike(a, b)]
    assert not bad, 'modules named alike:\n' + '\n'.join(bad)


def _exported(path: Path) -> set[str]:
    """The names a module lists in ``__all__`` (none when it has no literal ``__all__``)."""
    for node in ast.parse(path.read_text()).body:
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and isinstance(node.targets[0], ast.Name) and node.targets[0].id == '__all__'
                and isinstance(node.value, (ast.List, ast.Tuple))):
            return {ast.literal_eval(e) for e in node.value.elts}
    return set()


def test_config_error_has_one_home():
    """``ConfigError`` is exported by one module of the package (and by the package root,
    the public face), and everybody imports it from there."""
    homes = sorted(_module_name(p) for p in PACKAGE.rglob('*.py')
                   if p != PACKAGE / '__init__.py' and 'ConfigError' in _exported(p))
    assert homes == [f'{ROOT}.schema.validation'], homes
    bad = [f'{i.source}:{i.line} takes ConfigError from {i.target}' for i in IMPORTS
           if 'ConfigError' in i.names and i.target not in (f'{ROOT}.schema.validation', ROOT)]
    assert not bad, '\n'.join(bad)



def _defined(tree: ast.Module) -> set[str]:
    """The names a module's own top-level statements bind (classes, functions, constants)."""
    names = {n.name for n in tree.body
             if isinstance(n, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))}
    for n in tree.body:
        targets = n.targets if isinstance(n, ast.Assign) else (
            [n.target] if isinstance(n, ast.AnnAssign) else [])
        for t in targets:
            names |= {e.id for e in ast.walk(t) if isinstance(e, ast.Name)}
    return names


def test_a_module_exports_only_what_it_defines():
    """One home per exported name: a module's ``__all__`` lists only names it defines
    (``ros/node.py`` does not hand on the core's classes, ``simulation`` not the results of
    a run, ``params`` not the schema's names); the public names are gathered by the
    packages' ``__init__.py`` (the public face), not re-exported module by module."""
    bad = []
    for p in sorted(PACKAGE.rglob('*.py')):
        if p.name == '__init__.py':
            continue
        foreign = _exported(p) - _defined(ast.parse(p.read_text()))
        if foreign:
            bad.append(f'{_module_name(p)} re-exports {sorted(foreign)}')
    assert not bad, '\n'.join(bad)


def test_the_readme_is_a_front_door():
    """The README says what the project is, its Quick-start commands (the demo and the
    tests first), one picture and where the docs are, in at most 200 lines; the details
    live in docs/, and every doc it links to exists."""
    root = PACKAGE.parent
    text = (root / 'README.md').read_text()
    assert len(text.splitlines()) <= 200, f'README.md: {len(text.splitlines())} lines'
    commands = re.findall(r'^(scripts/\w+\.sh)\b', text, re.MULTILINE)
    assert commands[:3] == ['scripts/run_demo.sh', 'scripts/run_tests.sh',
                            'scripts/run_pass.sh'], commands
    links = re.findall(r'\]\((docs/[^)#]+)', text)
    assert 'docs/performance.md' in links and any(p.endswith('.png') for p in links)
    missing = [p for p in links if not (root / p).is_file()]
    assert not missing, f'README links to missing files: {missing}'


#: Longest module docstring: what the module is for and what it holds, in a few lines; the
#: design it follows is on the docs page that owns it (docs/*.md), its history in git.
MAX_DOCSTRING_LINES = 15
#: Modules being re-cut where their jobs part (files near the line cap): their docstrings are
#: cut with them.  Each entry must still need it (the test says when one no longer does).
LONG_DOCSTRING_ALLOWED: set[str] = set()


def _docstring_lines(path: Path) -> int:
    """How many lines the module's docstring spans (0 without one)."""
    body = ast.parse(path.read_text()).body
    first = body[0] if body else None
    if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
            and isinstance(first.value.value, str)):
        return (first.end_lineno or first.lineno) - first.lineno + 1
    return 0


def test_module_docstrings_say_what_the_module_is_for():
    """No module docstring of the package over MAX_DOCSTRING_LINES lines (a design note belongs
    in docs/), but those of LONG_DOCSTRING_ALLOWED, each of which must still be over it."""
    lengths = {p.relative_to(PACKAGE).as_posix(): _docstring_lines(p)
               for p in sorted(PACKAGE.rglob('*.py'))}
    assert lengths['__init__.py'] > 0 and len(lengths) > 50, 'the scan misses the docstrings'
    missing = sorted(LONG_DOCSTRING_ALLOWED - lengths.keys())
    assert not missing, f'allowed files that no longer exist: {missing}'
    bad = [f'{ROOT}/{p}: {n} lines' for p, n in lengths.items()
           if n > MAX_DOCSTRING_LINES and p not in LONG_DOCSTRING_ALLOWED]
    assert not bad, (f'module docstrings over {MAX_DOCSTRING_LINES} lines:\n' + '\n'.join(bad))
    done = sorted(p for p in LONG_DOCSTRING_ALLOWED if lengths[p] <= MAX_DOCSTRING_LINES)
    assert not done, f'short now, drop from LONG_DOCSTRING_ALLOWED: {done}'
