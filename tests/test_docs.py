"""docs/ agrees with the code: the path-file schema, the README's command table, no docstring
pointing at a file the repository lacks, and `import open3d` for Python users (issue 18)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import click
import pytest

from scrapcut_cli.cli import cli

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def path_schema() -> dict[str, object]:
    return dict(json.loads((DOCS / "path.schema.json").read_text(encoding="utf-8")))


def check_schema(data: object, name: str) -> None:
    """Validate ``data`` against the JSON Schema docs/``name`` (raises on a mismatch)."""
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads((DOCS / name).read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    jsonschema.Draft202012Validator(schema).validate(data)


def check_path_file(data: object) -> None:
    """Validate a path file against docs/path.schema.json (raises on a mismatch)."""
    check_schema(data, "path.schema.json")


def test_the_path_schema_is_a_schema_and_rejects_what_the_reader_rejects() -> None:
    jsonschema = pytest.importorskip("jsonschema")
    from test_toolpath_pathfile import _example  # a curve and a path with a flagged set-point

    from scrapcut_cli.toolpath.pathfile import path_from_dict, path_to_dict

    jsonschema.Draft202012Validator.check_schema(path_schema())
    curve, path = _example()
    data = path_to_dict(
        curve,
        path,
        source={
            "path": "x.mcap",
            "sha256_first_mib": "0" * 64,
            "frames_used": 3,
            "frames_skipped": 0,
            "start_ns": 5,
        },
        method_params={},
        config={},
        frame_id="panda_link0",
    )
    data = json.loads(json.dumps(data))
    check_path_file(data)
    path_from_dict(data)  # and the reader takes it
    for broken in (
        {**data, "units": "mm"},
        {**data, "schema": "scrapcut.path/v2"},
        {**data, "path": {**data["path"], "setpoints": [{"s": 0.0}]}},
    ):
        with pytest.raises(jsonschema.ValidationError):
            check_path_file(broken)


def _table_rows() -> dict[str, str]:
    """README's command table: command name → its synopsis cell."""
    rows = {}
    for line in (ROOT / "README.md").read_text(encoding="utf-8").splitlines():
        match = re.match(r"^\| `scrapcut (\S+)(.*?)` \|", line)
        if match:
            rows[match.group(1)] = match.group(2)
    return rows


def test_the_readme_command_table_matches_help() -> None:
    rows = _table_rows()
    ctx = click.Context(cli)
    commands = {name: cli.get_command(ctx, name) for name in cli.list_commands(ctx)}
    assert set(rows) == set(commands), "README's command table and `scrapcut --help` differ"
    for name, synopsis in rows.items():
        command = commands[name]
        assert command is not None
        known = {opt for p in command.params for opt in (*p.opts, *p.secondary_opts)}
        named = set(re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", synopsis))
        assert named <= known, f"scrapcut {name}: README names {sorted(named - known)}"


def test_no_docstring_points_at_a_missing_file() -> None:
    sources = sorted((ROOT / "scrapcut_cli").rglob("*.py"))
    text = {p: p.read_text(encoding="utf-8") for p in sources}
    assert not [p.name for p, t in text.items() if "DESIGN.md" in t]
    for p, t in text.items():
        for doc in set(re.findall(r"(?<![\w/.])docs/[\w.-]+\.\w+", t)):
            assert (ROOT / doc).is_file(), f"{p.relative_to(ROOT)} points at {doc}"
    assert (DOCS / "torch_frame.png").stat().st_size > 10_000


def test_import_open3d_finds_libusb_for_a_python_user() -> None:
    """After ``import scrapcut_cli``, looking up ``open3d`` loads the wheel's libusb first (what
    open3d's extension needs); before it, nothing is loaded. In a fresh interpreter: the finder
    changes sys.meta_path, which pytest's own process must keep. (The import itself, a few
    seconds, is exercised by every open3d-using test.)"""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    code = (
        "import importlib.util, scrapcut_cli\n"
        "def loaded(): return any('libusb' in l for l in open('/proc/self/maps'))\n"
        "before = loaded(); importlib.util.find_spec('open3d'); print(before, loaded())"
    )
    result = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.split() == ["False", "True"]


def test_one_help_style_and_old_spellings_warn(tmp_path: Path) -> None:
    """Defaults are stated in the help text as "(default X)" (no click show_default); a length
    option carries its unit; the old spellings still work, with one warning line."""
    from click.testing import CliRunner

    ctx = click.Context(cli)
    for name in cli.list_commands(ctx):
        command = cli.get_command(ctx, name)
        assert command is not None
        for p in command.params:
            if not isinstance(p, click.Option) or p.hidden or p.required or p.is_flag:
                continue
            where = f"scrapcut {name} {p.opts[-1]}"
            assert not p.show_default, where
            if p.default not in (None, ()) and p.name != "help":
                assert "default" in (p.help or ""), where
    missing = tmp_path / "missing.mcap"
    runner = CliRunner()
    for args, old, new in (
        (["fit", missing, "-o", tmp_path / "p.json", "--leaf-size", "20"], "--leaf-size", "-mm"),
        (["filter", missing, "--surface"], "--surface", "--with-surface"),
    ):
        result = runner.invoke(cli, [str(a) for a in args])
        assert result.exit_code == 1  # the recording is missing: the warning came first
        warning, error = result.stderr.strip().splitlines()
        assert warning.startswith(f"warning: {old} is deprecated; use ") and new in warning
        assert error.startswith("scrapcut: error: ")
    both = runner.invoke(cli, ["fit", str(missing), "-o", "p.json", "--leaf-size", "5",
                               "--leaf-size-mm", "5"])  # fmt: skip
    assert both.exit_code == 2 and "give one" in both.output
