"""Public callables carry a docstring: at least 90 % of them, as counted by
``tests/support/docstring_coverage.py`` (``python -m tests.support.docstring_coverage --missing``
lists the rest)."""

from __future__ import annotations

from pathlib import Path

from tests.support.docstring_coverage import coverage

#: the share the library and the node packages keep
FLOOR = 0.90


def test_public_callables_are_documented() -> None:
    documented, total, missing = coverage()
    assert total > 1000      # the walk found the library, not an empty tree
    assert documented / total >= FLOOR, (
        f"{documented} of {total} documented ({documented / total:.1%}); undocumented:\n"
        + "\n".join(missing[:40]))


def test_the_count_follows_the_rules(tmp_path: Path) -> None:
    """Public: module-level functions and classes, and the methods and properties of public
    classes, whose names do not start with ``_``; nested functions and private members do not
    count."""
    package = tmp_path / "stillframe"
    package.mkdir()
    (package / "module.py").write_text(
        'def shown():\n    """Documented."""\n\n'
        "def bare():\n    def nested():\n        pass\n\n"
        "def _private():\n    pass\n\n"
        'class Public:\n    """Documented."""\n\n'
        "    def __init__(self):\n        pass\n\n"
        "    @property\n    def value(self):\n        return 1\n\n"
        '    def method(self):\n        """Documented."""\n\n'
        "class _Hidden:\n    def method(self):\n        pass\n")
    documented, total, missing = coverage(tmp_path)
    assert (documented, total) == (3, 5)
    assert missing == ["stillframe/module.py:4 bare", "stillframe/module.py:18 Public.value"]
