"""Every input fuzzed (issue 31, item 4): malformed scenes, ``--set`` values, command-line
arguments, bag directories and metadata, and CDR payloads, run against every command.

Each case asserts: no traceback (in process, no exception but ``SystemExit`` leaves
:func:`stillframe.app.cli.main`; in a subprocess, no ``Traceback`` on stderr), the exit code of
the error's kind (``errors.py``: 2 input, 3 bag), a last stderr line ``stillframe CMD: error:``
naming what is wrong (the key, the file, the option), and completion within a bound (an interval
timer interrupts a hang). The commands are found by walking the real parser, so a command added
later is fuzzed too. The cases are drawn with a fixed seed and a bounded count; most run in
process (milliseconds each), a few as real subprocesses (stderr, broken pipes, non-UTF-8 argv).
"""

from __future__ import annotations

import copy
import functools
import math
import os
import random
import re
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from mcap.reader import make_reader

from stillframe.bags.storage import BagWriter
from stillframe.config.scene import load_scene, scene_from_dict
from stillframe.config.yamlio import load_yaml
from stillframe.contract.messages import TYPESTORE
from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from tests.support.cli_fuzz import (
    HOSTILE,
    assert_one_line_error,
    bounded,
    leaf_commands,
    positionals,
    run,
)
from tests.support.middleware import child_env

SCENE = REPO_ROOT / "scenes" / "thesis_lqg.yaml"
HAMMER = REPO_ROOT / "bags" / "hammer"
SEED = 31
#: short closed-loop runs: control from 1 s, peaks over 1 s
SHORT = ["--set", "duration=2", "--set", "controller.start=1", "--set", "evaluation.window=1"]
IDENTIFY = ["--input", "/frame/excitation/wrench:wrench.force.x",
            "--output", "/frame/floor1/imu:linear_acceleration.x"]


def scene_commands() -> list[list[str]]:
    """Commands whose first positional is a scene file."""
    return [path for path, parser in leaf_commands()
            if positionals(parser)[:1] in (["scene"], ["scenes"])]


# -- scenes ----------------------------------------------------------------------------------

def malformed_scenes(root: Path) -> dict[str, Path]:
    """Scene files no command may take: each one a kind the issue lists, and more."""
    rng = random.Random(SEED)
    text = SCENE.read_text()
    files = {
        "random bytes": rng.randbytes(4000),
        "UTF-16 without a byte-order mark": text.encode("utf-16-le"),
        "latin-1 text": "name: caf\xe9\nduration: 3\n".encode("latin-1"),
        "a NUL byte": b"name: a\x00b\n",
        "nested 3000 deep (flow)": ("a: " + "[" * 3000 + "]" * 3000 + "\n").encode(),
        "nested 3000 deep (mappings)": ("a: " + "{a: " * 3000 + "1" + "}" * 3000).encode(),
        "a duplicate key": (text + "\nduration: 3\n").encode(),
        "a list": b"- name\n- x\n",
        "a scalar": b"3\n",
        "empty": b"",
        "more than 1 MiB": b"name: x\n" + b" " * (2 << 20),
        "an integer of 5000 digits": ("name: x\nduration: 1" + "0" * 5000 + "\n").encode(),
        "duration nan": re.sub(r"(?m)^duration:.*$", "duration: .nan", text).encode(),
        "a tab": b"name: x\n\tduration: 3\n",
        "an unknown key": (text + "\ncolour: red\n").encode(),
    }
    paths = {}
    for i, (kind, data) in enumerate(files.items()):
        paths[kind] = root / f"scene{i}.yaml"
        paths[kind].write_bytes(data)
    paths["a directory"] = root
    paths["a missing file"] = root / "missing.yaml"
    paths["/dev/zero (endless)"] = Path("/dev/zero")
    return paths


def test_malformed_scenes_through_every_scene_command(tmp_path: Path) -> None:
    commands = scene_commands()
    assert {"modes", "simulate", "closed-loop", "launch", "montecarlo"} <= {
        " ".join(c) for c in commands}
    named = {"duration nan": "duration: must be finite", "an unknown key": "colour: unknown key"}
    for kind, path in malformed_scenes(tmp_path).items():
        for command in commands:
            argv = [*command, str(path)]
            code, _out, err = run(*argv)
            assert_one_line_error(argv, code, err, {2}, named.get(kind, str(path)))
            if kind == "a duplicate key":
                assert "found duplicate key 'duration' at line" in err
            if kind.startswith("nested"):
                assert "nested more than 200 levels deep" in err


def test_utf16_with_a_byte_order_mark_is_a_scene(tmp_path: Path) -> None:
    """YAML allows UTF-16 with its byte-order mark: read, not refused."""
    path = tmp_path / "utf16.yaml"
    path.write_bytes(SCENE.read_text().encode("utf-16"))
    assert load_scene(path) == load_scene(SCENE)


def _numeric_keys() -> list[str]:
    """Every numeric scene key (scalars, lists of numbers, and the nullable ones, whose default
    is null: the limits), found from the scene's own values."""
    keys = []

    def walk(node: object, prefix: str) -> None:
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, f"{prefix}{k}.")
        elif node is None or (isinstance(node, int | float | list | tuple)
                              and not isinstance(node, bool)):
            keys.append(prefix.rstrip("."))

    walk(load_scene(SCENE).to_dict(), "")
    return keys


def test_every_numeric_key_takes_only_finite_bounded_values() -> None:
    """Every numeric key with every hostile value, at load time: refused in one line naming
    the key (or the --set), or a scene whose every number is finite."""
    keys = _numeric_keys()
    assert len(keys) > 60
    base = load_yaml(SCENE.read_bytes())      # parsed once; each case on a copy
    accepted = 0
    for key in keys:
        for value in HOSTILE:
            try:
                with bounded(5.0):
                    scene = scene_from_dict(copy.deepcopy(base), [f"{key}={value}"])
            except InputError as exc:
                message = str(exc)
                assert "\n" not in message and len(message) < 400, (key, value, message)
                assert message.startswith(key) or message.startswith("--set ") or \
                    key.rsplit(".", 1)[0] in message, (key, value, message)
                continue
            accepted += 1
            numbers = [v for k in keys for v in _values(scene.to_dict(), k)]
            assert all(math.isfinite(v) and abs(v) < 1e15 for v in numbers), (key, value)
    assert accepted > 0     # 0, -1 and 1e-308 are fine for some keys


def _values(data: dict, key: str) -> list[float]:
    node: object = data
    for part in key.split("."):
        node = node[part]  # type: ignore[index]
    return [float(v) for v in (node if isinstance(node, list) else [node]) if v is not None]


def test_set_values_through_the_commands() -> None:
    """A fixed-seed sample of (key, value) through ``modes`` and a short ``closed-loop``."""
    rng = random.Random(SEED)
    keys = [*_numeric_keys(), "name", "model.type", "controller.type", "no.such.key",
            "duration.x"]
    for command, count in (("modes", 40), ("closed-loop", 8)):
        for _ in range(count):
            key, value = rng.choice(keys), rng.choice(HOSTILE)
            argv = [command, str(SCENE), *(SHORT if command == "closed-loop" else []),
                    "--set", f"{key}={value}"]
            code, _out, err = run(*argv)
            if code != 0:
                assert_one_line_error(argv, code, err, {2, 4})


def _mutations(text: str, rng: random.Random) -> Iterator[str]:
    lines = text.splitlines()
    for _ in range(30):
        kind = rng.randrange(5)
        copy = list(lines)
        i = rng.randrange(len(copy))
        if kind == 0:           # a number replaced by a hostile value
            head, _, _rest = copy[i].partition(":")
            copy[i] = f"{head}: {rng.choice(HOSTILE)}"
        elif kind == 1:         # a line lost
            del copy[i]
        elif kind == 2:         # a line twice
            copy.insert(i, copy[i])
        elif kind == 3:         # random bytes in a line
            copy[i] = copy[i][:5] + "".join(chr(rng.randrange(1, 0x2FF)) for _ in range(8))
        else:                   # the file cut short
            copy = copy[:i]
        yield "\n".join(copy) + "\n"


def test_randomly_mutated_scenes(tmp_path: Path) -> None:
    rng = random.Random(SEED)
    for n, text in enumerate(_mutations(SCENE.read_text(), rng)):
        path = tmp_path / f"m{n}.yaml"
        path.write_text(text, errors="surrogatepass")
        argv = ["modes", str(path)]
        code, _out, err = run(*argv)
        if code != 0:
            assert_one_line_error(argv, code, err, {2})


# -- command-line arguments ------------------------------------------------------------------

def test_every_command_refuses_malformed_arguments(tmp_path: Path) -> None:
    """Every command: an unknown option; every float option given nan, inf and 1e999; every
    whole-number option given 1e9x; every file positional given a non-UTF-8, an overlong and a
    missing path. Exit 2 (or 3 for a bag) in one line, no traceback, no hang."""
    commands = leaf_commands()
    assert len(commands) >= 30
    for path, parser in commands:
        code, _out, err = run(*path, "--no-such-option")
        # argparse names a missing positional first, else the unknown option
        assert_one_line_error([*path, "--no-such-option"], code, err, {2},
                              "required" if "required" in err else "--no-such-option")
        for action in parser._actions:
            if not action.option_strings or action.type not in (float, int) or action.nargs:
                continue
            option = action.option_strings[-1]
            for value in (["nan", "inf", "-inf", "1e999"] if action.type is float
                          else ["1e9x", "nan"]):
                argv = [*path, f"{option}={value}"]
                code, _out, err = run(*argv)
                assert_one_line_error(argv, code, err, {2}, option)
        files = [d for d in positionals(parser) if d in ("scene", "scenes", "bag")]
        if files:
            for name in ("\udcff\udcfe.yaml", "x" * 5000, str(tmp_path / "missing")):
                argv = [*path, name, *(IDENTIFY if path == ["identify"] else [])]
                code, _out, err = run(*argv)
                assert_one_line_error(argv, code, err, {2, 3})


# -- bags ------------------------------------------------------------------------------------

def malformed_bags(root: Path) -> dict[str, Path]:
    """Bag directories that cannot be read: each file kind broken in its own way."""
    rng = random.Random(SEED)
    meta = (HAMMER / "metadata.yaml").read_text()
    mcap = (HAMMER / "hammer.mcap").read_bytes()
    cases: dict[str, dict[str, bytes] | None] = {
        "no metadata.yaml": {"hammer.mcap": mcap},
        "binary metadata.yaml": {"metadata.yaml": rng.randbytes(2000), "hammer.mcap": mcap},
        "metadata.yaml a list": {"metadata.yaml": b"- 1\n- 2\n", "hammer.mcap": mcap},
        "metadata.yaml without its keys": {"metadata.yaml": b"rosbag2_bagfile_information: {}\n",
                                           "hammer.mcap": mcap},
        "metadata.yaml version 999": {"metadata.yaml": meta.replace("version: 9",
                                                                    "version: 999").encode(),
                                      "hammer.mcap": mcap},
        "metadata.yaml nested 3000 deep": {"metadata.yaml": b"a: " + b"[" * 3000 + b"]" * 3000,
                                           "hammer.mcap": mcap},
        "storage file missing": {"metadata.yaml": meta.encode()},
        "storage file outside the bag": {"metadata.yaml": meta.replace(
            "hammer.mcap", "../../../../etc/passwd").encode(), "hammer.mcap": mcap},
        "storage file random bytes": {"metadata.yaml": meta.encode(),
                                      "hammer.mcap": rng.randbytes(5000)},
        "storage file empty": {"metadata.yaml": meta.encode(), "hammer.mcap": b""},
        "storage file cut": {"metadata.yaml": meta.encode(), "hammer.mcap": mcap[:100]},
        "not a directory": None,
    }
    paths = {}
    for i, (kind, files) in enumerate(cases.items()):
        bag = root / f"bag{i}"
        if files is None:
            bag.write_bytes(b"a file")
        else:
            bag.mkdir()
            for name, data in files.items():
                (bag / name).write_bytes(data)
        paths[kind] = bag
    return paths


@pytest.mark.parametrize("command", [["bag", "info"], ["identify", *IDENTIFY]])
def test_malformed_bags(tmp_path: Path, command: list[str]) -> None:
    for _kind, bag in malformed_bags(tmp_path).items():
        argv = [*command, str(bag)]
        code, _out, err = run(*argv)
        assert_one_line_error(argv, code, err, {3}, str(bag))


def test_reindex_of_malformed_bags_recovers_or_refuses(tmp_path: Path) -> None:
    """``bag reindex`` needs only the storage file: it recovers from a bad metadata.yaml, and
    refuses a storage file that is not MCAP (exit 3)."""
    for kind, bag in malformed_bags(tmp_path).items():
        argv = ["bag", "reindex", str(bag), "--json"]
        code, _out, err = run(*argv)
        if kind.startswith(("no metadata", "binary", "metadata.yaml", "storage file outside",
                            "storage file cut")):     # a cut file: 0 whole messages, kept
            assert code == 0, (kind, err)
        else:
            assert_one_line_error(argv, code, err, {3}, str(bag))


#: a value of each wrong type for a metadata field
WRONG_VALUES = {"a string": "text", "a list": [1], "a map": {"a": 1}, "null": None,
                "negative": -5, "huge": 2**70, "NaN": math.nan}


def metadata_fields(node: object, path: tuple = ()) -> Iterator[tuple]:
    """The path of every field of a metadata document (mappings and lists too), the first
    topic's in full and the other topics' entries whole."""
    if path:
        yield path
    if isinstance(node, dict):
        for key, value in node.items():
            yield from metadata_fields(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            if path[-1] == "topics_with_message_count" and i > 0:
                yield (*path, i)
            else:
                yield from metadata_fields(value, (*path, i))


def _replaced(document: object, path: tuple, value: object) -> object:
    changed = copy.deepcopy(document)
    node = changed
    for key in path[:-1]:
        node = node[key]
    node[path[-1]] = value
    return changed


def test_metadata_fields_of_every_wrong_type_are_one_line(tmp_path: Path) -> None:
    """Each field of the sample bag's metadata.yaml (every level) set to a value of each wrong
    type, one at a time: ``bag info`` says which field in one line, exit 3. A string where a
    string belongs and ``custom_data: null`` (what rosbag2 writes for none) are right, not
    wrong, and left out."""
    document = yaml.safe_load((HAMMER / "metadata.yaml").read_text())
    bag = shutil.copytree(HAMMER, tmp_path / "bag")
    cases = 0
    for path in metadata_fields(document):
        current = functools.reduce(lambda node, key: node[key], path, document)
        for kind, value in WRONG_VALUES.items():
            if (isinstance(current, str) and isinstance(value, str)) or (
                    path[-1] == "custom_data" and value is None):
                continue
            (bag / "metadata.yaml").write_text(yaml.safe_dump(_replaced(document, path, value)))
            argv = ["bag", "info", str(bag)]
            code, _out, err = run(*argv)
            where = ".".join(map(str, path))
            assert_one_line_error([where[-60:] + f"={kind}", *argv], code, err, {3},
                                  "metadata.yaml")
            assert str(path[-1]) in err.strip().splitlines()[-1], (where, kind, err)
            cases += 1
    assert cases > 300


def _garbage_bag(path: Path, rng: random.Random) -> int:
    """The hammer bag with a fixed-seed share of floor 1's IMU payloads replaced by CDR that
    cannot decode (empty, cut to 10 bytes, random bytes); how many were replaced."""
    broken = 0
    with (HAMMER / "hammer.mcap").open("rb") as f, BagWriter(path, TYPESTORE) as writer:
        seen: set[str] = set()
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.topic not in seen:
                writer.add_topic(channel.topic, schema.name)
                seen.add(channel.topic)
            data = message.data
            if channel.topic == "/frame/floor1/imu" and rng.random() < 0.2:
                data = rng.choice([b"", data[:10], data[:3] + rng.randbytes(7)])
                broken += 1
            writer.write(channel.topic, message.log_time, data)
    return broken


def test_garbage_cdr_inside_a_valid_bag_is_counted_and_refused(tmp_path: Path) -> None:
    broken = _garbage_bag(tmp_path / "garbage", random.Random(SEED))
    argv = ["identify", str(tmp_path / "garbage"), *IDENTIFY]
    code, _out, err = run(*argv)
    assert_one_line_error(argv, code, err, {3}, "corrupt CDR")
    assert f"/frame/floor1/imu: {broken} of 256" in err


# -- real subprocesses -----------------------------------------------------------------------

def _stillframe(*argv: str | bytes,
                stdout: object = subprocess.PIPE) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stillframe", *argv], env=child_env(),
                          cwd=REPO_ROOT, stdout=stdout, stderr=subprocess.PIPE, timeout=120)


def test_broken_pipe_exits_quietly() -> None:
    """``closed-loop --json | head -1``, the reader gone before the first write (forced: the
    pipe's read end is closed at once): no BrokenPipeError, exit 141 as a shell's SIGPIPE."""
    proc = subprocess.Popen([sys.executable, "-m", "stillframe", "closed-loop", str(SCENE),
                             *SHORT, "--json"], env=child_env(), cwd=REPO_ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()
    _out, err = proc.communicate(timeout=120)
    assert err.decode() == "" and proc.returncode == 141


def test_real_stderr_of_a_binary_scene_and_non_utf8_arguments(tmp_path: Path) -> None:
    path = tmp_path / "binary.yaml"
    path.write_bytes(random.Random(SEED).randbytes(3000))
    done = _stillframe("closed-loop", str(path))
    assert done.returncode == 2 and done.stderr.decode().count("\n") == 1
    assert b"not valid YAML: not UTF-8 or UTF-16 text" in done.stderr
    done = _stillframe("modes", os.fsencode(tmp_path) + b"/\xff\xfe.yaml")
    assert done.returncode == 2 and b"Traceback" not in done.stderr
    assert b"cannot read the scene file" in done.stderr


def test_unwritable_outputs_are_one_line(tmp_path: Path) -> None:
    """--out under a file, in a directory that cannot be written, on a full disk
    (/dev/full)."""
    blocker = tmp_path / "file"
    blocker.write_text("")
    readonly = tmp_path / "ro"
    readonly.mkdir()
    readonly.chmod(0o555)
    cases = [(["simulate", str(SCENE), "--duration", "0.1", "--out", str(blocker / "h.npz")],
              f"{blocker} is a file"),
             (["montecarlo", str(SCENE), *SHORT, "--runs", "1", "--out", str(blocker / "mc")],
              f"{blocker} is a file"),
             (["identify", str(HAMMER), *IDENTIFY, "--save-model", str(blocker / "m.json")],
              f"{blocker} is a file"),
             (["identify", str(HAMMER), *IDENTIFY, "--plots", str(blocker / "plots")],
              f"{blocker} is a file")]
    lumped = str(REPO_ROOT / "scenes" / "thesis_lumped.yaml")
    # where even root cannot write: a process's /proc directory (refused before the work),
    # sysfs (the write itself fails)
    cases += [(["simulate", lumped, "--duration", "0.1", "--out", "/proc/1/h.npz"],
               "/proc/1 is not writable"),
              (["simulate", lumped, "--duration", "0.1", "--out", "/sys/stillframe/h.npz"],
               "/sys/stillframe: ")]
    if os.geteuid() != 0:     # root writes into read-only directories
        cases.append((["simulate", str(SCENE), "--duration", "0.1", "--out",
                       str(readonly / "h.npz")], f"{readonly} is not writable"))
    for argv, named in cases:
        code, _out, err = run(*argv)
        assert_one_line_error(argv, code, err, {2}, named)
    # a full disk: the write itself fails
    with open("/dev/full", "wb") as full:
        done = _stillframe("bag", "info", str(HAMMER), "--json", stdout=full)
    assert done.returncode == 2 and b"No space left on device" in done.stderr
    assert b"Traceback" not in done.stderr


def test_play_counts_what_it_cannot_publish(tmp_path: Path, ros_domain: int) -> None:
    """metadata.yaml says the IMU topics are WrenchStamped; the storage file holds Imu: play
    published the 256 wrenches, and says it could not play the 768 others (exit 3)."""
    bag = shutil.copytree(HAMMER, tmp_path / "mismatch")
    meta = bag / "metadata.yaml"
    meta.write_text(meta.read_text().replace("sensor_msgs/msg/Imu",
                                             "geometry_msgs/msg/WrenchStamped"))
    done = _stillframe("play", str(bag), "--rate", "1000", "--delay", "0")
    err = done.stderr.decode()
    assert done.returncode == 3, err
    assert "Published 256 messages" in err
    assert "could not play 768 messages" in err and "/frame/floor1/imu: 256 of 256" in err
