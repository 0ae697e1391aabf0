"""groundsieve:dtm — DTM from classified points: the ground an earlier classification made (a vendor's
class 2, an earlier run's, a hand-edited one) as a DTM, without filtering it again."""
from qgis.core import (QgsProcessingException, QgsProcessingOutputNumber, QgsProcessingParameterRasterDestination,
                       QgsProcessingParameterString)

from .base import (FILTER_PARAMETER_HELP, INPUT_FILTER, GroundFilterAlgorithm, core_modules, dialog_help, dtm_cell_set,
                   dtm_extent_value, feedback_callables, kernels_compiled)


class DTMFromClassesAlgorithm(GroundFilterAlgorithm):
    """A ground filter's input, tiles and DTM options, with the input's classes as the ground: the
    engine makes the DTM (whole, or in buffered tiles for a survey) as it makes any filter's."""
    CLASSES = "CLASSES"
    PARAMETER_HELP = dict(
        FILTER_PARAMETER_HELP,
        CLASSES="The classes whose points make the DTM, as the cloud has them (2 = ground; e.g. 2,9 with water, "
                "2,9,11 with a road surface). Nothing is filtered again.",
        IGNORE_CLASSES="Points of these classes stay out of the DTM and of its extent (7 and 18, noise, by default).",
        INPUT="A classified LAS/LAZ (1.0-1.4), a folder of them or a .vpc (a survey, in buffered tiles); a text file "
              "carries no classes. Only read, never changed.",
        TILE_BUFFER="The margin read around each tile; -1 = 40 m: gaps in the ground up to this wide are bridged "
                    "as a run of the whole cloud bridges them.",
        DTM="The DTM: a cloud-optimised GeoTIFF of the triangulation of the ground classes' points.")
    #: the DTM output is DTM, as in every ground filter and rfclassify: a model swaps a filter for this
    #: algorithm without rewiring (a QGIS power user)
    GROUND_COUNT = "GROUND_COUNT"
    POINT_COUNT = "POINT_COUNT"

    def name(self):
        return "dtm"

    def displayName(self):  # noqa: N802
        return "DTM from classified points"

    def group(self):
        return "Raster workflows"

    def groupId(self):  # noqa: N802
        return "rasterworkflows"

    def iconName(self):  # noqa: N802
        return "groundsieve.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Makes a DTM from the points an earlier classification made ground: a vendor's
delivery, an earlier run of a ground filter, a cloud edited by hand. Nothing is filtered again: the
points of the <i>Ground classes</i> (2 by default) are interpolated linearly on their Delaunay
triangulation, as the ground filters' DTMs are, and every other point stays out of it. The run says how
many points of each other class it left out.</p>
<h3>Parameters</h3>
<p><b>Input point cloud</b>: LAS 1.0-1.4 or LAZ, a folder of them or a .vpc (a survey, run in buffered
tiles). Only read, never changed. <b>Ground classes</b>: the classes of the DTM's points: 2 (ground);
add 9 (water) for a flood model's water surface, e.g. <code>2,9</code>, and the classes the vendor kept apart
from the ground that are terrain too: 8 (model key points), 10 (rail), 11 (road surface), e.g.
<code>2,9,11</code> (an embankment's crest classed 11 is otherwise bridged, lower). A class that is no terrain
(6 building, 17 bridge deck, ...) is warned about.
<b>Ignored classes</b> (default <code>7,18</code>, noise): left out of the DTM's extent too, so that a
stray noise point far away does not stretch the grid; withheld points always are.
<b>DTM cell size (m)</b>: in the unit of the cloud's CRS when you set it; the default 1 m is 3 ft
for a cloud in feet. <b>Fill cells outside the ground hull</b>: nearest value instead of nodata (-9999).
<b>Leave cells farther than this from any ground point empty</b> (advanced, 0 = no limit): data gaps
are otherwise bridged by the triangulation. <i>DTM extent</i> (advanced): the DTM covers it, widened to whole cells on multiples of the cell size, nodata
beyond the points' own DTM: two epochs' DTMs or a model's domain on one grid of one size. QGIS writes an
extent xmin,xmax,ymin,ymax (an extent in another CRS is reprojected to the cloud's); one that misses the
points, or is thousands of times their area where its numbers in the other order fit them, is refused.
On a survey, only the tiles making the extent's cells are read and triangulated, and only the files within
their reach are read: a model domain's DTM from a county's survey takes the domain's time (its point and
ground counts are then those of the tiles it read).</p>
<h3>Surveys</h3>
<p>A folder, a .vpc, a tile size or a cloud beyond the memory budget runs in square tiles, each
triangulated with a buffer of 40 m around it (or <i>Tile buffer</i>): a gap in the ground up to that
wide (a building, a pond) is bridged as one triangulation of the whole survey bridges it, so the DTM
shows no tile lines; set a larger buffer for wider gaps. The DTM is one seamless cloud-optimised
GeoTIFF.</p>
<p>A cloud with no point of the ground classes is refused with the classes it holds: filter it first
with one of the ground filters.</p>""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addInputParameters()
        # an ISPRS text file has no classes: not offered (the ground filters' input takes one)
        param = self.parameterDefinition(self.INPUT)
        param.setDescription(param.description().replace(", or ISPRS .txt)", ", or a .vpc)").replace(
            "a folder of them, a .vpc, or a .vpc)", "a folder of them, or a .vpc)"))
        param.setFileFilter(INPUT_FILTER.replace(";;ISPRS text (*.txt)", ""))
        self.addParameter(QgsProcessingParameterString(
            self.CLASSES, "Ground classes: the classes of the DTM's points (e.g. 2, or 2,9 with water)",
            defaultValue="2"))
        self.addParameter(QgsProcessingParameterString(
            self.IGNORE_CLASSES, "Ignored classes: out of the DTM and of its extent (e.g. 7,18)",
            defaultValue="7,18", optional=True))
        self.addTileParameters()
        buffer = self.parameterDefinition(self.TILE_BUFFER)  # (its reach is a fixed 40 m)
        buffer.setDescription("Tile buffer (m; -1 = 40 m, gaps in the ground up to this wide are bridged)")
        self.addDtmParameters(dtm_classes=False)
        self.addParameter(QgsProcessingParameterRasterDestination(self.DTM, "DTM (ground surface)"))
        self.addOutput(QgsProcessingOutputNumber(self.GROUND_COUNT, "Ground points"))
        self.addOutput(QgsProcessingOutputNumber(self.POINT_COUNT, "Points read"))

    def buildFilter(self, parameters, context, log=None):  # noqa: N802
        """The "filter": the points of the ground classes (core/filters/classes.py)."""
        from ..core.filters.classes import ClassGround
        ground = ClassGround(self.parameterAsString(parameters, self.CLASSES, context) or "")
        if log is not None:
            log(f"Ground classes: {', '.join(str(c) for c in ground.classes)}.")
        return ground

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, workflow = core_modules(feedback=feedback, kernels_of=self.name())
        from . import pointclouds, styles
        input_path = pointclouds.input_path(self, parameters, context, self.INPUT, self.INPUT_LAYER)
        dtm_path = self.parameterAsOutputLayer(parameters, self.DTM, context)
        try:
            ground = self.buildFilter(parameters, context, feedback.pushInfo)
            # the input's classes are kept as they are (no classified copy is written): no point's class
            # is said to be replaced, and the classes left out of the DTM are named
            options = workflow.FilterOptions(ignore_classes=self.parameterAsString(parameters, self.IGNORE_CLASSES, context)
                                             or "",
                                             keep_existing_classes=True, tiling=self.tileOptions(parameters, context))
            dtm = workflow.DTMOptions(
                cell_size_m=self.parameterAsDouble(parameters, self.DTM_CELL, context),
                cell_set=dtm_cell_set(self, parameters, context, self.DTM_CELL),
                fill_outside_hull=self.parameterAsBoolean(parameters, self.DTM_FILL, context),
                max_distance_m=self.parameterAsDouble(parameters, self.DTM_MAX_DISTANCE, context),
                extent=dtm_extent_value(self, parameters, self.DTM_EXTENT, context, input_path, feedback))
            run = workflow.run_ground_filter(input_path, None, ground, options=options, dtm_path=dtm_path, dtm=dtm,
                                             **feedback_callables(feedback))
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        tiled = run.cloud is None
        if tiled and options.tiling.only != "":  # one file of the survey: its DTM's path
            dtm_path = run.dtm_path
        styles.style_when_loaded(context, dtm_path, styles.DTM_STYLE)
        kernels_compiled(self.name())
        return {self.DTM: dtm_path, self.GROUND_COUNT: run.ground_count,
                self.POINT_COUNT: run.point_count if tiled else len(run.cloud)}

    def checkParameterValues(self, parameters, context):  # noqa: N802
        """The ground and ignored classes' form, and that no class is both, in the dialog's words (a batch
        row found them wrong only at its run: a QGIS power user); then the ground filters' checks (the
        input, a cell of -1 or text)."""
        from ..core.errors import GroundSieveError
        from ..core.io.clouds import parse_classes
        label, ignored_label = (self.parameterDefinition(name).description().split(":")[0]
                                for name in (self.CLASSES, self.IGNORE_CLASSES))
        try:
            ground = parse_classes(self.parameterAsString(parameters, self.CLASSES, context) or "", what=label)
            if not ground:
                return False, f"{label}: name at least one class (2 is ground)"
            ignored = parse_classes(self.parameterAsString(parameters, self.IGNORE_CLASSES, context) or "",
                                    what=ignored_label)
        except GroundSieveError as err:
            return False, str(err)
        both = sorted(set(ground) & set(ignored))
        if both:
            return False, (f"{label} and {ignored_label} both name {', '.join(map(str, both))}: a class cannot make "
                           "the DTM and be left out of it")
        return super().checkParameterValues(parameters, context)
