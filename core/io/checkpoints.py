"""Surveyed checkpoints for a DTM's accuracy check (core/raster/accuracy.py): a text or CSV file of
x, y, z, optionally an id and a land cover, read into plain arrays, and the land-cover labels
reduced to the two classes of the ASPRS standards, NVA (non-vegetated) and VVA (vegetated).

The file, as survey software exports it:

- the delimiter is found on the first line: a semicolon, a tab or a comma, else spaces; with a
  semicolon or a tab, a decimal comma is read as well (``500000,25``);
- an optional header names the columns (case, spaces, ``_`` and ``-`` ignored): x / e / east / easting,
  y / n / north / northing, z / h / elev / elevation / height, id / name / point / pt, class / landcover /
  land_cover / cover / lc; other columns are ignored. With a header the columns may come in any order
  (PNEZD exports: point, northing, easting, elevation, description);
- without a header the columns are ``x y z``, ``x y z class`` (a 4th column that is not a number) or
  ``id x y z [class]`` (a 4th column that is a number): x (easting) before y (northing);
- empty lines and lines starting with ``#`` are skipped.

Land cover: ``NVA``, ``non-vegetated`` (or ``nonvegetated``, ``non vegetated``), ``VVA``, ``vegetated``, in any
case; an empty cell leaves the checkpoint unlabelled (it counts in the overall figures only); anything
else is refused unless the caller's mapping names it (``road=NVA, forest=VVA``:
:func:`parse_land_cover_mapping`). May import: errors."""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Dict, Optional, Tuple

import numpy as np

from ..errors import InputError, InvalidParameterError

NVA, VVA = "NVA", "VVA"
#: the label of a checkpoint without a land cover
UNLABELLED = ""

#: header names of each column (compared after :func:`_key`)
COLUMN_NAMES = {
    "x": ("x", "e", "east", "easting"),
    "y": ("y", "n", "north", "northing"),
    "z": ("z", "h", "elev", "elevation", "height"),
    "id": ("id", "name", "point", "pt", "p", "pointid", "pointname", "pointnumber", "pnt"),
    "land_cover": ("class", "landcover", "cover", "lc"),
}
#: land-cover words known without a mapping (compared after :func:`_key`)
KNOWN_LAND_COVERS = {"nva": NVA, "nonvegetated": NVA, "vva": VVA, "vegetated": VVA}
KNOWN_TEXT = "NVA, VVA, non-vegetated, vegetated"


class ColumnsError(InputError):
    """The file's header (or its lack) does not tell its x, y, z columns, or a column named is not in it: QGIS's
    delimited text layer, which names the X and Y fields, reads it (the caller may say so)."""


def is_text_file(raw: bytes) -> bool:
    """Whether the first bytes ``raw`` of a file are text (no NUL byte): a GeoPackage or a LAS file is none."""
    return b"\0" not in raw[:4096]


class UnknownLandCover(InputError):
    """A land-cover value that is neither known nor in the caller's mapping (the caller says where to map it)."""


def _key(text: str) -> str:
    """``text`` lower case without spaces, ``_``, ``-``, dots and a unit in brackets: "Land_Cover" and "land
    cover" alike, "Easting (m)" and "Elevation [ft]" as "easting" and "elevation" (a surveyor's export)."""
    return re.sub(r"[\s_\-.]", "", re.sub(r"\s*[(\[][^)\]]*[)\]]\s*$", "", str(text))).lower()


@dataclass(frozen=True)
class Checkpoints:
    """Checkpoints as arrays: ``x``, ``y``, ``z`` (float64), ``ids`` (text, one each) and
    ``land_cover`` (``"NVA"``, ``"VVA"`` or ``""`` each; None when the source had no land cover)."""
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    ids: Tuple[str, ...]
    land_cover: Optional[Tuple[str, ...]] = None
    source: str = "checkpoints"
    #: the checkpoints left out for an empty height (their ids): a mark not observed, as a layer's NULL
    no_height: Tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self.x)


def parse_land_cover_mapping(text: str) -> Dict[str, str]:
    """``"road=NVA, forest=VVA; 1=NVA"`` as {key: "NVA" or "VVA"} (keys compared as :func:`_key` makes
    them); empty text: {}. Raises InvalidParameterError naming the item that is wrong."""
    mapping = {}
    for item in re.split(r"[,;]", text or ""):
        item = item.strip()
        if not item:
            continue
        if "=" not in item:
            head, sep, tail = item.rpartition(":")  # (road:NVA, a power user: meant road=NVA)
            if sep and head.strip() and KNOWN_LAND_COVERS.get(_key(tail)):
                raise InvalidParameterError(f"land cover mapping: '{item}' has no '=': write it as "
                                            f"{head.strip()}={tail.strip()}")
            raise InvalidParameterError(f"land cover mapping: '{item}' has no '=': write it as {item}=NVA or {item}=VVA")
        value, target = (part.strip() for part in item.rsplit("=", 1))
        known = KNOWN_LAND_COVERS.get(_key(target))
        if not value or known is None:
            raise InvalidParameterError(f"land cover mapping: '{item}' must map a value to NVA or VVA "
                                        f"(e.g. {value or 'road'}=NVA)")
        mapping[_key(value)] = known
    return mapping


def land_cover_of(value, mapping: Optional[Dict[str, str]] = None) -> str:
    """``"NVA"``, ``"VVA"`` or ``""`` (unlabelled: an empty value) for a land-cover value; the
    caller's ``mapping`` (:func:`parse_land_cover_mapping`) wins over the known words. Raises
    InputError saying what is accepted (the caller adds where the value is)."""
    if value is None:
        return UNLABELLED
    text = str(value).strip()
    if not text:
        return UNLABELLED
    key = _key(text)
    if mapping and key in mapping:
        return mapping[key]
    if key in KNOWN_LAND_COVERS:
        return KNOWN_LAND_COVERS[key]
    raise UnknownLandCover(f"'{text}' is not a land cover this check knows ({KNOWN_TEXT}): map it, e.g. "
                           f"{text}=NVA or {text}=VVA")


def _read_lines(path: str):
    """The file's lines (UTF-8, with or without BOM; else Windows-1252, as older survey software writes)."""
    try:
        with open(path, "rb") as f:
            raw = f.read()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, not a checkpoint file") from None
    except OSError as err:
        raise InputError(f"{path}: cannot be read ({err.strerror or err})") from None
    if not is_text_file(raw):
        raise InputError(f"{path}: is not a text file (give the checkpoints as x, y, z text or CSV)")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = raw.decode("cp1252", errors="replace")
    return text.splitlines()


def _delimiter(line: str) -> Optional[str]:
    """The delimiter of ``line``: ";", tab or ","; None for spaces."""
    for d in (";", "\t", ","):
        if d in line:
            return d
    return None


def _split(line: str, delimiter: Optional[str]):
    if delimiter is None:
        return line.split()
    fields = [f.strip() for f in line.split(delimiter)]
    return [f[1:-1] if len(f) >= 2 and f[0] == f[-1] and f[0] in "\"'" else f for f in fields]


def _number(text: str, decimal_comma: bool) -> Optional[float]:
    """``text`` as a finite number, or None."""
    t = text.strip()
    if decimal_comma and "," in t and "." not in t:
        t = t.replace(",", ".")
    try:
        value = float(t)
    except ValueError:
        return None
    return value if np.isfinite(value) else None


def _header_columns(fields, path: str, named: Optional[Dict[str, str]] = None) -> Dict[str, int]:
    """{column: index} from a header row, the columns ``named`` ({"z": "Elev_ortho", ...}) by their names
    (compared as :func:`_key` makes them); raises InputError when x, y or z is not found, or a named column."""
    columns = {}
    keys = [_key(name) for name in fields]
    for column, name in (named or {}).items():
        if _key(name) not in keys:
            raise ColumnsError(f"{path}, line 1: the header ({', '.join(repr(f) for f in fields)}) has no column "
                             f"'{name}' (given for {column.replace('_', ' ')})")
        columns[column] = keys.index(_key(name))
    for i, name in enumerate(fields):
        key = _key(name)
        for column, names in COLUMN_NAMES.items():
            if key in names and column not in columns:
                columns[column] = i
    missing = [c for c in ("x", "y", "z") if c not in columns]
    if missing:
        raise ColumnsError(f"{path}, line 1: the header ({', '.join(repr(f) for f in fields)}) names no "
                         f"{' and no '.join(missing)} column (x: x/easting/e, y: y/northing/n, z: z/elevation/height/h)")
    return columns


def read_checkpoints(path: str, *, mapping: Optional[Dict[str, str]] = None,
                     columns: Optional[Dict[str, str]] = None, land_cover: bool = True) -> Checkpoints:
    """The checkpoints of a text/CSV file (see the module's notes on the format). Checkpoints without
    an id column are named by their line ("line 14"). ``columns`` names header columns the file's
    header words do not give away ({"z": "Elev_ortho", "id": "Name", "land_cover": "Surface"}; keys among
    x, y, z, id, land_cover); without a header, ``field_3`` is the third column (OGR's name for it, which
    QGIS's field lists show). ``land_cover`` False: no column is read as the land cover unless named (QGIS,
    where the land-cover field is chosen or left empty). Raises InputError naming the file and line."""
    path = os.fspath(path)
    lines = [(n, line) for n, line in enumerate(_read_lines(path), 1)
             if line.strip() and not line.lstrip().startswith("#")]
    if not lines:
        raise InputError(f"{path}: holds no checkpoints (an empty file)")
    delimiter = _delimiter(lines[0][1])
    decimal_comma = delimiter in (";", "\t")
    first = _split(lines[0][1], delimiter)
    if len(first) < 3:
        raise InputError(f"{path}, line {lines[0][0]}: {len(first)} field(s); a checkpoint needs x, y and z "
                         f"({'spaces' if delimiter is None else repr(delimiter)} taken as the delimiter)")
    def number_or_empty(f):  # (an empty height is a mark not observed, not a header's word)
        return _number(f, decimal_comma) is not None or not f.strip()

    header = any(not number_or_empty(f) for f in first[:3]) and \
        not (len(first) >= 4 and _number(first[0], decimal_comma) is None
             and all(_number(f, decimal_comma) is not None for f in first[1:3]) and number_or_empty(first[3]))
    named = {k: v for k, v in (columns or {}).items() if v}
    unknown = sorted(set(named) - set(COLUMN_NAMES))
    if unknown:
        raise InvalidParameterError(f"checkpoint columns: {', '.join(unknown)} is not one of {', '.join(COLUMN_NAMES)}")
    positional = {k: int(re.fullmatch(r"field_(\d+)", v).group(1)) - 1 for k, v in named.items()
                  if re.fullmatch(r"field_(\d+)", v) and int(re.fullmatch(r"field_(\d+)", v).group(1)) >= 1}
    if named and not header and len(positional) < len(named):
        raise ColumnsError(f"{path}: has no header line, so it has no column "
                         f"{' or '.join(repr(v) for k, v in named.items() if k not in positional)} (without a header "
                         "the columns are x y z, x y z class or id x y z [class], or field_1, field_2, ... by their "
                         "place)")
    if not header and any(i >= len(first) for i in positional.values()):
        raise InputError(f"{path}, line {lines[0][0]}: {len(first)} field(s), no "
                         f"{', '.join(v for k, v in named.items() if positional.get(k, 0) >= len(first))}")
    if header:
        columns = _header_columns(first, path, named)
        lines = lines[1:]
    elif len(first) >= 4 and (_number(first[3], decimal_comma) is not None or _number(first[0], decimal_comma) is None):
        columns = {"id": 0, "x": 1, "y": 2, "z": 3}
        if len(first) >= 5:
            columns["land_cover"] = 4
    else:
        columns = {"x": 0, "y": 1, "z": 2}
        if len(first) >= 4:
            columns["land_cover"] = 3
    if not header:
        for column, index in positional.items():  # (field_3 named for z: the third column is z)
            columns = {k: i for k, i in columns.items() if i != index}
            columns[column] = index
    if not land_cover and "land_cover" not in named:
        columns.pop("land_cover", None)
    if not lines:
        raise InputError(f"{path}: holds a header and no checkpoints")
    needed = max(columns.values()) + 1
    xyz, ids, covers, no_height = [], [], [], []
    for n, line in lines:
        fields = _split(line, delimiter)
        if len(fields) < max(columns[c] for c in ("x", "y", "z")) + 1:
            raise InputError(f"{path}, line {n}: {len(fields)} field(s), expected {needed} "
                             f"({', '.join(c for c, _i in sorted(columns.items(), key=lambda kv: kv[1]))})")
        i = columns.get("id")
        if not fields[columns["z"]].strip() and all(_number(fields[columns[c]], decimal_comma) is not None
                                                    for c in ("x", "y")):
            # (an empty height: a mark not observed, left out and named as a layer's NULL height is; the
            # whole file was refused, a technical writer)
            no_height.append(fields[i] if i is not None and i < len(fields) and fields[i] else f"line {n}")
            continue
        row = []
        for column in ("x", "y", "z"):
            value = _number(fields[columns[column]], decimal_comma)
            if value is None:
                raise InputError(f"{path}, line {n}: '{fields[columns[column]]}' is not a number (column {column})")
            row.append(value)
        xyz.append(row)
        i = columns.get("id")
        ids.append(fields[i] if i is not None and i < len(fields) and fields[i] else f"line {n}")
        i = columns.get("land_cover")
        if i is not None:
            value = fields[i] if i < len(fields) else ""
            try:
                covers.append(land_cover_of(value, mapping))
            except UnknownLandCover as err:
                raise UnknownLandCover(f"{path}, line {n}: {err}") from None
    if not xyz:
        raise InputError(f"{path}: every checkpoint's height (column z) is empty: is it the column of their heights?")
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    return Checkpoints(xyz[:, 0].copy(), xyz[:, 1].copy(), xyz[:, 2].copy(), tuple(ids),
                       tuple(covers) if "land_cover" in columns else None, source=path, no_height=tuple(no_height))
