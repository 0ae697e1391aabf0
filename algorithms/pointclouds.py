"""Point-cloud layers: what the running QGIS can open, decided here and nowhere else.

QGIS opens a point cloud through a point-cloud data provider: ``pdal`` (LAS/LAZ and more; in the
Windows and macOS builds), ``copc`` (.copc.laz), ``vpc`` (.vpc, QGIS >= 3.32), ``ept`` (ept.json).
Debian's 3.22 registers only ``ept``; the 3.40 from bookworm-backports ``copc``, ``ept`` and ``vpc``.
Every decision below comes from the file patterns the registered point-cloud providers declare
(``QgsProviderMetadata.filters``), never from a version number:

- the input stays a file parameter (a path, a folder of LAS/LAZ, a .vpc, an ISPRS .txt) on every
  QGIS; where a provider opens one of the formats the filters read, an optional *loaded point-cloud
  layer* parameter is offered beside it (its source file is read);
- the classified cloud is loaded as a point-cloud layer when the run ends where a provider opens
  the file written (a .las/.laz with ``pdal``, a .vpc with ``vpc``); elsewhere the log says where it
  was written and why it is not loaded, with a warning when it is a temporary file (deleted when
  QGIS closes); the cloud of a graphical model's step that is not a model
  output is never loaded, as QGIS loads none of its own (``is_model_intermediate``);
- in the graphical modeler, the point-cloud inputs offer only what can be a point cloud (see
  ``point_cloud_sources``): QGIS's modeler keys a file parameter's choices on output *types* alone
  (``availableSourcesForChild``, 3.22 to 3.40), so it would offer a DTM raster, a vector layer or an
  ``.npz`` model as well; the inputs carry the ``widget_wrapper`` metadata that Processing's dialogs
  honour, whose class keeps QGIS's own widgets and removes the other outputs in the modeler only.
"""
import fnmatch
import os

from qgis.core import (QgsProcessing, QgsProcessingContext, QgsProcessingException,
                       QgsProcessingParameterDefinition, QgsProcessingUtils, QgsProviderMetadata, QgsProviderRegistry)

try:  # QGIS >= 3.32 names the enum Qgis.FileFilterType.PointCloud
    from qgis.core import Qgis
    _POINT_CLOUD_FILTER = Qgis.FileFilterType.PointCloud
except AttributeError:  # QGIS 3.22
    _POINT_CLOUD_FILTER = QgsProviderMetadata.FilterType.FilterPointCloud

#: what the ground filters read and write (``.copc.laz`` is LAZ 1.4: laspy reads it)
READ_SUFFIXES = (".las", ".laz", ".copc.laz", ".vpc")


def point_cloud_patterns():
    """{provider key: [lower-case file patterns]} of the registered point-cloud providers, from
    the filter each declares (e.g. ``"COPC Point Clouds (*.copc.laz *.COPC.LAZ)"``)."""
    registry = QgsProviderRegistry.instance()
    found = {}
    for key in registry.providerList():
        metadata = registry.providerMetadata(key)
        text = metadata.filters(_POINT_CLOUD_FILTER) if metadata is not None else ""
        patterns = []
        for group in (text or "").split(";;"):
            inside = group[group.find("(") + 1:group.rfind(")")] if "(" in group else ""
            patterns += [p.lower() for p in inside.split() if p not in ("*", "*.*")]
        if patterns:
            found[key] = sorted(set(patterns))
    return found


def providers_opening(path, patterns=None):
    """The keys of the point-cloud providers whose patterns match the file name of ``path``."""
    name = os.path.basename(str(path)).lower()
    patterns = point_cloud_patterns() if patterns is None else patterns
    return [key for key, pats in patterns.items() if any(fnmatch.fnmatchcase(name, p) for p in pats)]


def reads_loaded_layers(patterns=None):
    """True where a registered provider opens one of the formats the filters read: a loaded
    point-cloud layer can then be an input."""
    return any(providers_opening("cloud" + suffix, patterns) for suffix in READ_SUFFIXES)


# -- input ----------------------------------------------------------------------------------
def add_input_layer_parameter(algorithm, name, label):
    """Add the optional loaded-point-cloud-layer input where this QGIS can open a format the
    filters read; return whether it was added (the file input is then optional too)."""
    if not reads_loaded_layers():
        return False
    from qgis.core import QgsProcessingParameterPointCloudLayer  # QGIS >= 3.22
    param = QgsProcessingParameterPointCloudLayer(name, label, optional=True)
    param.setHelp("A point-cloud layer loaded in the project (its file is read); replaces the path above.")
    offer_point_clouds_in_modeler(param)
    algorithm.addParameter(param)
    return True


def input_path(algorithm, parameters, context, file_name, layer_name):
    """The path of the input cloud: the loaded layer's file when a layer is given, else the file
    parameter's value; a layer that is not a local file the filters read is refused by its label."""
    definition = algorithm.parameterDefinition(layer_name)
    value = parameters.get(layer_name) if definition is not None else None
    if isinstance(value, str) and value.lower().endswith(READ_SUFFIXES) and os.path.isfile(value):
        return value  # a file path (e.g. a previous child's classified cloud in a model), read as is
    if value:
        layer = algorithm.parameterAsPointCloudLayer(parameters, layer_name, context)
        if layer is None:
            raise QgsProcessingException(f"{definition.description()}: {parameters.get(layer_name)} is not a "
                                         "point-cloud layer this QGIS can open")
        source = layer.source().split("|")[0]
        if not (os.path.exists(source) and source.lower().endswith(READ_SUFFIXES)):
            raise QgsProcessingException(
                f"{definition.description()}: the layer '{layer.name()}' reads {source}, not a local "
                f"{'/'.join(READ_SUFFIXES)} file: give its file path instead")
        return source
    path = algorithm.parameterAsFile(parameters, file_name, context)
    if not path:
        file_label = algorithm.parameterDefinition(file_name).description()
        raise QgsProcessingException(f"{file_label}: give a file, a folder or a .vpc" +
                                     (f", or a layer in '{definition.description()}'" if definition else ""))
    return path


def is_survey_input(path):
    """Several files behind the input (a folder of LAS/LAZ, a .vpc): several classified files out
    (one file, even behind a folder or a .vpc, gives one: the core's ``output_files``)."""
    try:
        from ..core.io.lasfiles import expand_inputs
        return bool(path) and len(expand_inputs(path)) > 1
    except Exception:  # noqa: BLE001 - a bad input is the core's to report, in its words
        return False


def _in_temporary_folder(path, context):
    """True when ``path`` lies in Processing's temporary folder, where it generates the temporary
    destinations (``QgsProcessingUtils.generateTempFilename``)."""
    folders = {QgsProcessingUtils.tempFolder()}
    try:
        folders.add(QgsProcessingUtils.tempFolder(context))  # QGIS >= 3.32 takes the context's setting
    except TypeError:
        pass
    return bool(path) and any(os.path.abspath(path).startswith(os.path.abspath(folder) + os.sep)
                              for folder in folders if folder)


def _temporary(value, path, context):
    """True when an output is Processing's temporary one: the dialog's default "[Save to temporary
    file]", ``TEMPORARY_OUTPUT`` in qgis_process, a graphical model's intermediate step."""
    sink = getattr(value, "sink", None)
    if sink is not None:
        value = sink.staticValue()
    if value == QgsProcessing.TEMPORARY_OUTPUT:
        return True
    return _in_temporary_folder(path, context)


def is_model_intermediate(value, context):
    """True when the value of a destination parameter is the one a graphical model gives an output
    of a child that is not a model output: QgsProcessingModelAlgorithm.parametersForChildAlgorithm
    (3.22 to 3.40) passes such a child ``generateTemporaryDestination()``, a plain path in
    Processing's temporary folder, already resolved. Every other run's value differs: a model
    output (final) is the model's own value (a path or a QgsProcessingOutputLayerDefinition); the
    dialog passes a QgsProcessingOutputLayerDefinition, its "[Save to temporary file]" and
    qgis_process ``TEMPORARY_OUTPUT`` unresolved; a script the path it names."""
    return (isinstance(value, str) and value != QgsProcessing.TEMPORARY_OUTPUT
            and _in_temporary_folder(value, context))


def classified_output_path(algorithm, parameters, context, name, input_path):
    """The classified cloud's path. Several input files give several classified files, which a .vpc
    names (core/engine/tiles.py ``output_files``): a temporary output of a folder or .vpc input is
    therefore made a .vpc, where the user could not choose its extension (the dialog's default, a
    model's intermediate step); a named one is left for the core to check."""
    path = algorithm.parameterAsFileOutput(parameters, name, context)
    if path and is_survey_input(input_path) and not path.lower().endswith(".vpc") \
            and _temporary(parameters.get(name), path, context):
        path = os.path.splitext(path)[0] + ".vpc"
    return path


def make_input_optional(param):
    """The file input is optional where a loaded layer may replace it; its label says that one of the
    two is needed (QGIS marks it "[optional]", and `qgis_process help` lists it optional: a modeler
    reviewer's model without an input passed validation on 3.40)."""
    param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagOptional)
    param.setDescription(param.description() + EITHER_INPUT)


#: what :func:`make_input_optional` adds to the file input's label (left out of the messages about its value)
EITHER_INPUT = ": this or a loaded layer below is needed"


# -- output ---------------------------------------------------------------------------------
def nothing_to_write(algorithm, cloud="OUTPUT", dtm="DTM"):
    """The refusal of a run whose classified cloud and DTM are both skipped, in the dialog's words."""
    def label(name):
        return algorithm.parameterDefinition(name).description().split(" (")[0]
    return f"{label(cloud)} and {label(dtm)} are both skipped: the run would write nothing; give one of them"


def load_or_log(context, feedback, path, layer_name, output_name, value=None):
    """Load the point cloud written at ``path`` when the run ends, where a provider of this QGIS
    opens it; else say in the log where it is and why it is not loaded, and warn when it is
    Processing's temporary output (``_temporary``: the dialog's "[Save to temporary file]"), which
    QGIS deletes at exit: not loaded, nothing else would tell the user. Returns the provider key
    used, or None. (Under qgis_process nothing is loaded either way.)

    ``value``, the output parameter's value as the run was given it: the intermediate output of a
    graphical model's step (``is_model_intermediate``) is never loaded, as QGIS loads none of its
    own (its layer outputs are loaded only when their value is a QgsProcessingOutputLayerDefinition
    with a destination project, QgsProcessingParameters.parameterAsOutputLayer, which a model gives
    its final outputs alone).

    The layer is named ``layer_name`` unless ``value`` names its destination: a model output's
    value carries the model output's name (QgsProcessingOutputLayerDefinition.destinationName, set
    by QgsProcessingModelAlgorithm), which QGIS's own outputs take as their layer's name, so that
    two outputs of one model are told apart in the Layers panel."""
    layer_name = getattr(value, "destinationName", None) or layer_name
    if is_model_intermediate(value, context):
        feedback.pushDebugInfo(f"{layer_name}: {path}: an intermediate output of the model, not loaded.")
        return None
    keys = providers_opening(path)
    if keys:
        details = QgsProcessingContext.LayerDetails(layer_name, context.project(), output_name,
                                                    QgsProcessingUtils.LayerHint.PointCloud)
        context.addLayerToLoadOnCompletion(path, details)
        undrawn = _members_not_opened(path)
        if undrawn:
            feedback.pushInfo(f"{layer_name}: {path}: this QGIS has no point-cloud provider that opens its "
                              f"{'/'.join(undrawn)} files (QGIS builds with PDAL, as on Windows and macOS, do): "
                              "loaded as a layer, it shows the files' extents only, not their points.")
        return keys[0]
    ext = _suffix(path)
    feedback.pushInfo(f"{layer_name}: written to {path}. Not loaded: this QGIS has no point-cloud provider "
                      f"that opens {ext} files (QGIS builds with PDAL, as on Windows and macOS, do); "
                      "open it there or in CloudCompare.")
    if _temporary(value, path, context):
        feedback.pushWarning(f"{layer_name}: {path} is a temporary file: QGIS deletes it when it closes. "
                             "To keep it, give the output a file name (instead of [Save to temporary file]) "
                             "and run again, or copy the file elsewhere before closing QGIS.")
    return None


def _suffix(name):
    """A point-cloud file's suffix as the providers tell formats apart: ``.copc.laz`` or the last."""
    return ".copc.laz" if name.lower().endswith(".copc.laz") else os.path.splitext(name)[1].lower()


def _members_not_opened(path, patterns=None):
    """The extensions of a written .vpc's files (in the folder beside it) no provider here opens."""
    if not path.lower().endswith(".vpc"):
        return []
    folder = os.path.splitext(path)[0]
    names = os.listdir(folder) if os.path.isdir(folder) else []
    exts = sorted({_suffix(n) for n in names})
    return [ext for ext in exts if ext in READ_SUFFIXES and not providers_opening("cloud" + ext, patterns)]


# -- the graphical modeler ------------------------------------------------------------------
#: output types that can carry a point cloud (``outputPointCloud``: QGIS >= 3.24)
_CLOUD_OUTPUT_TYPES = ("outputFile", "outputPointCloud")


def _filter_suffixes(file_filter):
    """The lower-case suffixes a Qt file filter names (``"LAZ (*.laz);;All (*)"`` -> {".laz"})."""
    suffixes = set()
    for group in (file_filter or "").split(";;"):
        inside = group[group.find("(") + 1:group.rfind(")")] if "(" in group else group
        suffixes.update(p.lower()[1:] for p in inside.split() if p.startswith("*.") and len(p) > 2)
    return suffixes


def is_point_cloud_output(algorithm, output):
    """True when a child algorithm's output can be a point cloud the filters read: a point-cloud
    layer output, or a file output whose destination names a point-cloud extension in its file
    filter (our classified clouds: .laz/.las/.vpc). A raster, a vector layer, an .npz model, an
    HTML report or a file of no declared point-cloud extension is not."""
    if output.type() == "outputPointCloud":
        return True
    if output.type() != "outputFile":
        return False
    destination = algorithm.parameterDefinition(output.name())
    file_filter = getattr(destination, "fileFilter", None)
    return bool(file_filter) and bool(_filter_suffixes(file_filter()) & set(READ_SUFFIXES))


def point_cloud_sources(model, child_id, parameter_types=("file",)):
    """What the modeler offers to a GroundSieve point-cloud input of the child ``child_id``: the
    model inputs of ``parameter_types`` (a file or folder input) and the outputs of the other
    children (not those depending on this one) that ``is_point_cloud_output`` accepts."""
    sources = []
    for source in model.availableSourcesForChild(child_id, list(parameter_types), list(_CLOUD_OUTPUT_TYPES), []):
        child_output = _child_output(model, source)
        if child_output is None or is_point_cloud_output(*child_output):
            sources.append(source)
    return sources


def _child_output(model, source):
    """(algorithm, output definition) of a child-output source; None for any other source."""
    if not source.outputChildId():
        return None
    algorithm = model.childAlgorithm(source.outputChildId()).algorithm()
    output = algorithm.outputDefinition(source.outputName()) if algorithm is not None else None
    return (algorithm, output) if output is not None else None


def keep_point_cloud_outputs(widget, model):
    """Remove from a modeler parameter widget's list of child outputs those that cannot be a point
    cloud; return the [child id, output name] removed. (QGIS's widget lists child outputs in a
    combo box whose items hold [child id, output name]; a widget built otherwise is left alone.)"""
    from qgis.PyQt.QtWidgets import QComboBox
    removed = []
    for combo in widget.findChildren(QComboBox):
        items = [combo.itemData(i) for i in range(combo.count())]
        if not items or not all(isinstance(d, list) and len(d) == 2 for d in items):
            continue
        for index in reversed(range(combo.count())):
            child, name = combo.itemData(index)
            algorithm = model.childAlgorithm(child).algorithm() if child in model.childAlgorithms() else None
            output = algorithm.outputDefinition(name) if algorithm is not None else None
            if output is None or not is_point_cloud_output(algorithm, output):
                combo.removeItem(index)
                removed.append([child, name])
    return removed


def offer_point_clouds_in_modeler(param, folders=False):
    """Give a point-cloud input (a file or point-cloud layer parameter) the widget below in
    Processing's dialogs; the parameter's type, name and value are unchanged. ``folders``: the
    input also takes a folder of LAS/LAZ files (a survey), and the algorithm dialog's file widget
    gets a button that picks one (QGIS's file parameter picks files or folders, never both)."""
    metadata = param.metadata()
    metadata["widget_wrapper"] = {"class": f"{__name__}.PointCloudInputWidget"}
    if folders:
        metadata["widget_wrapper"]["folders"] = True
    param.setMetadata(metadata)
    return param


def takes_folders(param):
    """Whether the input ``param`` takes a folder of LAS/LAZ files (offer_point_clouds_in_modeler's
    ``folders``)."""
    wrapper = param.metadata().get("widget_wrapper")
    return isinstance(wrapper, dict) and bool(wrapper.get("folders"))


class PointCloudInputWidget:
    """The ``widget_wrapper`` of the point-cloud inputs (Processing's WidgetWrapperFactory builds
    it with (parameter, dialog, row, col)). It returns QGIS's own widget for the dialog at hand,
    as Processing would without the metadata; in the modeler, that widget without the child
    outputs that cannot be a point cloud."""

    def __new__(cls, param, dialog, row=0, col=0, folders=False, **_options):
        from processing.gui.wrappers import DIALOG_STANDARD, WidgetWrapperFactory, dialogTypes
        from qgis.gui import QgsGui
        registry = QgsGui.processingGuiRegistry()
        kind = dialog.__class__.__name__
        if kind == "ModelerParametersDialog":
            wrapper = registry.createModelerParameterWidget(dialog.model, dialog.childId, param, dialog.context)
            if wrapper is not None:
                keep_point_cloud_outputs(wrapper, dialog.model)
        else:  # exactly what Processing does for a parameter without this metadata
            wrapper = registry.createParameterWidgetWrapper(param, dialogTypes.get(kind, DIALOG_STANDARD))
            if wrapper is not None and folders and kind == "AlgorithmDialog":
                add_folder_button(wrapper)
        if wrapper is None:
            return WidgetWrapperFactory.create_wrapper_from_class(param, dialog, row, col)
        wrapper.setDialog(dialog)
        return wrapper



def add_folder_button(wrapper):
    """Beside QGIS's own file widget of ``wrapper`` (the algorithm dialog's), a button that picks a
    folder of LAS/LAZ files: QGIS's file parameter picks files or folders, never both. The value,
    its checks and its signals stay QGIS's: the button only sets the widget's path. Processing's
    dialog (Python) calls ``createWrappedWidget``, which this wraps."""
    create = wrapper.createWrappedWidget

    def create_with_folder_button(context):
        widget = create(context)
        layout = widget.layout() if widget is not None else None
        if layout is None or not hasattr(widget, "setFilePath"):
            return widget  # not the file widget this was written for: QGIS's widget as it is
        from qgis.core import QgsApplication
        from qgis.PyQt.QtWidgets import QFileDialog, QToolButton
        button = QToolButton()
        button.setIcon(QgsApplication.getThemeIcon("/mIconFolderOpen.svg"))
        button.setToolTip("Choose a folder of LAS/LAZ files (a survey, filtered in tiles)")

        def choose_folder():
            start = widget.filePath()
            if start and os.path.isfile(start):
                start = os.path.dirname(start)
            folder = QFileDialog.getExistingDirectory(button, "Choose a folder of LAS/LAZ files", start or "")
            if folder:
                widget.setFilePath(folder)

        button.clicked.connect(choose_folder)
        layout.addWidget(button)
        return widget

    wrapper.createWrappedWidget = create_with_folder_button
    return wrapper
