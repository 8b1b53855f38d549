"""The environment is input (``stillframe/config/environment.py``): every variable the code reads
is declared, read through the declaration, checked with generated hostile values, and documented
by the generated table in docs/middleware.md."""

from __future__ import annotations

import ast
import functools
import itertools
import random
import re
from pathlib import Path

import pytest

from stillframe.config import environment
from stillframe.config.environment import BY_NAME, VARIABLES, check_environment, value
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT

SOURCES = ("stillframe", "sim_node", "estimator_node", "controller_node", "container_node",
           "identification")
#: names of variables of ROS 2 and of this project
NAME = re.compile(r"\b(ROS_[A-Z_]+|RMW_IMPLEMENTATION|CYCLONEDDS_URI|STILLFRAME_[A-Z_]+)\b")
#: reads of the environment outside the declarations, and why: each sets a variable for its own
#: children or restores one it set
OWN_READS = {
    "stillframe/app/bench/loop.py": "sets its child processes' backend, then restores it",
    "stillframe/app/netns_lab.py": "sets the observer's discovery for a block, then restores it",
    "stillframe/studies/cluster.py": "PYTHONPATH of the dask workers it starts",
}

#: what any variable may be given: the issue's values and a seeded draw of text
HOSTILE = ["-1", "233", "999", "abc", "$$$", " 7 ", "1e3", "0x10", "nan", "inf", "1.5",
           "٣", "a b", "x" * 5000, "\udcff", ";;", "localhost;$$$", "rmw_", "RMW_FASTRTPS_CPP",
           "/nonexistent", "0", "1", "232", "SUBNET", "dds"]


def generated(rng: random.Random, count: int) -> list[str]:
    alphabet = "0123456789abcXYZ-_.;:$ /\t[]"
    return ["".join(rng.choice(alphabet) for _ in range(rng.randrange(1, 12)))
            for _ in range(count)]


@pytest.mark.parametrize("variable", VARIABLES, ids=lambda v: v.name)
def test_every_variable_takes_only_what_it_may(variable: environment.Variable) -> None:
    """Each value: refused in one short line naming the variable, or a value the check calls
    good (then check_environment takes it too). Unset and empty are the default."""
    values = HOSTILE + generated(random.Random(variable.name), 60)
    for text in values:
        environ = {variable.name: text}
        try:
            got = value(variable.name, environ)
        except InputError as exc:
            message = str(exc)
            assert message.startswith(f"{variable.name}=") and "\n" not in message, message
            assert len(message) < 200, message
            with pytest.raises(InputError):
                check_environment(environ)
            continue
        assert got == (text.strip() or variable.default)
        assert not text.strip() or variable.check(got) is None
        check_environment(environ)
    assert value(variable.name, {}) == value(variable.name, {variable.name: " "}) == \
        variable.default


@pytest.mark.parametrize(("name", "good", "bad"), [
    ("ROS_DOMAIN_ID", ["0", "42", "232"], ["-1", "233", "999", "abc", "٣", "1.0", "+1"]),
    ("ROS_STATIC_PEERS", ["localhost", "192.168.0.1;host-a.lab", "[::1]", "fe80::1;a.b.c."],
     ["$$$", "a b", "-host", "host-", "a..b", "x" * 64, "localhost;$$$"]),
    ("ROS_AUTOMATIC_DISCOVERY_RANGE", ["SUBNET", "LOCALHOST", "OFF", "SYSTEM_DEFAULT"],
     ["subnet", "ALL", "1"]),
    ("ROS_LOCALHOST_ONLY", ["0", "1"], ["2", "true", "yes"]),
    ("RMW_IMPLEMENTATION", ["rmw_fastrtps_cpp", "rmw_cyclonedds_cpp"],
     ["fastrtps", "rmw_", "rmw-x", "RMW_FASTRTPS_CPP"]),
    ("STILLFRAME_RMW", ["dds", "rclpy"], ["fastrtps", "DDS"]),
    ("STILLFRAME_DAEMON_IDLE_S", ["1", "0.5", "7200"], ["0", "-1", "nan", "inf", "1e7", "x"]),
    ("STILLFRAME_DATASETS", [str(REPO_ROOT / "datasets")],
     ["/nonexistent", str(REPO_ROOT / "README.md"), "/dev/null"]),
])
def test_the_issue_values(name: str, good: list[str], bad: list[str]) -> None:
    for text in good:
        assert value(name, {name: text}) == text
    for text in bad:
        with pytest.raises(InputError, match=f"^{name}="):
            value(name, {name: text})


def test_the_documented_table_is_the_declared_one() -> None:
    page = (REPO_ROOT / "docs" / "middleware.md").read_text()
    assert environment.with_reference(page) == page, \
        "run: python -m stillframe.config.environment"
    for variable in VARIABLES:
        assert f"| `{variable.name}` |" in page


@functools.cache
def _sources() -> list[tuple[str, ast.AST]]:
    return [(str(path.relative_to(REPO_ROOT)), ast.parse(path.read_text()))
            for package in SOURCES for path in sorted((REPO_ROOT / package).rglob("*.py"))]


def test_every_variable_the_code_names_is_declared() -> None:
    """Every ROS_*, RMW_IMPLEMENTATION, CYCLONEDDS_URI and STILLFRAME_* named in the library's
    code (outside docstrings) is declared."""
    named = set()
    for _module, tree in _sources():
        docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                      if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef)
                      and node.body and isinstance(node.body[0], ast.Expr)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and id(node) not in docstrings:
                named.update(NAME.findall(node.value))
    assert named, "the scan found no variable at all"
    assert named <= set(BY_NAME), f"read but not declared: {named - set(BY_NAME)}"


def test_the_environment_is_read_only_through_the_declarations() -> None:
    """``os.environ.get``, ``os.getenv`` and ``os.environ[NAME]`` read nowhere but in the
    declarations' module, and where a process sets a variable of its own (:data:`OWN_READS`)."""
    found = set()
    for module, tree in _sources():
        if module == "stillframe/config/environment.py":
            continue
        for node in ast.walk(tree):
            text = ast.unparse(node) if isinstance(node, ast.Call | ast.Subscript) else ""
            if (isinstance(node, ast.Call) and re.match(r"os\.(environ\.get|getenv)\(", text)) \
                    or (isinstance(node, ast.Subscript) and isinstance(node.ctx, ast.Load)
                        and text.startswith("os.environ[")):
                found.add(module)
    assert found == set(OWN_READS), found ^ set(OWN_READS)


def test_a_combination_of_bad_variables_names_the_first_declared() -> None:
    """Several bad values at once: the message names one of them, the first in the table."""
    bad = {"ROS_DOMAIN_ID": "-1", "ROS_STATIC_PEERS": "$$$", "STILLFRAME_RMW": "x"}
    for pair in itertools.combinations(bad, 2):
        first = next(v.name for v in VARIABLES if v.name in pair)
        with pytest.raises(InputError, match=f"^{first}="):
            check_environment({k: bad[k] for k in pair})


def test_a_source_with_an_undeclared_variable_fails_the_scan(tmp_path: Path) -> None:
    """The scan can fail: a new name in code is found (docstrings are not code)."""
    tree = ast.parse('"""Reads STILLFRAME_DOCUMENTED."""\nx = os.environ.get("STILLFRAME_NEW")\n')
    names = {m for node in ast.walk(tree) if isinstance(node, ast.Constant)
             and isinstance(node.value, str) and node is not tree.body[0].value
             for m in NAME.findall(node.value)}
    assert names == {"STILLFRAME_NEW"}
