"""Preset files: a filter's parameters saved once (by ``groundsieve:tune``, or shipped with the
plugin in ``presets/``) and given to every run of that filter.

A preset is a small JSON file::

    {"format": "groundsieve-preset", "format_version": 1, "groundsieve": "0.1.0",
     "filter": "smrf",
     "parameters": {"SLOPE": 0.2, "WINDOW": 16.0, "THRESHOLD": 0.45, "SCALAR": 1.2},
     "description": "...", "source": {"patch": "samp11.txt", "metric": "total", "cv_total": 0.091}}

Parameters go by their Processing names (core/engine/parameters.py; the finer settings the
dialog does not show by their field in upper case). Parameters a preset does not give keep the
filter's defaults. The rule when a run gets a preset and dialog / command-line values: the
preset replaces the filter's defaults, and a value set to something other than the filter's
default wins over the preset (so a user may change one parameter of a preset).

Validation: format and format version, the filter, every name, its type, the table's minimum,
maximum and choices, then the filter dataclass's own checks; every error names the file.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Mapping, Optional

from ..errors import InputError
from ..io.outputs import atomic_path
from . import parameters as P

FORMAT = "groundsieve-preset"
FORMAT_VERSION = 1

#: the presets shipped with the plugin
SHIPPED_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "presets")


class PresetError(InputError):
    """A preset file cannot be used (names the file and the problem)."""


@dataclass(frozen=True)
class Preset:
    filter: str
    values: Dict[str, object]           #: dataclass field -> value (only those the preset gives)
    path: str = ""
    description: str = ""
    source: Dict[str, object] = field(default_factory=dict)
    groundsieve: str = ""

    def build(self, given: Optional[Mapping[str, object]] = None, typed: Iterable[str] = ()):
        """The filter with this preset's values over its defaults and, over both, the ``given``
        values (field -> value) that differ from the filter's defaults, and those of the fields in
        ``typed`` whatever their value (the command line knows what was typed)."""
        given, typed = given or {}, set(typed)
        for key in given:
            P.default(self.filter, key)  # (an unknown field is refused in words, not as a KeyError)
        built = P.filter_class(self.filter)(**merge(self.filter, self.values, given, typed))
        return P.mark_user_set(built, {k for k, v in given.items() if v != P.default(self.filter, k) or k in typed})


def merge(name: str, preset_values: Mapping[str, object], given: Mapping[str, object],
          typed: Iterable[str] = ()) -> Dict[str, object]:
    """Keyword arguments of the filter: defaults < preset < values given that differ from the default
    (or whose field is in ``typed``: given on purpose, even at the default)."""
    typed = set(typed)
    out = {f.name: f.default for f in P.filter_fields(name)}
    out.update(preset_values)
    for key, value in given.items():
        if value != P.default(name, key) or key in typed:
            out[key] = value
    return out


def describe(name: str, built, preset: Optional["Preset"] = None, typed_wins: bool = False) -> List[str]:
    """Log lines saying which parameters the filter ``built`` (of filter ``name``) runs with: the
    dialog's, and the finer settings (by their preset names) where they are not the defaults; with
    a preset, which fields come from it and which the run changed (the dialog, the command line, or
    a filter completing its arguments)."""
    values = {f.name: getattr(built, f.name) for f in P.filter_fields(name)}
    table = {p.field: p for p in P.params(name)}
    names = {fld: key for key, fld in P.preset_names(name).items()}

    def show(fld):
        v = values[fld]
        v = f"{v:g}" if isinstance(v, float) else str(v)
        unit = table[fld].unit if fld in table else ""
        return f"{names.get(fld, fld)} {v}" + (f" {unit}" if unit in ("m", "degrees", "cells") else "")
    shown = list(table) + [f.name for f in P.core_only_fields(name)
                           if values[f.name] != f.default or (preset is not None and f.name in preset.values)]
    lines = [f"{P.FILTERS[name][1]} parameters: " + ", ".join(show(f) for f in shown)]
    if preset is not None:
        given = [f for f in shown if f in preset.values]
        changed = [f for f in given if values[f] != preset.values[f]]
        lines.append(f"From the preset {os.path.basename(preset.path) or preset.path}: "
                     + (", ".join(show(f) for f in given if f not in changed) or "nothing")
                     + ("; changed from the preset: " + ", ".join(show(f) for f in changed) if changed else "")
                     + ("" if typed_wins else " (a value equal to the filter's default never replaces the preset's)"))
        if preset.description and os.path.dirname(os.path.abspath(preset.path)) == os.path.abspath(SHIPPED_DIR):
            # (what a shipped preset is for and what it measured, where the user sees the run: a forester took
            # forest-smrf for a forest's preset, and its DTM lifted crowns on a real plot)
            lines.append(f"The shipped preset {os.path.basename(preset.path)}: {preset.description}.")
    return lines


def _version() -> str:
    from ..io.provenance import package_version
    return package_version()


def check_value(name: str, key: str, value, where: str):
    """``value`` of the preset's parameter ``key`` (Processing name) converted to the field's type,
    or a PresetError naming ``where``."""
    fields = P.preset_names(name)
    if key not in fields:
        raise PresetError(f"{where}: {P.FILTERS[name][1]} has no parameter {key!r} "
                          f"(its parameters: {', '.join(sorted(fields))})")
    fld = fields[key]
    kind = P.field_type(name, fld)
    table = P.by_name(name).get(key)
    if kind is bool:
        if not isinstance(value, bool):
            raise PresetError(f"{where}: parameter {key} must be true or false (got {value!r})")
        return value
    if kind in (int, float):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise PresetError(f"{where}: parameter {key} must be a number (got {value!r})")
        if kind is int:
            if value != int(value):
                raise PresetError(f"{where}: parameter {key} must be a whole number (got {value!r})")
            value = int(value)
        else:
            value = float(value)
    elif not isinstance(value, str):
        raise PresetError(f"{where}: parameter {key} must be text (got {value!r})")
    if table is not None:
        if table.choices and value not in table.choices:
            raise PresetError(f"{where}: parameter {key} is {value!r}, not one of "
                              f"{', '.join(repr(c) for c in table.choices)}")
        if table.minimum is not None and kind in (int, float) and value < table.minimum:
            raise PresetError(f"{where}: parameter {key} is {value}, below its minimum {table.minimum}")
        if table.maximum is not None and kind in (int, float) and value > table.maximum:
            raise PresetError(f"{where}: parameter {key} is {value}, above its maximum {table.maximum}")
    return value


def preset_from_dict(data, where: str, expected_filter: Optional[str] = None) -> Preset:
    if not isinstance(data, dict):
        raise PresetError(f"{where}: not a GroundSieve preset (a JSON object is expected)")
    if data.get("format") != FORMAT:
        raise PresetError(f"{where}: not a GroundSieve preset (\"format\" is {data.get('format')!r}, "
                          f"expected {FORMAT!r})")
    version = data.get("format_version")
    if version != FORMAT_VERSION:
        raise PresetError(f"{where}: preset format version {version!r}, this GroundSieve ({_version()}) reads "
                          f"version {FORMAT_VERSION}; save the preset again with this version (groundsieve:tune)")
    name = data.get("filter")
    if name not in P.FILTERS:
        raise PresetError(f"{where}: unknown filter {name!r} (one of {', '.join(P.FILTERS)})")
    if expected_filter is not None and name != expected_filter:
        raise PresetError(f"{where}: a preset for {P.FILTERS[name][1]} ({name}), not for "
                          f"{P.FILTERS[expected_filter][1]} ({expected_filter})")
    params = data.get("parameters")
    if not isinstance(params, dict):
        raise PresetError(f"{where}: \"parameters\" must be an object of name: value")
    fields = P.preset_names(name)
    values = {}
    for key, value in params.items():
        value = check_value(name, key, value, where)  # an unknown name is refused here
        values[fields[key]] = value
    preset = Preset(filter=name, values=values, path=where, description=str(data.get("description", "")),
                    source=data.get("source") if isinstance(data.get("source"), dict) else {},
                    groundsieve=str(data.get("groundsieve", "")))
    try:  # the filter's own checks (e.g. SMRF's window at least one cell)
        preset.build()
    except InputError:
        raise
    except ValueError as err:
        raise PresetError(f"{where}: the preset's parameters are refused by {P.FILTERS[name][1]}: {err}") from err
    return preset


def shipped_path(name: str) -> Optional[str]:
    """The path of a shipped preset given by its name (``uav-lidar-smrf``) or None."""
    path = os.path.join(SHIPPED_DIR, name if name.endswith(".json") else name + ".json")
    return path if os.path.isfile(path) else None


def load_preset(path: str, expected_filter: Optional[str] = None) -> Preset:
    """Read and validate a preset file (or a shipped preset's name)."""
    path = os.fspath(path)
    if expected_filter is not None:
        P.known_filter(expected_filter)
    if not os.path.isfile(path):
        shipped = shipped_path(path) if os.sep not in path and "/" not in path else None
        if shipped is None:
            raise PresetError(f"{path}: preset file not found")
        path = shipped
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except (OSError, UnicodeDecodeError) as err:
        raise PresetError(f"{path}: cannot read the preset ({err})") from err
    except json.JSONDecodeError as err:
        raise PresetError(f"{path}: not a GroundSieve preset (not JSON: {err})") from err
    return preset_from_dict(data, path, expected_filter)


def preset_dict(name: str, values: Mapping[str, object], *, description: str = "",
                source: Optional[Mapping[str, object]] = None) -> dict:
    """The JSON object of a preset giving ``values`` (field -> value) of filter ``name``."""
    to_name = {fld: key for key, fld in P.preset_names(P.known_filter(name)).items()}
    for key in values:
        if key not in to_name:
            P.default(name, key)  # (its words for an unknown field)
            raise PresetError(f"{key!r} of {P.FILTERS[name][1]} is set by a run, not by a preset")
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "groundsieve": _version(), "filter": name,
            "parameters": {to_name[k]: v for k, v in values.items()},
            "description": description, "source": dict(source or {})}


def write_preset(path: str, name: str, values: Mapping[str, object], **kwargs) -> None:
    data = preset_dict(name, values, **kwargs)
    preset_from_dict(json.loads(json.dumps(data)), path, name)  # never write a preset we would refuse
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=2)
            f.write("\n")
