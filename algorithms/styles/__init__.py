"""Styles given to GroundSieve's layers when QGIS loads them at the end of a run: the EVC class
raster as a paletted layer with a legend (its classes named and coloured), the DTM as an
elevation ramp, the accuracy check's checkpoints by their dz. Applied by layer post-processors (QgsProcessingLayerPostProcessorInterface), which
run in the main thread once the layer is loaded; qgis_process loads nothing, so styles nothing."""
import collections
import functools

import numpy as np
from qgis.core import (Qgis, QgsColorRampShader, QgsPalettedRasterRenderer, QgsProcessingLayerPostProcessorInterface,
                       QgsRasterBandStats, QgsRasterLayer, QgsRasterShader, QgsSingleBandPseudoColorRenderer,
                       QgsStyle, QgsVectorLayer)
from qgis.PyQt.QtGui import QColor

#: the EVC filter's classes (Fan et al. 2023, Table 2): value, legend label, colour; the core's table
#: (core/filters/evc.py EVC_CLASSES, which names them in the class raster too), read when a layer is styled
def _evc_classes():
    from ...core.filters.evc import EVC_CLASSES
    return EVC_CLASSES


def style_evc_classes(layer):
    """A paletted renderer with the three EVC classes named and coloured (nodata stays empty)."""
    classes = [QgsPalettedRasterRenderer.Class(value, QColor(colour), label) for value, label, colour in _evc_classes()]
    layer.setRenderer(QgsPalettedRasterRenderer(layer.dataProvider(), 1, classes))
    layer.triggerRepaint()


def style_evc_values(layer, threshold):
    """The EVC raster in the three intervals that make the classes (Fan et al. 2023, Table 2):
    EVC <= 0, 0 < EVC <= threshold, EVC > threshold, coloured and labelled as the class raster. A
    stretch over the values would show grey: dividing by near-zero mean differences makes a few
    values of +-1e4 or more where most lie within a few units."""
    colours = {label: colour for _value, label, colour in _evc_classes()}
    items = [QgsColorRampShader.ColorRampItem(0.0, QColor(colours["Vegetation area"]),
                                              "EVC <= 0: vegetation area"),
             QgsColorRampShader.ColorRampItem(threshold, QColor(colours["Ground"]),
                                              f"0 < EVC <= {threshold:g}: ground"),
             QgsColorRampShader.ColorRampItem(float("inf"), QColor(colours["Vegetation boundary"]),
                                              f"EVC > {threshold:g}: vegetation boundary")]
    function = QgsColorRampShader(-abs(threshold), 2 * abs(threshold))
    function.setColorRampType(QgsColorRampShader.Type.Discrete)
    function.setColorRampItemList(items)
    shader = QgsRasterShader()
    shader.setRasterShaderFunction(function)
    layer.setRenderer(QgsSingleBandPseudoColorRenderer(layer.dataProvider(), 1, shader))
    layer.triggerRepaint()


def style_dtm(layer):
    """An elevation ramp (QGIS's "Spectral", low blue to high red) stretched over the band's
    minimum and maximum, five classes interpolated: a DTM reads as terrain, not as grey."""
    provider = layer.dataProvider()
    if hasattr(Qgis, "RasterBandStatistic"):
        # QGIS 3.40: every call giving the statistics wanted warns as deprecated, the default (all) does not
        stats = provider.bandStatistics(1)
    else:
        stats = provider.bandStatistics(1, QgsRasterBandStats.Min | QgsRasterBandStats.Max)
    if not stats.maximumValue > stats.minimumValue:
        return  # an empty or flat DTM: QGIS's default grey is as good
    ramp = QgsStyle.defaultStyle().colorRamp("Spectral")
    if ramp is None:
        return
    ramp.invert()
    shader_function = QgsColorRampShader(stats.minimumValue, stats.maximumValue, ramp)
    shader_function.classifyColorRamp(5, -1)
    shader = QgsRasterShader()
    shader.setRasterShaderFunction(shader_function)
    layer.setRenderer(QgsSingleBandPseudoColorRenderer(provider, 1, shader))
    layer.triggerRepaint()


#: the residual layer's classes of dz in units of the RMSEz, blue (the DTM too low) to red (too high), the two
#: nearest 0 saturated enough to show on a grey hillshade (a power user: near white there)
DZ_CLASSES = ((-np.inf, -2.0, "#2166ac"), (-2.0, -1.0, "#4393c3"), (-1.0, 0.0, "#92c5de"),
              (0.0, 1.0, "#f4a582"), (1.0, 2.0, "#d6604d"), (2.0, np.inf, "#b2182b"))


def style_residuals(layer, rmse, unit="m"):
    """The accuracy check's checkpoints coloured by dz (DTM - checkpoint) in six classes of +-1 and +-2
    RMSEz around 0, blue where the DTM lies too low, red where too high; a layer with a plain symbol
    of a random colour told nothing (a QGIS plugin reviewer). Skipped checkpoints (no dz) stay grey."""
    from qgis.core import QgsRuleBasedRenderer, QgsSymbol
    if not (rmse and np.isfinite(rmse)):
        return
    unit = f" {unit}" if unit else ""
    root = QgsRuleBasedRenderer.Rule(None)

    def add(colour, expression, label):
        symbol = QgsSymbol.defaultSymbol(layer.geometryType())
        symbol.setColor(QColor(colour))
        root.appendChild(QgsRuleBasedRenderer.Rule(symbol, 0, 0, expression, label))

    for low, high, colour in DZ_CLASSES:
        lo, hi = low * rmse, high * rmse
        if not np.isfinite(low):
            add(colour, f'"dz" < {hi!r}', f"dz < {hi:+.3f}{unit}")
        elif not np.isfinite(high):
            add(colour, f'"dz" >= {lo!r}', f"dz > {lo:+.3f}{unit}")
        else:
            add(colour, f'"dz" >= {lo!r} AND "dz" < {hi!r}', f"{lo:+.3f} to {hi:+.3f}{unit}")
    # (a graduated renderer draws no point without a value: the skipped checkpoints vanished from the map)
    add("#9a9a9a", '"dz" IS NULL', "skipped (outside the DTM or on nodata)")
    layer.setRenderer(QgsRuleBasedRenderer(root))
    layer.triggerRepaint()


class _Styler(QgsProcessingLayerPostProcessorInterface):
    def __init__(self, apply):
        super().__init__()
        self._apply = apply

    def postProcessLayer(self, layer, context, feedback):  # noqa: N802
        if isinstance(layer, (QgsRasterLayer, QgsVectorLayer)) and layer.isValid():
            self._apply(layer)


#: the styles (functions of the loaded layer) the algorithms name
DTM_STYLE = style_dtm
EVC_CLASS_STYLE = style_evc_classes


def evc_value_style(threshold):
    """The style of an EVC raster made with ``threshold``."""
    return functools.partial(style_evc_values, threshold=float(threshold))


#: the post-processors given to QGIS, held here too: QGIS takes each one's ownership and deletes
#: it after its layer loaded (so one instance serves one run), and a Python post-processor must
#: stay alive on the Python side until then (the last ones are enough: a run loads its layers
#: as it ends)
_GIVEN = collections.deque(maxlen=64)


def style_when_loaded(context, path, style):
    """Give the layer ``path`` (a raster's path, a sink's id) the ``style`` (a function of the loaded layer) if this run loads it
    when it ends (the dialog, the modeler with 'open output file'); nothing otherwise. A new
    post-processor each time: QGIS deletes the one it was given once it has run."""
    if style is not None and path and context.willLoadLayerOnCompletion(path):
        styler = _Styler(style)
        _GIVEN.append(styler)
        context.layerToLoadOnCompletionDetails(path).setPostProcessor(styler)
