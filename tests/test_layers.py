"""The packages form layers: no module imports a higher layer, and no import cycle exists.

``python -m tests.import_graph`` prints the graph these tests check.
"""

from __future__ import annotations

import subprocess
import sys

from tests.import_graph import (
    LAYERS,
    ROOT,
    cycles,
    module_graph,
    package_graph,
    private_imports,
    sublayer_upward_edges,
    upward_edges,
)


def test_no_module_imports_a_higher_layer() -> None:
    graph = module_graph()
    assert upward_edges(graph) == []
    packages = package_graph(graph)
    for package, imported in packages.items():
        assert all(LAYERS.index(p) < LAYERS.index(package) for p in imported), package


def test_no_sub_package_imports_a_higher_one() -> None:
    """Inside identification: the roll model, recordings, instruments, the estimation
    core, the methods, the reports, the commands, each importing only those before it."""
    assert sublayer_upward_edges(module_graph()) == []
    graph = {"identification.recordings.a": {"identification.methods.b"}}
    assert sublayer_upward_edges(graph) == [
        ("identification.recordings.a", "identification.methods.b")
    ]


def test_the_store_only_stores() -> None:
    """The SQLite store imports no domain module but the recording type it returns (an
    annotation): the rows check their names, and the registered methods are asked above
    it (``disturbances.stores``), once for every back end."""
    graph = module_graph()
    domain = {m for m in graph["disturbances.db"] if m.startswith("identification")}
    assert domain == {"identification.recordings.recording"}
    assert "identification.methods" in graph["disturbances.stores"]


def test_each_command_lives_in_the_lowest_package_that_imports_what_it_uses() -> None:
    """A command's module imports its own package: with only lower packages' modules
    imported it would belong lower down."""
    from rocketroll.cli import COMMANDS

    graph = module_graph()
    for module in {m for m, _ in COMMANDS.values()}:
        package = module.split(".")[0]
        own = {m for m in graph[module] if m.split(".")[0] == package}
        assert own, f"{module} uses nothing of {package}"


def test_the_modules_import_one_another_without_a_cycle() -> None:
    assert cycles(module_graph()) == []


def test_no_module_imports_another_modules_private_names() -> None:
    """What a module keeps private (``_name``) is its own: a name two modules need is
    public in the one that defines it."""
    assert private_imports() == []


def test_the_checks_can_fail() -> None:
    """The checks see a cycle and an upward edge when there is one."""
    graph = {"identification.a": {"agents.b"}, "agents.b": {"identification.a"}}
    assert cycles(graph) == [["agents.b", "identification.a", "agents.b"]]
    assert upward_edges(graph) == [("identification.a", "agents.b")]


def test_the_graph_sees_lazy_and_type_checking_imports() -> None:
    graph = module_graph()
    assert "rollenv.render" in graph["rollenv.env"]  # imported inside render()
    assert "rollenv.core" in graph["rollenv.history"]
    assert graph["rocketroll_common.errors"] == set()  # the bottom imports nothing of ours


def test_the_script_prints_the_graph_and_the_verdict() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "tests.import_graph"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "identification     -> rocketroll_common" in done.stdout
    assert done.stdout.rstrip().endswith("0 cycles, 0 upward edges")
