"""The PRESET input of the ground-filter algorithms: a preset file (written by groundsieve:tune, or
one shipped with the plugin in presets/) whose parameters replace the filter's defaults.

The rule (the same as the command line's ``--preset``): the preset replaces the filter's
defaults; a dialog value set to something other than the filter's default wins over the preset
(so "the preset, with a threshold of 0.3 m" is one change in the dialog); where the parameters hold
only what was typed (qgis_process's command line, a script's processing.run), every given value
wins, even at the default (:func:`filled_by_qgis` tells the two apart, the same on every platform). A preset for another
filter, another preset format version, an unknown or out-of-range parameter is refused with the
file's name and the problem (core/engine/presets.py).

Used by algorithms/base.py (GroundFilterAlgorithm): ``add_preset_parameter`` right after the
filter's own parameters, and ``buildFilter`` returns ``build_filter(self, parameters, context)``.
"""
import os

from qgis.core import QgsProcessingParameterFile

PRESET = "PRESET"
PRESET_FILTER = "GroundSieve preset (*.json *.JSON)"


def shipped_folder() -> str:
    return os.path.join(os.path.dirname(os.path.dirname(__file__)), "presets")


def add_preset_parameter(algorithm) -> None:
    """Add the optional PRESET file input to a ground-filter algorithm."""
    algorithm.addParameter(QgsProcessingParameterFile(
        PRESET, "Preset: parameters file (from Tune, or in the plugin's presets folder); replaces the defaults",
        behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=PRESET_FILTER, optional=True))


def shipped_names():
    """The names of the presets shipped with the plugin (file names without .json)."""
    folder = shipped_folder()
    return sorted(f[:-5] for f in os.listdir(folder) if f.endswith(".json")) if os.path.isdir(folder) else []


def shipped_preset_problem(label, value):
    """None when ``value`` names a shipped preset (``forest-smrf.json``: QGIS takes a file input's
    value only with the extension of its filter); else what is wrong, with the shipped names."""
    bare = os.sep not in value and "/" not in value
    if bare and value.endswith(".json") and value[:-5] in shipped_names():
        return None
    if bare and value in shipped_names():
        return f"{label}: give the shipped preset's name with .json: {value}.json"
    return (f"{label}: {value} does not exist or is not a file (the shipped presets, which can be given by "
            f"name: {', '.join(n + '.json' for n in shipped_names())}; their folder: {shipped_folder()})")


def preset_path(algorithm, parameters, context) -> str:
    if PRESET not in parameters or parameters.get(PRESET) in (None, ""):
        return ""
    return algorithm.parameterAsFile(parameters, PRESET, context) or ""


def build_filter(algorithm, parameters, context, log=None):
    """The filter of ``algorithm`` (a GroundFilterAlgorithm with FILTER set): the dialog's values,
    over the preset's when a PRESET is given, then the algorithm's own completion of them
    (``completeFilterArguments``). Raises the core's PresetError / InvalidParameterError
    (GroundSieveError: processAlgorithm turns it into a QgsProcessingException)."""
    from ..core.engine import parameters as table
    from ..core.engine.presets import describe, load_preset, merge
    kwargs = algorithm.filterArguments(parameters, context)
    path = preset_path(algorithm, parameters, context)
    preset = load_preset(path, algorithm.FILTER) if path else None
    typed = typed_fields(algorithm, algorithm.FILTER, parameters)
    # what the user set: lengths in the cloud's CRS unit; the defaults and a preset's values are metres
    # (converted for a cloud in feet: workflow.defaults_in_crs_unit)
    chosen = {p.field for p in table.params(algorithm.FILTER)
              if set_by_user(algorithm, parameters, p.name, kwargs[p.field], table.default(algorithm.FILTER, p.field))}
    if preset is not None:
        kwargs = merge(algorithm.FILTER, preset.values, kwargs, typed)
    kwargs = algorithm.completeFilterArguments(kwargs)
    built = table.mark_user_set(table.filter_class(algorithm.FILTER)(**kwargs), chosen)
    if log is not None:
        for line in describe(algorithm.FILTER, built, preset, typed_wins=bool(typed) and preset is not None):
            log(line)
    return built


def filled_by_qgis(algorithm, parameters) -> bool:
    """Whether ``parameters`` were filled in by QGIS rather than typed: the dialog, the batch dialog,
    a model's step and a copied Python command hold a value for (nearly) every parameter, typed or
    left alone; qgis_process's command line and a script's ``processing.run`` hold what was given.
    Nearly: a model saved before a parameter was added lacks it (a reviewer's model, saved before
    LOW_OUTLIER_SLOPE, lost forest-smrf's values under qgis_process and kept them in PyQGIS: the rule
    followed the platform). Two thirds of the algorithm's parameters tell one from the other."""
    names = [d.name() for d in algorithm.parameterDefinitions()]
    return sum(1 for n in names if n in parameters) * 3 >= 2 * len(names)


def typed_names(algorithm, parameters) -> set:
    """The parameters given on purpose: where the parameters were typed (qgis_process's command line,
    ``processing.run`` with some parameters), every one given, a value equal to the default included.
    Empty where QGIS filled every parameter (:func:`filled_by_qgis`): there a typed default cannot be
    told from an untouched one."""
    return set() if filled_by_qgis(algorithm, parameters) else set(parameters)


def typed_fields(algorithm, name: str, parameters) -> set:
    """The filter's fields given on purpose (:func:`typed_names`): a value equal to the default given
    there wins over the preset, as on GroundSieve's own command line."""
    from ..core.engine import parameters as table
    typed = typed_names(algorithm, parameters)
    return {p.field for p in table.params(name) if p.name in typed}


def set_by_user(algorithm, parameters, name: str, value, default) -> bool:
    """Whether the user set parameter ``name`` (its ``value``): another value than the ``default``, or one
    given on purpose (:func:`typed_names`). Such lengths are in the cloud's CRS unit; the defaults and
    a preset's values are metres (core/engine/workflow.py defaults_in_crs_unit)."""
    return value != default or name in typed_names(algorithm, parameters)


PRESET_HELP = """<p><b>Preset</b> (optional; every filter but the learned hybrid): a parameters file written by <i>Tune a ground filter on a
labelled patch</i> (groundsieve:tune), or one shipped with the plugin, by its file or its name
(<code>forest-smrf.json</code>; the plugin's <code>presets</code> folder).
Its parameters replace the filter's defaults; a parameter you set in this dialog to a value other than
its default wins over the preset (in qgis_process and in a script's processing.run with a few parameters, every parameter given wins). A preset for another filter, of another format version, or with an
unknown or out-of-range parameter is refused with the file's name and the problem.</p>"""
