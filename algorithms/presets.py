"""The PRESET input of the ground-filter algorithms: a preset file (written by groundsieve:tune, or
one shipped with the plugin in presets/) whose parameters replace the filter's defaults.

The rule (the same as the command line's ``--preset``): the preset replaces the filter's
defaults; a dialog value set to something other than the filter's default wins over the preset
(so "the preset, with a threshold of 0.3 m" is one change in the dialog). A preset for another
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


def preset_path(algorithm, parameters, context) -> str:
    if PRESET not in parameters or parameters.get(PRESET) in (None, ""):
        return ""
    return algorithm.parameterAsFile(parameters, PRESET, context) or ""


def build_filter(algorithm, parameters, context):
    """The filter of ``algorithm`` (a GroundFilterAlgorithm with FILTER set): the dialog's values,
    over the preset's when a PRESET is given, then the algorithm's own completion of them
    (``completeFilterArguments``). Raises the core's PresetError / InvalidParameterError
    (GroundSieveError: processAlgorithm turns it into a QgsProcessingException)."""
    from ..core.engine import parameters as table
    from ..core.engine.presets import load_preset, merge
    kwargs = algorithm.filterArguments(parameters, context)
    path = preset_path(algorithm, parameters, context)
    if path:
        kwargs = merge(algorithm.FILTER, load_preset(path, algorithm.FILTER).values, kwargs)
    return table.filter_class(algorithm.FILTER)(**algorithm.completeFilterArguments(kwargs))


PRESET_HELP = """<p><b>Preset</b> (optional; every filter but the learned hybrid): a parameters file written by <i>Tune a ground filter on a
labelled patch</i> (groundsieve:tune), or one shipped with the plugin (its <code>presets</code> folder).
Its parameters replace the filter's defaults; a parameter you set in this dialog to a value other than
its default wins over the preset. A preset for another filter, of another format version, or with an
unknown or out-of-range parameter is refused with the file's name and the problem.</p>"""
