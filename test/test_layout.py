# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
The layout's rules: imports run down the floors, the algorithm does not depend on ROS.

Floors, lowest first; a package may import its own modules and those of lower floors:

1. ``core``: the algorithm.
2. ``viz`` (drawing), ``io`` (files, bags, media, camera inputs), ``ros`` (message adapters,
   names, QoS). On this floor, ``io`` may use ``viz`` (a received scene as a PNG) and ``ros`` may
   use ``io`` and ``viz`` (bag conversions, marker colours); ``viz`` uses neither.
3. ``pose2d``, ``sim``, ``eval``: the 2D stage, the simulator, the metrics (not each other).
4. ``nodes``, ``commands``, ``testing`` (the test and bench harness), ``cli``: the top. Nodes
   and commands do not import each other; ``testing`` may use both, ``cli`` loads commands.

Inside ``core`` the same rule holds between its stages (``CORE_STAGES``): the shared modules at
its root (types, skeleton, assignment, files, diagnostic keys) import no stage; ``geometry``,
``tracking``, ``fusion`` (with ``selfcal`` beside it) and ``live`` import only the stages below.

No command imports another command, except ``demo``, which runs the others. Function-level
(lazy) imports count: they are imports all the same.

``core/``, ``viz/``, ``io/``, ``eval/`` and ``sim/`` import nothing of ROS at all; ``pose2d/``
(models, inference, the inference-rate policy) nothing at module level (``fetch`` reads a
rosbag2 bag's images inside one function, for calibration). The nodes are the adapters.
"""

import ast
import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(ROOT, 'mv3dpose_ros')
ROS_FREE = {'core': 'anywhere', 'viz': 'anywhere', 'io': 'anywhere', 'eval': 'anywhere',
            'sim': 'anywhere', 'pose2d': 'module level'}
FLOORS = (('core',), ('viz', 'io', 'ros'), ('pose2d', 'sim', 'eval'),
          ('nodes', 'commands', 'testing', 'cli'))
FLOOR = {package: level for level, floor in enumerate(FLOORS) for package in floor}
#: Imports allowed between different packages of one floor: (importer, imported).
SIDEWAYS = {('io', 'viz'), ('ros', 'io'), ('ros', 'viz'),
            ('testing', 'nodes'), ('testing', 'commands'), ('cli', 'commands')}
#: The stages of ``core``, lowest first; ``''`` is the shared modules at its root.
CORE_STAGES = (('',), ('geometry',), ('tracking',), ('fusion', 'selfcal'), ('live',))
CORE_STAGE = {stage: level for level, floor in enumerate(CORE_STAGES) for stage in floor}
#: The one command that may import other commands (it runs them).
RUNS_COMMANDS = 'demo'


def _is_ros(module: str) -> bool:
    top = module.split('.')[0]
    return (top in ('rclpy', 'rosidl_runtime_py', 'rosbag2_py', 'builtin_interfaces')
            or top.endswith('_msgs') or top.endswith('_srvs')
            or module.startswith(('mv3dpose_ros.ros', 'mv3dpose_ros.nodes')))


def _ros_imports(path: str, module_level_only: bool):
    tree = ast.parse(open(path).read(), path)
    nodes = tree.body if module_level_only else list(ast.walk(tree))
    for node in nodes:
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names = [node.module]
        else:
            continue
        for name in names:
            if _is_ros(name):
                yield f'{os.path.relpath(path, ROOT)}:{node.lineno} imports {name}'


def _modules():
    """Yield ``(dotted name, path)`` of every module of the package."""
    for folder, dirs, files in os.walk(PACKAGE):
        dirs[:] = sorted(d for d in dirs if d != '__pycache__')
        for name in sorted(files):
            if name.endswith('.py'):
                path = os.path.join(folder, name)
                parts = os.path.relpath(path[:-3], ROOT).split(os.sep)
                yield '.'.join(parts[:-1] if parts[-1] == '__init__' else parts), path


def _package_imports(module: str, path: str, module_level_only: bool = False):
    """Yield ``(line, imported module)`` for each import of an ``mv3dpose_ros`` module."""
    tree = ast.parse(open(path).read(), path)
    is_package = path.endswith('__init__.py')
    nodes = tree.body if module_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ''
            if node.level:                                   # relative: resolve it
                parts = module.split('.')
                keep = len(parts) - node.level + (1 if is_package else 0)
                base = '.'.join(parts[:keep] + ([base] if base else []))
            # `from mv3dpose_ros.x import y`: y may be a module of x
            targets = [f'{base}.{a.name}' if os.path.exists(
                os.path.join(ROOT, *base.split('.'), a.name + '.py')) or os.path.isdir(
                os.path.join(ROOT, *base.split('.'), a.name)) else base for a in node.names]
        else:
            continue
        for target in sorted(set(targets)):
            if target == 'mv3dpose_ros' or target.startswith('mv3dpose_ros.'):
                yield node.lineno, target


def _package_of(module: str) -> str:
    parts = module.split('.')
    return parts[1] if len(parts) > 1 else ''


def test_every_package_has_a_floor():
    packages = {_package_of(m) for m, _ in _modules()} - {''}
    assert packages <= set(FLOOR), f'no floor for {sorted(packages - set(FLOOR))}'


def test_imports_run_down_the_floors():
    """No module imports a higher floor, nor a package beside it that the floors forbid."""
    found = []
    for module, path in _modules():
        mine = _package_of(module)
        for line, target in _package_imports(module, path):
            theirs = _package_of(target)
            if not mine or not theirs or theirs == mine:
                continue
            if FLOOR[theirs] > FLOOR[mine] or (FLOOR[theirs] == FLOOR[mine]
                                               and (mine, theirs) not in SIDEWAYS):
                found.append(f'{os.path.relpath(path, ROOT)}:{line}: {mine} (floor '
                             f'{FLOOR[mine] + 1}) imports {target} (floor {FLOOR[theirs] + 1})')
    assert not found, '\n'.join(found)


def _stage_of(module: str) -> str:
    """Return the ``core`` stage of a module (``''`` for the shared modules at core's root)."""
    parts = module.split('.')
    return parts[2] if len(parts) > 3 else ''


def test_core_stages_import_downward():
    """A stage of ``core`` imports the shared modules and lower stages, never one beside it."""
    found = []
    for module, path in _modules():
        if _package_of(module) != 'core' or module == 'mv3dpose_ros.core':
            continue
        mine = _stage_of(module)
        for line, target in _package_imports(module, path):
            if _package_of(target) != 'core' or target == 'mv3dpose_ros.core':
                continue
            theirs = _stage_of(target)
            if theirs != mine and CORE_STAGE[theirs] >= CORE_STAGE[mine]:
                found.append(f'{os.path.relpath(path, ROOT)}:{line}: core stage '
                             f'{mine or "(shared)"} imports {target}')
    assert not found, '\n'.join(found)


def test_every_core_stage_has_a_map_and_all():
    """Each stage package names its modules in its docstring and lists them in ``__all__``."""
    core = os.path.join(PACKAGE, 'core')
    stages = sorted(d for d in os.listdir(core)
                    if os.path.isfile(os.path.join(core, d, '__init__.py')))
    assert set(stages) == {s for floor in CORE_STAGES for s in floor} - {''}
    problems = []
    for stage in stages:
        tree = ast.parse(open(os.path.join(core, stage, '__init__.py')).read())
        doc = ast.get_docstring(tree) or ''
        modules = sorted(n[:-3] for n in os.listdir(os.path.join(core, stage))
                         if n.endswith('.py') and n != '__init__.py')
        listed = [ast.literal_eval(node.value) for node in tree.body
                  if isinstance(node, ast.Assign) and node.targets[0].id == '__all__']
        if listed != [modules]:
            problems.append(f'core/{stage}: __all__ {listed} is not its modules {modules}')
        problems += [f'core/{stage}/__init__.py does not name {m}' for m in modules
                     if f':mod:`.{m}`' not in doc]
    assert not problems, '\n'.join(problems)


def test_no_command_imports_another_but_the_demo():
    found = []
    for module, path in _modules():
        if _package_of(module) != 'commands' or module.split('.')[-1] in (RUNS_COMMANDS,
                                                                          'commands'):
            continue
        for line, target in _package_imports(module, path):
            if _package_of(target) == 'commands' and target != module:
                found.append(f'{os.path.relpath(path, ROOT)}:{line} imports {target}')
    assert not found, '\n'.join(found)


def test_no_import_cycles_between_modules():
    """Module-level imports form no cycle (a cycle half-initialises a module on import)."""
    modules = dict(_modules())
    graph = {m: {t if t in modules else t.rsplit('.', 1)[0]
                 for _, t in _package_imports(m, p, module_level_only=True)} - {m}
             for m, p in modules.items()}
    state = {}

    def visit(m, stack):
        state[m] = 'open'
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 'open':
                return stack[stack.index(n):] + [n] if n in stack else [m, n]
            if n not in state:
                cycle = visit(n, stack + [n])
                if cycle:
                    return cycle
        state[m] = 'done'
        return None

    for m in sorted(graph):
        if m not in state:
            cycle = visit(m, [m])
            assert cycle is None, ' -> '.join(cycle)


@pytest.mark.parametrize('package', sorted(ROS_FREE))
def test_the_algorithm_and_the_2d_logic_import_no_ros(package):
    found = []
    for module, path in _modules():
        if _package_of(module) == package:
            found += _ros_imports(path, ROS_FREE[package] == 'module level')
    assert not found, '\n'.join(found)


def test_the_ros_free_packages_load_without_rclpy():
    """Importing every module of them loads no rclpy (nor any message package)."""
    modules = [m for m, _ in _modules() if _package_of(m) in ROS_FREE]
    code = ('import importlib, sys\n'
            f'for m in {modules!r}: importlib.import_module(m)\n'
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'rclpy'"
            " or m.split('.')[0].endswith('_msgs')))\n")
    out = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                         text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == '[]', out.stdout


def test_every_module_is_in_its_package_map():
    """Each package's docstring names each of its modules (``:mod:`.name```): a real map."""
    missing = []
    packages = sorted(os.path.relpath(folder, PACKAGE) for folder, dirs, files in
                      os.walk(PACKAGE) if '__init__.py' in files and folder != PACKAGE
                      and '__pycache__' not in folder)
    for package in packages:         # nested ones too (core/fusion, nodes/fusion, ros/system)
        path = os.path.join(PACKAGE, package)
        init = os.path.join(path, '__init__.py')
        doc = ast.get_docstring(ast.parse(open(init).read())) or ''
        for name in sorted(os.listdir(path)):
            module = name[:-3] if name.endswith('.py') else name
            if module == '__init__' or not (
                    name.endswith('.py') or os.path.isfile(os.path.join(path, name,
                                                                        '__init__.py'))):
                continue
            if f':mod:`.{module}`' not in doc:
                missing.append(f'mv3dpose_ros/{package}/__init__.py does not name {module}')
    assert not missing, '\n'.join(missing)


#: The most lines and instance attributes a class under ``core/`` may have: past them it
#: holds several ideas, each of which deserves its own name.
MAX_CLASS_LINES, MAX_CLASS_ATTRIBUTES = 400, 20


def _instance_attributes(cls: ast.ClassDef) -> set:
    """Return the names ``x`` of every ``self.x = ...`` (plain, augmented, unpacked) in ``cls``."""
    names = set()
    for node in ast.walk(cls):
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, (ast.AugAssign, ast.AnnAssign)) else []
        for target in targets:
            for t in ast.walk(target):
                if isinstance(t, ast.Attribute) and isinstance(t.value, ast.Name) \
                        and t.value.id == 'self' and isinstance(t.ctx, ast.Store):
                    names.add(t.attr)
    return names


def test_no_core_class_over_400_lines_or_20_attributes():
    """Every class of the algorithm is one idea: at most 400 lines and 20 instance attributes."""
    found = []
    for module, path in _modules():
        if _package_of(module) != 'core':
            continue
        for node in ast.walk(ast.parse(open(path).read())):
            if not isinstance(node, ast.ClassDef):
                continue
            lines = node.end_lineno - node.lineno + 1
            attributes = len(_instance_attributes(node))
            if lines > MAX_CLASS_LINES or attributes > MAX_CLASS_ATTRIBUTES:
                found.append(f'{os.path.relpath(path, ROOT)}:{node.lineno}: {node.name} has '
                             f'{lines} lines and {attributes} instance attributes')
    assert not found, '\n'.join(found)


def test_tests_and_benches_reach_the_package_through_public_names():
    """Tests and benches observe what users observe: no ``_private`` name of the package."""
    found = []
    for where in ('test', 'bench'):
        for name in sorted(os.listdir(os.path.join(ROOT, where))):
            if not name.endswith('.py'):
                continue
            path = os.path.join(ROOT, where, name)
            for node in ast.walk(ast.parse(open(path).read(), path)):
                if isinstance(node, ast.ImportFrom) and (node.module or '').startswith(
                        'mv3dpose_ros'):
                    found += [f'{where}/{name}:{node.lineno} imports {a.name}'
                              for a in node.names if a.name.startswith('_')
                              and not a.name.startswith('__')]
                elif isinstance(node, ast.Attribute) and node.attr.startswith('_') and \
                        not node.attr.startswith('__') and node.attr not in (
                            '_exit', '_getframe', '_replace', '_asdict', '_fields', '_make'):
                    found.append(f'{where}/{name}:{node.lineno} reads .{node.attr}')
    assert len(found) <= 10, '\n'.join(found)
