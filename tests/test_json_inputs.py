"""Every JSON file lobeview takes goes through one reader with limits (core/jsonio.py, issue 43
item 1): material files and inline material JSON, material edits (--materials), camera paths
(--path) and viewer scripts (--script). Hostile files from the issue's attack: 100 000-deep
nesting (was a RecursionError traceback), a 400-digit integer (an OverflowError in
``material show``), 1e999 and NaN, a FIFO (hung forever), a device, a folder, a file over the size
limit: each is a one-line error naming the file and the limit, at once."""

from __future__ import annotations

import os
import subprocess
import sys
import threading

import pytest

from lobeview.app.options import read_material_edits
from lobeview.app.script import ScriptError, load_script
from lobeview.core.errors import OptionError
from lobeview.core.jsonio import MAX_JSON_DEPTH, JSONInputError, parse_json_text, quoted, read_json_file
from lobeview.materials.spec import MaterialError, load_material
from lobeview.scenes.camera_path import CameraPath, CameraPathError

HOSTILE = {
    "deep": ("[" * 100_000 + "]" * 100_000, "nested deeper than the 64 levels"),
    "just too deep": ("[" * (MAX_JSON_DEPTH + 1) + "]" * (MAX_JSON_DEPTH + 1), "nested deeper"),
    "long integer": ('{"ks": ' + "9" * 400 + "}", "a number of 400 characters"),
    "overflowing float": ('{"ks": 1e999}', "'1e999' is not finite"),
    "NaN": ('{"ks": NaN}', "NaN is not a JSON number"),
    "Infinity": ('{"ks": -Infinity}', "-Infinity is not a JSON number"),
    "truncated": ('{"ks": ', "not valid JSON at line 1, column 8"),
    "not UTF-8": (b'{"name": "\xff"}', "not UTF-8 text"),
}
READERS = {
    "material file": (load_material, MaterialError),
    "--materials": (read_material_edits, OptionError),
    "camera path": (CameraPath.load, CameraPathError),
    "--script": (load_script, ScriptError),
}


def _finishes(call, seconds: float = 20.0):
    """Run ``call`` in a thread: (finished, the exception it raised)."""
    outcome = {}

    def target():
        try:
            call()
        except Exception as exc:  # what the caller checks
            outcome["error"] = exc

    thread = threading.Thread(target=target, daemon=True)
    thread.start()
    thread.join(seconds)
    return not thread.is_alive(), outcome.get("error")


@pytest.mark.parametrize("surface", READERS)
@pytest.mark.parametrize("case", HOSTILE)
def test_every_json_surface_refuses_hostile_files_with_a_one_line_error(tmp_path, surface, case):
    content, expected = HOSTILE[case]
    path = tmp_path / "input.json"
    path.write_bytes(content if isinstance(content, bytes) else content.encode())
    reader, error_type = READERS[surface]
    with pytest.raises(error_type) as info:
        reader(str(path))
    message = str(info.value)
    assert expected in message and str(path) in message and "\n" not in message and len(message) < 400, message


@pytest.mark.parametrize("surface", READERS)
def test_fifos_devices_and_folders_are_refused_before_any_open(tmp_path, surface):
    reader, error_type = READERS[surface]
    fifo = tmp_path / "fifo.json"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero", tmp_path):
        finished, error = _finishes(lambda p=path: reader(str(p)))
        assert finished, f"{surface} {path}: still reading"
        assert isinstance(error, error_type) and "not a regular file" in str(error), (path, error)


def test_size_limit_is_checked_before_reading_and_inline_json_has_the_same_limits(tmp_path):
    big = tmp_path / "big.json"
    big.write_text("[" + "0," * 600 + "0]")
    with pytest.raises(JSONInputError, match=r"1203 bytes exceeds the 1024 bytes limit"):
        read_json_file(big, "--script", max_bytes=1024)
    with pytest.raises(MaterialError, match="inline material JSON: a number of 400 characters"):
        load_material('{"model": "thesis", "ks": ' + "1" * 400 + "}")
    assert parse_json_text('{"a": [1, 2.5, {"b": "c"}]}', "x") == {"a": [1, 2.5, {"b": "c"}]}
    assert quoted("a" * 1000).endswith("...' (1000 characters)") and len(quoted("a" * 1000)) < 120
    assert quoted("\x1b[31mred") == repr("\x1b[31mred")  # control characters escaped


def test_material_show_prints_one_line_for_a_deep_file_instead_of_a_traceback(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    result = subprocess.run([sys.executable, "-m", "lobeview", "material", "show", str(path)],
                            capture_output=True, text=True, timeout=120)  # fmt: skip
    assert result.returncode == 2 and "Traceback" not in result.stderr, result.stderr[-2000:]
    assert "nested deeper than the 64 levels allowed" in result.stderr
