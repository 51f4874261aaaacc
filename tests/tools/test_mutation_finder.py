"""The test-finder: a module's tests from what they import, lazily or through a package."""

from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

from tools.mutation import finder, modules

ROOT = Path(__file__).resolve().parents[2]

PYPROJECT = """\
[tool.setuptools.package-dir]
"haptic.common" = "common"
"haptic.master" = "master"
"""


def write(root: Path, files: dict[str, str]) -> Path:
    """Write ``files`` (path -> text, dedented) under ``root``; return ``root``."""
    for path, text in files.items():
        (root / path).parent.mkdir(parents=True, exist_ok=True)
        (root / path).write_text(textwrap.dedent(text))
    return root


def project(tmp_path: Path) -> finder.ImportGraph:
    """A small project: a kernel module imported only by its node, a package re-exporting
    a function, and tests importing each way."""
    return finder.ImportGraph(write(tmp_path, {
        "pyproject.toml": PYPROJECT,
        "common/__init__.py": "",
        "common/config/__init__.py": "from .loader import load_config\n",
        "common/config/loader.py": "def load_config():\n    return {}\n",
        "common/guard.py": "LIMIT = 1\n",
        "master/__init__.py": "",
        "master/kernels.py": "GAIN = 2\n",
        "master/node.py": "from haptic.master import kernels\n",
        "tests/test_lazy.py": """\
            def test_guard():
                from haptic.common.guard import LIMIT
                assert LIMIT == 1
            """,
        "tests/test_config.py": "from haptic.common.config import load_config\n",
        "tests/sub/test_node.py": "import haptic.master.node\n",
        "tests/sub/test_helped.py": "from tests.sub.helpers import make\n",
        "tests/sub/helpers.py": "def make():\n    import importlib\n"
                                "    return importlib.import_module('haptic.common.guard')\n",
        "tests/test_other.py": "import os\n",
    }))


def test_module_names_and_files_follow_the_package_dir_mapping(tmp_path: Path) -> None:
    mapping = finder.package_dirs(ROOT)
    assert finder.module_name("master/node.py", mapping) == "haptic.master.node"
    assert finder.module_name("common/runtime/watchdog.py", mapping) == \
        "haptic.common.runtime.watchdog"
    assert finder.module_name("slave_sim/clay/sim.py", mapping) == "haptic.slave_sim.clay.sim"
    assert finder.module_name("common/wire/__init__.py", mapping) == "haptic.common.wire"
    assert finder.module_file("haptic.lockstep.simulator", ROOT, mapping) == \
        "lockstep/simulator.py"
    assert finder.module_file("haptic.common.wire", ROOT, mapping) == "common/wire/__init__.py"
    assert finder.module_file("numpy", ROOT, mapping) is None


def test_a_test_importing_a_module_lazily_is_found(tmp_path: Path) -> None:
    graph = project(tmp_path)
    assert finder.tests_for("common/guard.py", graph) == ["tests/sub/test_helped.py",
                                                          "tests/test_lazy.py"]


def test_a_name_reexported_by_a_package_counts_for_its_defining_module(tmp_path: Path) -> None:
    graph = project(tmp_path)
    assert finder.tests_for("common/config/loader.py", graph) == ["tests/test_config.py"]


def test_a_module_no_test_imports_is_found_through_its_importers(tmp_path: Path) -> None:
    graph = project(tmp_path)
    assert finder.tests_for("master/kernels.py", graph) == ["tests/sub/test_node.py"]
    assert finder.tests_for("master/node.py", graph) == ["tests/sub/test_node.py"]


def test_depth_two_adds_the_tests_of_the_modules_that_import_it(tmp_path: Path) -> None:
    graph = project(tmp_path)
    assert finder.tests_for("common/guard.py", graph, depth=2) == [
        "tests/sub/test_helped.py", "tests/test_lazy.py"]
    write(tmp_path, {"common/user.py": "from haptic.common import guard\n",
                     "tests/test_user.py": "from haptic.common.user import guard\n"})
    graph = finder.ImportGraph(tmp_path)
    assert "tests/test_user.py" not in finder.tests_for("common/guard.py", graph)
    assert "tests/test_user.py" in finder.tests_for("common/guard.py", graph, depth=2)


def test_the_tests_named_for_a_module_come_first_then_the_narrowest(tmp_path: Path) -> None:
    project(tmp_path)
    write(tmp_path, {"tests/test_wide.py": "import haptic.master.node, haptic.common.guard\n",
                     "tests/test_config_limits.py": "import haptic.common.guard\n"})
    graph = finder.ImportGraph(tmp_path)
    tests = ["tests/test_wide.py", "tests/test_lazy.py", "tests/test_config_limits.py"]
    assert finder.ordered("common/config/loader.py", tests, graph) == [
        "tests/test_config_limits.py", "tests/test_lazy.py", "tests/test_wide.py"]
    assert finder.ordered("common/guard.py", tests, graph) == [
        "tests/test_config_limits.py", "tests/test_lazy.py", "tests/test_wide.py"]
    # the test named exactly for the module first, however much more it imports
    write(tmp_path, {"tests/test_guard.py": "import haptic.master.node, haptic.common.guard\n",
                     "tests/test_guard_limits.py": "import haptic.common.guard\n"})
    graph = finder.ImportGraph(tmp_path)
    assert finder.ordered("common/guard.py", [*tests, "tests/test_guard_limits.py",
                                              "tests/test_guard.py"], graph)[:2] == [
        "tests/test_guard.py", "tests/test_guard_limits.py"]


def test_imports_are_read_wherever_they_are() -> None:
    source = textwrap.dedent("""\
        import haptic.master.node as node
        from haptic.common.wire import messages, receive as rx
        if False:
            from haptic.view import cli
        def f():
            import importlib
            return importlib.import_module("haptic.lockstep.simulator")
        """)
    assert finder.imports_of(source) >= {
        "haptic.master.node", "haptic.common.wire", "haptic.common.wire.messages",
        "haptic.common.wire.receive", "haptic.view.cli", "haptic.lockstep.simulator"}
    assert finder.imports_of("from .b import c\n", "haptic.common.a") == {
        "haptic.common.b", "haptic.common.b.c"}


@pytest.fixture(scope="module")
def repository_graph() -> finder.ImportGraph:
    """The repository's import graph, shared: it reads each file once, on first use, and the
    tests below only read it."""
    return finder.ImportGraph(ROOT)


def test_every_configured_module_has_tests_in_the_repository(
        repository_graph: finder.ImportGraph) -> None:
    graph = repository_graph
    for configured in modules.load(ROOT):
        tests = finder.tests_for(configured.path, graph)
        assert tests, configured.path
        assert all((ROOT / t).is_file() for t in tests)
    assert "tests/common/runtime/test_watchdog.py" in finder.tests_for("common/runtime/watchdog.py",
                                                               graph)


def _imported_names(source: str) -> set[str]:
    """The dotted names a file's import statements name, wherever they are (a plain walk of
    the syntax tree, apart from the finder's own reading)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def test_every_test_file_importing_a_configured_module_is_found_for_it(
        repository_graph: finder.ImportGraph) -> None:
    """A test file whose import statements (lazy ones too) name a configured module is one
    of that module's tests."""
    graph = repository_graph
    imported = {test: _imported_names((ROOT / test).read_text())
                for test in graph.test_files()}
    checked = 0
    for configured in modules.load(ROOT):
        name = finder.module_name(configured.path, graph.package_dir)
        importing = {test for test, names in imported.items() if name in names}
        found = finder.tests_for(configured.path, graph, configured.depth)
        assert importing <= set(found), (configured.path, sorted(importing - set(found)))
        checked += bool(importing)
    assert checked > 20
