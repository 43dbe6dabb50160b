"""Batch manifests: one row per sequence, from YAML or CSV.

Columns (YAML keys):

* ``input`` (required): a video, an image folder, a TUM/Bonn or EuRoC folder;
* ``name``: the sequence's output folder (default: the input's name);
* ``calib``: a calibration file or ``auto`` (default: what came with the input);
* ``gt``: a ground-truth trajectory; with it the sequence is evaluated;
* ``align``: ``sim3``, ``se3`` or ``none``, for the evaluation (default: ``se3`` for
  a metric run, i.e. one with sensor depth, else ``sim3``);
* ``config``: a built-in config name or a YAML file (default: ``default``);
* ``depth``: ``true`` for RGB-D mode, as ``droidw track --depth``;
  ``depth_scale``: its depth PNG units per metre (default 5000, TUM and Bonn);
* ``set``: overrides, ``KEY=VALUE`` (YAML: a list of them or a mapping;
  CSV: separated by ``;``);
* any column whose name contains a dot, e.g. ``frontend.window``: one override.

A YAML manifest is a list of rows, or a mapping with ``sequences`` (that
list) and optional ``defaults`` (a row merged under every row).  Relative
paths are relative to the manifest's folder.  Empty CSV cells are unset.
"""

from __future__ import annotations

import csv
import re
from dataclasses import asdict, dataclass
from pathlib import Path

import yaml

from droidw_cli.errors import UserError, yaml_problem
from droidw_cli.io.sources import TUM_DEPTH_SCALE

COLUMNS = ("name", "input", "calib", "gt", "align", "config", "depth", "depth_scale", "set")
ALIGN_CHOICES = ("sim3", "se3", "none")
_SAFE_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*")


class ManifestError(UserError):
    """The manifest cannot be read or has a malformed row."""


@dataclass(frozen=True)
class Row:
    """One sequence of a batch; paths are absolute or as given (``calib: auto``)."""

    name: str
    input: str
    calib: str | None = None
    gt: str | None = None
    align: str | None = None  # None: se3 when the run is metric (sensor depth), else sim3
    config: str | None = None  # None: the batch's --config, else "default"
    overrides: tuple[str, ...] = ()
    depth: bool = False
    depth_scale: float = TUM_DEPTH_SCALE

    def as_dict(self) -> dict:
        d = asdict(self)
        d["overrides"] = list(self.overrides)
        return d

    @staticmethod
    def from_dict(d: dict) -> "Row":
        return Row(**{**d, "overrides": tuple(d.get("overrides", ()))})


def load_manifest(path: str | Path) -> list[Row]:
    """The rows of a YAML (``.yaml``/``.yml``) or CSV manifest, names unique."""
    path = Path(path)
    if not path.is_file():
        raise ManifestError(f"manifest not found: {path}")
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        raw = _yaml_rows(path)
    elif suffix == ".csv":
        raw = _csv_rows(path)
    else:
        raise ManifestError(f"{path}: a manifest is a .yaml, .yml or .csv file")
    if not raw:
        raise ManifestError(f"{path}: the manifest has no rows")
    rows = [_row(path, i + 1, r) for i, r in enumerate(raw)]
    explicit = [r.get("name") not in (None, "") for r in raw]
    given = [row.name for row, e in zip(rows, explicit) if e]
    dup = sorted({n for n in given if given.count(n) > 1})
    if dup:
        raise ManifestError(f"{path}: name(s) {', '.join(dup)} given to more than one row")
    return _unique_names(rows, explicit)


def _yaml_rows(path: Path) -> list[dict]:
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise ManifestError(f"{path}: not valid YAML ({yaml_problem(exc)})") from None
    defaults: dict = {}
    if isinstance(data, dict):
        unknown = set(data) - {"sequences", "defaults"}
        if unknown:
            raise ManifestError(f"{path}: unknown top-level key(s) {', '.join(sorted(map(str, unknown)))}; "
                                "use 'sequences' (a list of rows) and optional 'defaults'")
        defaults = data.get("defaults") or {}
        data = data.get("sequences")
        if not isinstance(defaults, dict):
            raise ManifestError(f"{path}: 'defaults' must be a mapping of columns")
    if not isinstance(data, list):
        raise ManifestError(f"{path}: expected a list of rows (or 'sequences:' with one)")
    rows = []
    for i, r in enumerate(data):
        if not isinstance(r, dict):
            raise ManifestError(f"{path}: row {i + 1}: expected a mapping such as {{input: video.mp4}}")
        merged = {**defaults, **r}
        over = _overrides(path, i + 1, defaults.get("set")) + _overrides(path, i + 1, r.get("set"))
        merged["set"] = over
        rows.append(merged)
    return rows


def _csv_rows(path: Path) -> list[dict]:
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(row for row in fh if row.strip() and not row.lstrip().startswith("#"))
            if reader.fieldnames is None:
                return []
            rows = []
            for i, r in enumerate(reader):
                if None in r:
                    raise ManifestError(f"{path}: row {i + 1}: more cells than columns")
                cleaned = {k.strip(): v.strip() for k, v in r.items() if k is not None and v is not None and v.strip()}
                cleaned["set"] = _overrides(path, i + 1, cleaned.get("set"))
                rows.append(cleaned)
            return rows
    except (csv.Error, UnicodeDecodeError) as exc:
        raise ManifestError(f"{path}: not a valid CSV file ({_first_line(exc)})") from None


def _overrides(path: Path, line: int, value) -> list[str]:
    """``set`` as ``KEY=VALUE`` strings, from a list, a mapping or a ``;``-separated string."""
    if value is None or value == "":
        return []
    if isinstance(value, dict):
        return [f"{k}={_yaml_scalar(v)}" for k, v in value.items()]
    items = value if isinstance(value, list) else str(value).split(";")
    out = []
    for item in items:
        item = str(item).strip()
        if not item:
            continue
        if "=" not in item:
            raise ManifestError(f"{path}: row {line}: override {item!r} is not KEY=VALUE")
        out.append(item)
    return out


def _yaml_scalar(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    return str(v)


def _row(path: Path, line: int, r: dict) -> Row:
    where = f"{path}: row {line}"
    keys = {str(k) for k in r}
    unknown = sorted(k for k in keys if k not in COLUMNS and "." not in k)
    if unknown:
        raise ManifestError(f"{where}: unknown column(s) {', '.join(unknown)}; columns are {', '.join(COLUMNS)} "
                            "and overrides such as frontend.window")
    if not r.get("input"):
        raise ManifestError(f"{where}: 'input' is required")
    base = path.parent
    overrides = list(r.get("set") or []) + [f"{k}={_yaml_scalar(v)}" for k, v in r.items() if "." in str(k)]
    align = str(r["align"]).lower() if r.get("align") not in (None, "") else None
    if align is not None and align not in ALIGN_CHOICES:
        raise ManifestError(f"{where}: align must be one of {', '.join(ALIGN_CHOICES)}, got {align!r}")
    calib = r.get("calib")
    calib = None if calib in (None, "") else (str(calib) if str(calib) == "auto" else _path(base, calib))
    config = str(r["config"]) if r.get("config") not in (None, "") else None
    if config is not None and (config.endswith((".yaml", ".yml")) or "/" in config):
        config = _path(base, config)
    name = str(r["name"]) if r.get("name") not in (None, "") else _derived_name(str(r["input"]))
    if not _SAFE_NAME.fullmatch(name):
        raise ManifestError(f"{where}: name {name!r} must be letters, digits, '.', '_' or '-' "
                            "(not starting with '.' or '-')")
    return Row(name=name, input=_path(base, r["input"]), calib=calib,
               gt=_path(base, r["gt"]) if r.get("gt") else None, align=align, config=config,
               overrides=tuple(overrides), depth=_flag(where, "depth", r.get("depth")),
               depth_scale=_positive(where, "depth_scale", r.get("depth_scale"), TUM_DEPTH_SCALE))


def _flag(where: str, column: str, value) -> bool:
    """A yes/no cell: YAML booleans, or true/false, yes/no, 1/0 (any case); unset is no."""
    if value in (None, ""):
        return False
    if isinstance(value, bool):
        return value
    text = str(value).strip().lower()
    if text in ("true", "yes", "1", "on"):
        return True
    if text in ("false", "no", "0", "off"):
        return False
    raise ManifestError(f"{where}: {column} must be true or false, got {value!r}")


def _positive(where: str, column: str, value, default: float) -> float:
    if value in (None, ""):
        return default
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if not number > 0:
        raise ManifestError(f"{where}: {column} must be a positive number, got {value!r}")
    return number


def _path(base: Path, value) -> str:
    p = Path(str(value)).expanduser()
    return str(p if p.is_absolute() else base / p)


def _derived_name(inp: str) -> str:
    p = Path(inp.rstrip("/\\"))
    stem = p.stem if p.suffix else p.name
    name = re.sub(r"[^A-Za-z0-9._-]", "_", stem).lstrip("._-")
    return name or "sequence"


def _unique_names(rows: list[Row], explicit: list[bool]) -> list[Row]:
    """A derived name already taken (by a given or an earlier derived one) gets -2, -3, ..."""
    seen = {r.name for r, given in zip(rows, explicit) if given}
    out = []
    for r, given in zip(rows, explicit):
        if given:
            out.append(r)
            continue
        name, k = r.name, 1
        while name in seen:
            k += 1
            name = f"{r.name}-{k}"
        seen.add(name)
        out.append(r if name == r.name else Row.from_dict({**r.as_dict(), "name": name}))
    return out


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
