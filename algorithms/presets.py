"""The PRESET input of the ground-filter algorithms: a preset file (written by groundsieve:tune, or
one shipped with the plugin in presets/) whose parameters replace the filter's defaults.

The rule (the same as the command line's ``--preset``): the preset replaces the filter's
defaults; a dialog value set to something other than the filter's default wins over the preset
(so "the preset, with a threshold of 0.3 m" is one change in the dialog); under qgis_process, whose
parameters hold only what was typed, every given value wins, even at the default. A preset for another
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
    typed = typed_fields(algorithm.FILTER, parameters) if preset is not None else set()
    if preset is not None:
        kwargs = merge(algorithm.FILTER, preset.values, kwargs, typed)
    kwargs = algorithm.completeFilterArguments(kwargs)
    built = table.filter_class(algorithm.FILTER)(**kwargs)
    if log is not None:
        for line in describe(algorithm.FILTER, built, preset, typed_wins=bool(typed)):
            log(line)
    return built


def running_in_qgis_process() -> bool:
    """Whether this is qgis_process, whose parameters hold only what the command line gave (the
    dialog, the modeler and the batch give every parameter, typed or not)."""
    from qgis.core import QgsApplication
    return QgsApplication.platform() == "qgis_process"


def typed_fields(name: str, parameters) -> set:
    """The filter's fields given on qgis_process's command line: there a value equal to the
    default was typed on purpose and wins over the preset, as on GroundSieve's own command line.
    Empty elsewhere, and when every parameter of the filter is there: a dialog, a model's step (also
    run by qgis_process) or a batch fills them all, and cannot tell a typed default from an untouched one."""
    if not running_in_qgis_process():
        return set()
    from ..core.engine import parameters as table
    params = table.params(name)
    given = {p.field for p in params if p.name in parameters}
    return set() if len(given) == len(params) else given


PRESET_HELP = """<p><b>Preset</b> (optional; every filter but the learned hybrid): a parameters file written by <i>Tune a ground filter on a
labelled patch</i> (groundsieve:tune), or one shipped with the plugin, by its file or its name
(<code>forest-smrf.json</code>; the plugin's <code>presets</code> folder).
Its parameters replace the filter's defaults; a parameter you set in this dialog to a value other than
its default wins over the preset (in qgis_process, every parameter given wins). A preset for another filter, of another format version, or with an
unknown or out-of-range parameter is refused with the file's name and the problem.</p>"""
