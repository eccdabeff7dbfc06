"""The inputs of ``scrapcut batch``: recordings (files, folders, globs, manifests) and the grid.

A manifest is a CSV with the header ``recording[,paint][,hsv][,reference][,name]`` or a TOML file
of ``[[recording]]`` tables with ``path`` and the same keys; its relative paths are relative to
the manifest. A grid is a TOML file of value lists: ``method = [...]`` and, per configuration
section, ``key = [...]`` (a scalar is a one-value list). Nothing here runs anything.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import io
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from scrapcut_cli.config import FitMethod, ScrapcutConfig, choice_names
from scrapcut_cli.errors import ConfigError, PipelineError

#: File name suffixes of recordings found in a folder (ROS 2 bag folders are found too).
RECORDING_SUFFIXES = (".mcap", ".bag")
#: Read in chunks of this many bytes while hashing.
_HASH_CHUNK = 1 << 20


# --------------------------------------------------------------------------- inputs


@dataclass(frozen=True)
class BatchInput:
    """One recording of the batch, with its own paint (preset or H1,H2,S,V) and reference."""

    recording: Path
    name: str
    paint: str | None = None
    hsv: str | None = None
    reference: Path | None = None


def collect_inputs(
    sources: Sequence[str | Path], *, reference: Path | None = None
) -> list[BatchInput]:
    """Recordings from files, bag folders, folders of recordings, globs and manifests.

    ``reference`` is the default for inputs without their own. Raises PipelineError naming the
    first source that is missing, empty or malformed.
    """
    if not sources:
        raise PipelineError("no recordings given")
    inputs: list[BatchInput] = []
    for source in sources:
        text = str(source)
        path = Path(text)
        if any(c in text for c in "*?[") and not path.exists():
            matches = sorted(glob.glob(text, recursive=True))
            if not matches:
                raise PipelineError(f"no recording matches {text!r}")
            inputs += [_input(Path(m), reference=reference) for m in matches]
        elif path.suffix.lower() in (".csv", ".toml") and path.is_file():
            inputs += read_manifest(path, reference=reference)
        elif not path.exists():
            raise PipelineError(f"recording not found: {path}")
        elif path.is_dir() and not (path / "metadata.yaml").is_file():
            found = _recordings_in(path)
            if not found:
                raise PipelineError(f"{path} holds no recordings (.mcap, .bag, ROS 2 bag folders)")
            inputs += [_input(p, reference=reference) for p in found]
        else:
            inputs.append(_input(path, reference=reference))
    unique: dict[tuple[Any, ...], BatchInput] = {}
    for item in inputs:
        key = (item.recording.resolve(), item.paint, item.hsv, item.reference)
        unique.setdefault(key, item)
    return list(unique.values())


def _input(path: Path, *, reference: Path | None, **options: Any) -> BatchInput:
    name = path.parent.name if path.name == "metadata.yaml" else path.stem
    return BatchInput(
        recording=path, name=options.pop("name", None) or name, reference=reference, **options
    )


def _recordings_in(folder: Path) -> list[Path]:
    found = []
    for path in sorted(folder.iterdir()):
        recording = path.is_file() and path.suffix.lower() in RECORDING_SUFFIXES
        if recording or (path.is_dir() and (path / "metadata.yaml").is_file()):
            found.append(path)
    return found


MANIFEST_KEYS = ("recording", "paint", "hsv", "reference", "name")


def read_manifest(path: Path, *, reference: Path | None = None) -> list[BatchInput]:
    """A manifest's recordings: CSV (header ``recording,paint,hsv,reference,name``; only
    ``recording`` required) or TOML (``[[recording]]`` tables with ``path`` and those keys)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise PipelineError(f"cannot read manifest {path}: {exc}") from None
    entries: list[dict[str, Any]]
    if path.suffix.lower() == ".toml":
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise PipelineError(f"manifest {path}: {exc}") from None
        tables = data.get("recording")
        if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
            raise PipelineError(f"manifest {path}: expected [[recording]] tables with a path")
        entries = [{("recording" if k == "path" else k): v for k, v in t.items()} for t in tables]
    else:
        reader = csv.DictReader(io.StringIO(text))
        header = [h.strip() for h in reader.fieldnames or []]
        if "recording" not in header:
            raise PipelineError(f"manifest {path}: the header must name a 'recording' column")
        entries = [{(k or "").strip(): (v or "").strip() for k, v in row.items()} for row in reader]
    if not entries:
        raise PipelineError(f"manifest {path} lists no recordings")
    out = []
    for i, entry in enumerate(entries, start=1):
        unknown = sorted(set(entry) - set(MANIFEST_KEYS) - {""})
        if unknown:
            raise PipelineError(
                f"manifest {path}: unknown column(s) {', '.join(unknown)}; known: "
                f"{', '.join(MANIFEST_KEYS)}"
            )
        rec = entry.get("recording")
        if not isinstance(rec, str) or not rec:
            raise PipelineError(f"manifest {path}: entry {i} names no recording")
        recording = _relative_to(path, rec)
        if not recording.exists():
            raise PipelineError(f"manifest {path}: entry {i}: recording not found: {recording}")
        own_reference = entry.get("reference") or None
        out.append(
            _input(
                recording,
                reference=_relative_to(path, own_reference) if own_reference else reference,
                paint=_text(entry.get("paint")),
                hsv=_text(entry.get("hsv")),
                name=_text(entry.get("name")),
            )
        )
    return out


def _relative_to(manifest: Path, value: str) -> Path:
    p = Path(value).expanduser()
    return p if p.is_absolute() else manifest.parent / p


def _text(value: Any) -> str | None:
    return None if value in (None, "") else str(value)


# --------------------------------------------------------------------------- grid


#: The grid axis that chooses the fitting method (every other axis is ``section.key``).
METHOD_AXIS = "method"


def load_grid(path: Path | None, *, methods: Sequence[str] = ()) -> dict[str, list[Any]]:
    """Grid axes in file order: ``method`` and ``section.key`` → the values to try.

    ``methods`` (``--methods``) is the method axis when the file has none (default nurbs).
    Every key is checked against the configuration at once (a typo fails before any run).
    """
    data: dict[str, Any] = {}
    if path is not None:
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise PipelineError(f"grid file not found: {path}") from None
        except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
            raise PipelineError(f"cannot read grid {path}: {exc}") from None
    grid: dict[str, list[Any]] = {}
    where = str(path) if path is not None else "grid"
    for key, value in data.items():
        if isinstance(value, dict):
            for name, values in value.items():
                grid[f"{key}.{name}"] = _values(values)
        else:
            grid[key] = _values(value)
    if METHOD_AXIS in grid and methods:
        raise PipelineError(f"{where} sets the method; drop --methods or the grid's 'method'")
    if METHOD_AXIS not in grid:
        grid = {METHOD_AXIS: list(methods or [FitMethod.NURBS.value]), **grid}
    known = choice_names(FitMethod)
    for method in grid[METHOD_AXIS]:
        if method not in known:
            raise PipelineError(f"{where}: unknown method {method!r}; known: {', '.join(known)}")
    for axis, values in grid.items():
        if not values:
            raise PipelineError(f"{where}: {axis} has no values")
        if axis == METHOD_AXIS:
            continue
        section, _, name = axis.partition(".")
        if not name or "." in name:
            raise PipelineError(f"{where}: {axis!r} is not a [section] key or 'method'")
        for value in values:
            try:
                ScrapcutConfig().override(section, **{name: value})
            except AttributeError:
                raise PipelineError(f"{where}: unknown section [{section}]") from None
            except ConfigError as exc:
                raise PipelineError(f"{where}: {exc}") from None
    return grid


def _values(value: Any) -> list[Any]:
    return list(value) if isinstance(value, list) else [value]


def content_hash(path: Path) -> str:
    """sha256 of a file's bytes, or of a folder's files (relative names and bytes, sorted)."""
    digest = hashlib.sha256()
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    if not files:
        raise PipelineError(f"{path} is empty")
    for file in files:
        if file != path:
            digest.update(str(file.relative_to(path)).encode() + b"\0")
        try:
            with file.open("rb") as fh:
                while chunk := fh.read(_HASH_CHUNK):
                    digest.update(chunk)
        except OSError as exc:
            raise PipelineError(f"cannot read {file}: {exc.strerror or exc}") from None
    return digest.hexdigest()


def slug(name: str) -> str:
    """A file-name-safe version of ``name``."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "recording"
