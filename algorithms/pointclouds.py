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
  was written and why it is not loaded.
"""
import fnmatch
import os

from qgis.core import (QgsProcessingContext, QgsProcessingException, QgsProcessingParameterDefinition,
                       QgsProcessingUtils, QgsProviderMetadata, QgsProviderRegistry)

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
    algorithm.addParameter(param)
    return True


def input_path(algorithm, parameters, context, file_name, layer_name):
    """The path of the input cloud: the loaded layer's file when a layer is given, else the file
    parameter's value; a layer that is not a local file the filters read is refused by its label."""
    definition = algorithm.parameterDefinition(layer_name)
    if definition is not None and parameters.get(layer_name):
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


def make_input_optional(param):
    """The file input is optional where a loaded layer may replace it."""
    param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagOptional)


# -- output ---------------------------------------------------------------------------------
def load_or_log(context, feedback, path, layer_name, output_name):
    """Load the point cloud written at ``path`` when the run ends, where a provider of this QGIS
    opens it; else say in the log where it is and why it is not loaded. Returns the provider key
    used, or None. (Under qgis_process nothing is loaded either way.)"""
    keys = providers_opening(path)
    if keys:
        details = QgsProcessingContext.LayerDetails(layer_name, context.project(), output_name,
                                                    QgsProcessingUtils.LayerHint.PointCloud)
        context.addLayerToLoadOnCompletion(path, details)
        return keys[0]
    ext = ".copc.laz" if path.lower().endswith(".copc.laz") else os.path.splitext(path)[1].lower()
    feedback.pushInfo(f"{layer_name}: written to {path}. Not loaded: this QGIS has no point-cloud provider "
                      f"that opens {ext} files (QGIS builds with PDAL, as on Windows and macOS, do); "
                      "open it there, in CloudCompare, or use the DTM.")
    return None
