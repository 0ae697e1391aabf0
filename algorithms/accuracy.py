"""groundsieve:accuracy — Check DTM accuracy against checkpoints (core/raster/accuracy.py): a
surveyor's vertical accuracy figures (RMSEz, bias, NVA and VVA under ASPRS Editions 1 and 2) of any
DTM raster, from a point layer of surveyed checkpoints."""
import dataclasses
import functools
import math
import os

from qgis.core import (QgsCoordinateTransform, QgsCsException, QgsFeature, QgsFeatureSink, QgsFields, QgsGeometry, QgsPoint, QgsPointXY, QgsProcessing, QgsProcessingAlgorithm,
                       QgsProcessingException, QgsProcessingOutputNumber, QgsProcessingParameterNumber,
                       QgsProcessingParameterDefinition, QgsProcessingParameterFeatureSink,
                       QgsProcessingParameterFeatureSource, QgsProcessingParameterField,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterRasterLayer,
                       QgsProcessingParameterString, QgsWkbTypes)
from qgis.PyQt.QtGui import QIcon

from .base import attribute_field, check_parameter_values, core_modules, dialog_help, sink_folder_problem
from .discovery import TAGS, Discoverable

_ICONS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "icons")


def _number(value):
    """An attribute value as a finite float, or None (NULL, text, NaN)."""
    if value is None or (hasattr(value, "isNull") and value.isNull()):
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def _text(value):
    """An attribute value as text ("" for NULL)."""
    if value is None or (hasattr(value, "isNull") and value.isNull()):
        return ""
    return str(value)


class AccuracyAlgorithm(Discoverable, QgsProcessingAlgorithm):
    DTM = "DTM"
    BAND = "BAND"
    CHECKPOINTS = "CHECKPOINTS"
    Z_FIELD = "Z_FIELD"
    ID_FIELD = "ID_FIELD"
    LAND_COVER_FIELD = "LAND_COVER_FIELD"
    LAND_COVER_MAP = "LAND_COVER_MAP"
    OUTPUT_HTML = "OUTPUT_HTML"
    OUTPUT = "OUTPUT"
    RMSEZ = "RMSEZ"
    MEAN = "MEAN"
    COUNT = "COUNT"
    SKIPPED = "SKIPPED"
    NVA95 = "NVA95"
    VVA95 = "VVA95"
    NVA_RMSEZ = "NVA_RMSEZ"
    VVA_RMSEZ = "VVA_RMSEZ"
    PARAMETER_HELP = {
        "DTM": "The DTM to check: any raster GDAL reads (this plugin's or another's).",
        "BAND": "The DTM's band holding the heights (1).",
        "CHECKPOINTS": "Surveyed checkpoints: a point layer, or the survey's text or CSV file as it is (its x and "
                       "y then in the DTM's CRS). Their heights must be in the DTM's vertical datum and unit.",
        "Z_FIELD": "The field of the checkpoints' heights; empty = the points' Z (or a text file's z column).",
        "ID_FIELD": "The field naming each checkpoint in the report; empty = the feature id (a file's id, name or "
                    "point column, else its line).",
        "LAND_COVER_FIELD": "NVA (non-vegetated) or VVA (vegetated) per checkpoint, for the figures per land cover; "
                            "other words are mapped in Land cover values.",
        "LAND_COVER_MAP": "The land-cover field's other words as NVA or VVA, e.g. road=NVA,grass=NVA,forest=VVA.",
        "OUTPUT_HTML": "The report: figures of ASPRS Editions 1 and 2, warnings, a histogram of dz and every "
                       "checkpoint; it opens in the results viewer.",
        "OUTPUT": "The checkpoints with their DTM height, dz = DTM - checkpoint, |dz|, sampling and outlier flag.",
    }

    def name(self):
        return "accuracy"

    def displayName(self):  # noqa: N802
        return "Check DTM accuracy against checkpoints"

    def group(self):
        return "Quality control"

    def groupId(self):  # noqa: N802
        return "qualitycontrol"

    def icon(self):
        return QIcon(os.path.join(_ICONS, "groundsieve.svg"))

    def tags(self):
        """Its own words (a DTM of any source, not only of point clouds) and the survey's sensors."""
        return list(TAGS[self.name()] + ("lidar", "uav", "drone", "photogrammetry"))

    def createInstance(self):  # noqa: N802
        return type(self)()

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>The vertical accuracy of a DTM (this plugin's or any raster GDAL reads) against
independently surveyed <b>checkpoints</b>, as a surveyor's QA under the ASPRS Positional Accuracy Standards
reports it.</p>
<p><b>dz = DTM - checkpoint z</b>: a positive mean error is a DTM lying too high. The DTM's height at a
checkpoint is interpolated bilinearly between the four cell centres around it; when one of them is nodata
or beyond the raster's edge, the value of the cell the checkpoint lies in is taken; when that cell is
nodata too, or the checkpoint lies outside the DTM, the checkpoint is skipped, counted and named.</p>
<p><b>Checkpoints</b>: a point layer; z from the points' Z, or from the <i>Checkpoint elevation field</i>.
Their x and y are reprojected to the DTM's CRS when the layer's CRS differs; <b>their heights are taken
as they are</b>: they must be in the DTM's vertical datum (geoid) and unit. A survey's <b>text or CSV
file</b> may be given as it is: its columns are found by their header (x/easting/e, y/northing/n,
z/elevation/height/h, id/name/point, class/landcover/cover; other names are given in the field
parameters), or are x y z, x y z class, id x y z [class] without one; its x and y are taken in the DTM's
CRS.</p>
<p><b>Land cover</b> (optional field): NVA (non-vegetated) or VVA (vegetated); the values NVA, VVA,
non-vegetated and vegetated are known, any other is mapped in <i>Land cover values</i>, e.g.
<code>road=NVA,grass=NVA,forest=VVA</code>. An empty value leaves a checkpoint in the overall figures only.</p>
<p><b>Figures</b> (all checkpoints used, and each land cover): count, mean error, standard deviation,
RMSEz, min, max. ASPRS Edition 1 (2014): NVA at 95 % confidence = 1.96 x RMSEz, VVA at 95 % = the 95th
percentile of |dz|. Edition 2 (2023) dropped the 95 % figures: NVA and VVA are each their RMSEz. Both
are reported, each named by its edition. A land cover with fewer than 20 checkpoints is warned about
(Edition 2 asks for 30); checkpoints with |dz| greater than 3 x their land cover's RMSEz are named as
outliers and kept in every figure.</p>
<p><b>Outputs</b>: an HTML report (it opens in the results viewer) with the figures, warnings, a
histogram and every residual; optionally the checkpoints as a layer with their DTM height, dz, |dz|,
sampling (bilinear, cell, outside, nodata) and outlier flag; and the numbers RMSEZ, MEAN, COUNT,
SKIPPED, NVA95, VVA95 (Edition 1), NVA_RMSEZ, VVA_RMSEZ (Edition 2), empty for a land cover without
checkpoints.</p>""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterRasterLayer(self.DTM, "DTM (raster of ground heights)"))
        # (a number, not a QgsProcessingParameterBand: QGIS 3.22 refused that one's default 1 when the DTM was
        # given as a path; the core names the bands the DTM has when the one asked for is not there)
        band = QgsProcessingParameterNumber(self.BAND, "DTM band", type=QgsProcessingParameterNumber.Type.Integer,
                                            defaultValue=1, minValue=1)
        band.setFlags(band.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
        self.addParameter(band)
        self.addParameter(QgsProcessingParameterFeatureSource(
            self.CHECKPOINTS, "Checkpoints (surveyed points)", types=[QgsProcessing.SourceType.TypeVectorPoint]))
        self.addParameter(QgsProcessingParameterField(
            self.Z_FIELD, "Checkpoint elevation field (empty = the points' Z)", parentLayerParameterName=self.CHECKPOINTS,
            # (any type: a CSV's columns are all text to QGIS, and a numeric list offered none of them; the
            # values are read as numbers, a text that is none is refused with the checkpoint's id)
            type=QgsProcessingParameterField.DataType.Any, optional=True))
        self.addParameter(QgsProcessingParameterField(
            self.ID_FIELD, "Checkpoint id field (empty = the feature id)", parentLayerParameterName=self.CHECKPOINTS,
            optional=True))
        self.addParameter(QgsProcessingParameterField(
            self.LAND_COVER_FIELD, "Land cover field (NVA / VVA, non-vegetated / vegetated)",
            parentLayerParameterName=self.CHECKPOINTS, optional=True))
        self.addParameter(QgsProcessingParameterString(
            self.LAND_COVER_MAP, "Land cover values (e.g. road=NVA,grass=NVA,forest=VVA)", defaultValue="",
            optional=True))
        self.addParameter(QgsProcessingParameterFileDestination(self.OUTPUT_HTML, "Accuracy report",
                                                                fileFilter="HTML (*.html)"))
        self.addParameter(QgsProcessingParameterFeatureSink(
            self.OUTPUT, "Checkpoints with their dz", type=QgsProcessing.SourceType.TypeVectorPoint, optional=True,
            createByDefault=True))
        for name, label in ((self.RMSEZ, "RMSEz of all checkpoints used"), (self.MEAN, "Mean error (DTM - checkpoint)"),
                            (self.COUNT, "Checkpoints used"), (self.SKIPPED, "Checkpoints skipped"),
                            (self.NVA95, "NVA at 95 % (ASPRS Edition 1: 1.96 x RMSEz)"),
                            (self.VVA95, "VVA at 95 % (ASPRS Edition 1: 95th percentile of |dz|)"),
                            (self.NVA_RMSEZ, "NVA (ASPRS Edition 2: RMSEz)"),
                            (self.VVA_RMSEZ, "VVA (ASPRS Edition 2: RMSEz)")):
            self.addOutput(QgsProcessingOutputNumber(name, label))

    def checkParameterValues(self, parameters, context):  # noqa: N802
        """QGIS's checks, said in the dialog's words (a band of 0 named by its label), and the fields named
        checked against the checkpoints' layer (a batch row or a model reused with another layer)."""
        source = self.parameterAsSource(parameters, self.CHECKPOINTS, context)
        if source is None and self.checkpointFile(parameters, context, source):
            # (a survey's text file QGIS opens as no layer, read by the core in the run: QGIS's own check
            # refused it as "not found")
            ok, message = True, ""
            for param in self.parameterDefinitions():
                if param.name() != self.CHECKPOINTS and not param.isDestination() and \
                        not param.checkValueIsAcceptable(parameters.get(param.name()), context):
                    ok, message = False, f"Incorrect parameter value for {param.description()}"
                    break
        else:
            ok, message = super().checkParameterValues(parameters, context)
        if ok and source is not None:
            missing = self.missingField(parameters, context, source)
            if missing:
                return False, missing
        return check_parameter_values(self, parameters, context, ok, message)

    def missingField(self, parameters, context, source):  # noqa: N802
        """What is wrong when a field parameter names no field of ``source`` (None when all are there): a
        field named in a batch table, a script or a model that another layer lacks ran into a KeyError."""
        names = source.fields().names()
        for name in (self.Z_FIELD, self.ID_FIELD, self.LAND_COVER_FIELD):
            field = self.parameterAsString(parameters, name, context) or ""
            if field and source.fields().lookupField(field) < 0:
                return (f"{self.label(name, short=True)}: the layer '{source.sourceName()}' has no field '{field}' "
                        f"(its fields: {', '.join(names) or 'none'})")
        return None

    def warn(self, feedback, text):
        """A warning of the run, in the log and in the report (a flood modeller's reprojection was in the log
        alone, which is not what goes into a model build report)."""
        feedback.pushWarning(text)
        self._warnings = getattr(self, "_warnings", []) + [text]

    def label(self, name, short=False):
        """The dialog's label of the parameter ``name``; ``short``: without its bracketed remark, as a message
        names it ("Checkpoints", not "Checkpoints (surveyed points)")."""
        text = self.parameterDefinition(name).description()
        return text.split(" (")[0] if short else text

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, _workflow = core_modules()
        self._warnings = []
        from ..core.io.checkpoints import land_cover_of, parse_land_cover_mapping
        from ..core.raster import accuracy
        layer = self.parameterAsRasterLayer(parameters, self.DTM, context)
        if layer is None:
            value = parameters.get(self.DTM)
            raise QgsProcessingException(f"{self.label(self.DTM)}: " + (
                f"'{value}' is not a raster GDAL reads" if isinstance(value, str) and value else "no raster layer given"))
        if layer.providerType() != "gdal":
            raise QgsProcessingException(f"{self.label(self.DTM)}: '{layer.name()}' is a {layer.providerType()} layer; "
                                         "give a raster file GDAL reads (e.g. a GeoTIFF)")
        dtm_path = layer.source()
        source = self.parameterAsSource(parameters, self.CHECKPOINTS, context)
        table = self.checkpointFile(parameters, context, source)
        if source is None and table is None:
            value = parameters.get(self.CHECKPOINTS)
            raise QgsProcessingException(f"{self.label(self.CHECKPOINTS)}: " + (
                f"'{value}' is no point layer QGIS opens" if isinstance(value, str) and value else "no point layer given"))
        if source is not None:
            missing = self.missingField(parameters, context, source)
            if missing:
                raise QgsProcessingException(missing)
        points_name = f"the file '{table}'" if table else f"the layer '{source.sourceName()}'"
        report = self.parameterAsFileOutput(parameters, self.OUTPUT_HTML, context)
        try:
            mapping = parse_land_cover_mapping(self.parameterAsString(parameters, self.LAND_COVER_MAP, context) or "")
            accuracy.check_accuracy_outputs([dtm_path], report)
            if parameters.get(self.OUTPUT):  # (its folder, before the work: a failed run leaves no report)
                why = sink_folder_problem(self, parameters, self.OUTPUT, context)
                if why:
                    raise QgsProcessingException(why)
            if table:
                x, y, z, ids, covers, geometries = self.readCheckpointFile(parameters, context, feedback, table,
                                                                           mapping)
            else:
                x, y, z, ids, covers, geometries = self.readCheckpoints(parameters, context, feedback, source, layer,
                                                                        mapping, land_cover_of, errors)
            result = accuracy.check_accuracy(
                dtm_path, x, y, z, ids=ids, land_cover=covers, band=self.parameterAsInt(parameters, self.BAND, context),
                name=f"DTM '{layer.name()}' ({dtm_path})", checkpoints_name=points_name)
            # the warnings of reading the layer (its reprojection, ...) in the report too
            result = dataclasses.replace(result, warnings=tuple(getattr(self, "_warnings", [])) + result.warnings)
            # the layer first: should QGIS fail to create it, no report is left behind (a surveyor)
            sink_id = self.writeResiduals(parameters, context, layer.crs() if table else source.sourceCrs(), result,
                                          geometries)
            accuracy.write_outputs(result, report)
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        for line in accuracy.summary_lines(result):
            feedback.pushInfo(line)
        for text in result.warnings[len(getattr(self, "_warnings", [])):]:  # (the layer's, said already)
            feedback.pushWarning(text)
        results = {self.OUTPUT_HTML: report, self.RMSEZ: result.overall.rmse, self.MEAN: result.overall.mean,
                   self.COUNT: result.count, self.SKIPPED: len(result.skipped),
                   self.NVA95: result.nva.ed1_95 if result.nva else None,
                   self.VVA95: result.vva.ed1_95 if result.vva else None,
                   self.NVA_RMSEZ: result.nva.rmse if result.nva else None,
                   self.VVA_RMSEZ: result.vva.rmse if result.vva else None}
        if sink_id is not None:
            results[self.OUTPUT] = sink_id
            from . import styles
            styles.style_when_loaded(context, sink_id, functools.partial(
                styles.style_residuals, rmse=result.overall.rmse if result.overall else None, unit=result.unit))
        return results

    def readCheckpoints(self, parameters, context, feedback, source, layer, mapping, land_cover_of,  # noqa: N802
                        errors):
        """The checkpoints' x, y (in the DTM's CRS), z, ids, land covers (None without a field) and
        their points as given (for the output layer), read from the layer; a value that cannot be used
        is refused naming the field and the feature."""
        z_field = self.parameterAsString(parameters, self.Z_FIELD, context) or ""
        id_field = self.parameterAsString(parameters, self.ID_FIELD, context) or ""
        cover_field = self.parameterAsString(parameters, self.LAND_COVER_FIELD, context) or ""
        label = self.label(self.CHECKPOINTS, short=True)
        if source.wkbType() == QgsWkbTypes.Type.NoGeometry:
            raise QgsProcessingException(  # (a CSV given as it is was first said to have no Z: a flood modeller)
                f"{label} '{source.sourceName()}': a table without geometries (a CSV opened without its coordinates?): "
                "add it as a delimited text layer with its X and Y fields, or give its text or CSV file")
        if not z_field and not QgsWkbTypes.hasZ(source.wkbType()):
            raise QgsProcessingException(f"{label} '{source.sourceName()}': the points have no Z; choose the field "
                                         f"holding their heights in '{self.label(self.Z_FIELD)}'")
        transform = self.transformTo(source, layer, context, feedback)
        x, y, z, ids, covers, geometries, empty, no_height = [], [], [], [], [], [], [], []
        total = max(source.featureCount(), 1)
        for k, feature in enumerate(source.getFeatures()):
            if feedback.isCanceled():
                raise QgsProcessingException("cancelled by the user")
            feedback.setProgress(90.0 * k / total)
            fid = _text(feature[id_field]) if id_field else str(feature.id())
            where = f"{label} '{source.sourceName()}', feature {feature.id()}" + (f" ('{fid}')" if id_field else "")
            geometry = feature.geometry()
            if geometry is None or geometry.isNull() or geometry.isEmpty():
                empty.append(fid)
                continue
            cover = ""
            if cover_field:
                try:
                    cover = land_cover_of(feature[cover_field], mapping)
                except errors.GroundSieveError as err:
                    raise QgsProcessingException(f"{where}, {self.label(self.LAND_COVER_FIELD, short=True)} "
                                                 f"'{cover_field}': {err} in '{self.label(self.LAND_COVER_MAP)}'") from err
            if z_field:
                height = _number(feature[z_field])
                if height is None:
                    value = _text(feature[z_field])
                    if not value:  # (a mark not observed: left out and named, as a point without a geometry)
                        no_height.append(fid)
                        continue
                    raise QgsProcessingException(f"{where}, {self.label(self.Z_FIELD, short=True)} '{z_field}': "
                                                 f"'{value}' is not a number")
            vertices = list(geometry.vertices())
            for part, vertex in enumerate(vertices, 1):
                height_here = height if z_field else vertex.z()
                if not math.isfinite(height_here):
                    raise QgsProcessingException(f"{where}: the point has no Z value; choose the field holding its "
                                                 f"height in '{self.label(self.Z_FIELD)}'")
                px, py = vertex.x(), vertex.y()
                if transform is not None:
                    try:
                        moved = transform.transform(QgsPointXY(px, py))
                    except QgsCsException as err:
                        raise QgsProcessingException(f"{where}: cannot be reprojected to the DTM's CRS ({err})") from err
                    px, py = moved.x(), moved.y()
                x.append(px)
                y.append(py)
                z.append(height_here)
                ids.append(fid if len(vertices) == 1 else f"{fid}.{part}")
                covers.append(cover)
                geometries.append((vertex.x(), vertex.y(), _text(feature[cover_field]) if cover_field else ""))
        if empty:
            self.warn(feedback, f"{len(empty)} checkpoint(s) without a geometry left out: {', '.join(empty[:12])}")
        if no_height:
            self.warn(feedback, f"{len(no_height)} checkpoint(s) with an empty (NULL) '{z_field}' left out: "
                                f"{', '.join(no_height[:12])}" + (" ..." if len(no_height) > 12 else ""))
        if not x and no_height:
            raise QgsProcessingException(f"{label} '{source.sourceName()}': every checkpoint's "
                                         f"{self.label(self.Z_FIELD, short=True)} '{z_field}' is empty (NULL): "
                                         "is it the field of their heights?")
        if not x:
            raise QgsProcessingException(
                f"{label} '{source.sourceName()}': holds no points" + (
                    f" ({len(empty)} feature(s), none with a geometry: a table such as a CSV opened without its "
                    "coordinates? Add it as a delimited text layer with its X and Y fields, or give its text or "
                    "CSV file)" if empty else ""))
        return x, y, z, ids, (covers if cover_field else None), geometries

    def checkpointFile(self, parameters, context, source):  # noqa: N802
        """The path of the checkpoints when they are a text or CSV file that is no point layer (a table
        without geometries, given as a path or added to the project as it is, or a file QGIS does not
        open), else None: a surveyor's export is read as the command line reads it (core/io/checkpoints.py),
        in the DTM's CRS."""
        from qgis.core import QgsProcessingFeatureSourceDefinition, QgsProcessingUtils
        from qgis.PyQt.QtCore import QUrl
        if source is not None and source.wkbType() != QgsWkbTypes.Type.NoGeometry:
            return None
        from qgis.core import QgsMapLayer
        value, subset = parameters.get(self.CHECKPOINTS), False
        if isinstance(value, QgsProcessingFeatureSourceDefinition):  # (selected features, a feature limit)
            subset = value.selectedFeaturesOnly or value.featureLimit >= 0 or \
                bool(getattr(value, "filterExpression", ""))  # (QGIS 3.32: a source's filter expression)
            value = value.source.staticValue()
        table = value if isinstance(value, QgsMapLayer) else None  # (a layer object: a script, the console)
        path = value if isinstance(value, str) else ""
        if source is not None and path and not os.path.isfile(path.split("|")[0]):
            table = QgsProcessingUtils.mapLayerFromString(path, context)  # (a layer of the project: its file)
        if table is not None and table.subsetString():  # (a layer's filter: the file has every row)
            subset = True
        if table is not None and table.providerType() == "ogr":
            path = table.source()
        elif table is not None and table.providerType() == "delimitedtext":
            path = QUrl(table.source()).toLocalFile()
        path = path.split("|")[0]
        if not path or not os.path.isfile(path):
            return None
        if subset:  # (the file is read whole: a selection of its table cannot be honoured)
            raise QgsProcessingException(
                f"{self.label(self.CHECKPOINTS, short=True)} '{path}': a table without geometries, of which only "
                "some rows are asked for (selected features, a filter or a number of them): its file is read whole. "
                "Add it as a delimited text layer with its X and Y fields to choose checkpoints, or leave the "
                "selection or filter off")
        from ..core.io.checkpoints import is_text_file
        try:
            with open(path, "rb") as f:
                return path if is_text_file(f.read(4096)) else None  # (a GeoPackage's table is no text file)
        except OSError:
            return path  # (the reader names what is wrong)

    def readCheckpointFile(self, parameters, context, feedback, path, mapping):  # noqa: N802
        """readCheckpoints' values from a text or CSV file: its columns found by their header words, or
        named by the field parameters; x and y taken in the DTM's CRS."""
        from ..core.io.checkpoints import ColumnsError, UnknownLandCover, read_checkpoints
        from ..core.raster.accuracy import empty_heights
        named = {column: self.parameterAsString(parameters, name, context) or ""
                 for column, name in (("z", self.Z_FIELD), ("id", self.ID_FIELD), ("land_cover", self.LAND_COVER_FIELD))}
        try:
            try:
                checkpoints = read_checkpoints(path, mapping=mapping, columns=named)
            except UnknownLandCover as err:
                if named["land_cover"] or mapping:  # (a map typed for it: its typo is said, as for a layer)
                    raise
                # (a "cover" column found by its header word, of words this check does not know, refused a run
                # whose land-cover field was left empty: a power user; the figures without it, and why)
                checkpoints = read_checkpoints(path, mapping=mapping, columns=named, land_cover=False)
                self.warn(feedback, f"the file's land-cover column is left out: {err}; map its words in "
                                    f"'{self.label(self.LAND_COVER_MAP)}' for the NVA and VVA figures")
        except ColumnsError as err:  # (x and y of other words, or no header: QGIS's delimited text layer names them)
            raise ColumnsError(f"{err}; or add the file as a delimited text layer with its X and Y fields and give "
                               "that layer") from None
        for text in empty_heights(checkpoints):
            self.warn(feedback, text)
        self.warn(feedback, f"{self.label(self.CHECKPOINTS, short=True)} '{path}': a text file without a CRS, read "
                            f"as x (easting), y (northing), z in the DTM's CRS, {len(checkpoints)} checkpoint(s); their "
                            "heights are taken as they are: they must be in the DTM's vertical datum (geoid) and unit")
        covers = checkpoints.land_cover
        return (checkpoints.x.tolist(), checkpoints.y.tolist(), checkpoints.z.tolist(), list(checkpoints.ids),
                list(covers) if covers is not None else None,
                [(float(px), float(py), covers[i] if covers is not None else "")
                 for i, (px, py) in enumerate(zip(checkpoints.x, checkpoints.y))])

    def transformTo(self, source, layer, context, feedback):  # noqa: N802
        """The transform of the checkpoints' x and y to the DTM's CRS (None when they share it, or when
        either has none: then the coordinates are taken as they are, with a warning)."""
        source_crs, dtm_crs = source.sourceCrs(), layer.crs()
        datum = ("their heights are taken as they are: they must be in the DTM's vertical datum (geoid) "
                 "and unit")
        if not source_crs.isValid() or not dtm_crs.isValid():
            self.warn(feedback, f"{'the checkpoints have' if not source_crs.isValid() else 'the DTM has'} no CRS: the "
                                 f"checkpoints' x and y are taken as in the DTM's CRS; {datum}")
            return None
        if source_crs == dtm_crs:
            feedback.pushInfo(f"Checkpoints and DTM in {dtm_crs.authid() or dtm_crs.description()}; {datum}.")
            return None
        self.warn(feedback, f"the checkpoints' x and y are reprojected from {source_crs.authid() or source_crs.description()} "
                             f"to the DTM's {dtm_crs.authid() or dtm_crs.description()}; {datum}")
        return QgsCoordinateTransform(source_crs, dtm_crs, context.transformContext())

    def writeResiduals(self, parameters, context, crs, result, geometries):  # noqa: N802
        """The checkpoints with their residuals as a PointZ layer in the checkpoints' CRS ``crs`` (z the
        checkpoint's height), skipped ones too (empty DTM height and dz); None when not asked for."""
        fields = QgsFields()
        # (the layer's own land-cover words beside NVA/VVA: a flood modeller's road/forest were lost)
        for name, kind in (("id", "String"), ("land_cover", "String"), ("cover_given", "String"), ("z_check", "Double"),
                           ("z_dtm", "Double"), ("dz", "Double"), ("abs_dz", "Double"), ("sampling", "String"),
                           ("outlier", "Int")):
            fields.append(attribute_field(name, kind))
        sink, sink_id = self.parameterAsSink(parameters, self.OUTPUT, context, fields, QgsWkbTypes.Type.PointZ, crs)
        if sink is None:
            return None
        outliers, used_all = result.outlier_mask(), result.used
        for i, (px, py, given) in enumerate(geometries):
            feature = QgsFeature(fields)
            feature.setGeometry(QgsGeometry(QgsPoint(px, py, float(result.z[i]))))
            used = bool(used_all[i])
            feature.setAttributes([result.ids[i], result.land_cover[i], given, float(result.z[i]),
                                   float(result.dtm_z[i]) if used else None, float(result.dz[i]) if used else None,
                                   abs(float(result.dz[i])) if used else None, result.status[i],
                                   int(bool(outliers[i]))])
            sink.addFeature(feature, QgsFeatureSink.Flag.FastInsert)
        return sink_id
