"""Cell files: JSON or YAML text of a robot cell (:mod:`rbe_ros.cell`), from a file
(``--cell``, the node's ``cell_file``) or a goal's text. A URDF path is relative to the
cell file's folder; ``example-robot-data:PATH`` names a model of the installed
example-robot-data (``example-robot-data:ur_description/urdf/ur10_robot.urdf``)."""
from __future__ import annotations

import json
import sysconfig
from dataclasses import replace
from pathlib import Path

import yaml

from ..cell import Cell, CellError, cell_from_dict

#: The prefix of a URDF shipped with example-robot-data (installed with pin, cmeel).
EXAMPLE_ROBOT_DATA = "example-robot-data:"


def example_robot_data() -> Path:
    """The folder of example-robot-data's robots in this environment."""
    return (Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share"
            / "example-robot-data" / "robots")


def _urdf_path(urdf: str, base_dir: Path | None) -> str:
    if not urdf:
        return ""
    if urdf.startswith(EXAMPLE_ROBOT_DATA):
        return str(example_robot_data() / urdf[len(EXAMPLE_ROBOT_DATA):])
    path = Path(urdf)
    if not path.is_absolute() and base_dir is not None:
        path = base_dir / path
    return str(path)


def parse_cell(text: str, base_dir: Path | None = None) -> Cell:
    """The cell of JSON or YAML ``text`` (YAML is a superset of JSON: JSON is tried first so
    that its error names the line); raises :class:`CellError` naming the field."""
    try:
        data = json.loads(text)
    except ValueError:
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
            problem = getattr(exc, "problem", None) or type(exc).__name__
            raise CellError(f"cell: YAML does not parse{where}: {problem}") from None
    cell = cell_from_dict(data)
    robots = tuple(replace(r, urdf=_urdf_path(r.urdf, base_dir)) for r in cell.robots)
    return Cell(robots)


def read_cell(path) -> Cell:
    """The cell of the file ``path`` (CellError when it cannot be read or is not a cell)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise CellError(f"cell: cannot read {path}: {exc.strerror or exc}") from None
    return parse_cell(text, path.resolve().parent)


__all__ = ["EXAMPLE_ROBOT_DATA", "example_robot_data", "parse_cell", "read_cell"]
