"""groundsieve:evc — Ground filter (multiscale EVC), Fan et al. 2023; and
groundsieve:evcrasters — the same with its intermediate rasters."""
from qgis.core import QgsProcessingParameterRasterDestination

from .base import COMMON_HELP, FILTER_PARAMETER_HELP, GroundFilterAlgorithm, dialog_help


EVC_HELP = """<p>The multiscale elevation-variation-coefficient filter of Fan et al. (2023), made for
UAV photogrammetry over low vegetation: virtual grids of mean elevation at a small and a large scale;
their difference on the small grid; in a square window of <i>Neighbourhood radius</i> cells,
EVC = standard deviation / mean of the difference; then the paper's Table 2: ground where
0 &lt; EVC &lt;= <i>Threshold</i>, vegetation where EVC &lt;= 0 (vegetation area) or EVC &gt; threshold
(vegetation boundary). Points take the class of their small cell. <i>Natural breaks</i> picks the
threshold automatically (Jenks, as the paper did).</p>
<p><b>Which settings?</b> The paper's method, kept faithful: on generated photogrammetry-like
clouds its defaults misclassify 40-44 % of the points, its shipped preset
<i>uav-photogrammetry-evc.json</i> (field <i>Preset</i>) 22-28 %, and <b>SMRF with the preset
uav-photogrammetry-smrf.json</b> 4.5-5.5 %, and 1.8-2.0 % where there are buildings and trees too
(the README's "Which ground filter?" table). On your own data, tune either on a
labelled patch (<i>Tune a ground filter</i>).</p>
<p><b>Empty small cells</b> (normal below about 25 points/m² at 0.2 m) are left out of every window;
where a window holds fewer than <i>Minimum non-empty cells</i>, it grows up to <i>Maximum radius</i>.
A cell still without an EVC is not ground.</p>
<p><b>Difference</b>: the paper's vegetation values are negative, i.e. large minus small (default).
<b>Ground offset</b> (0 = paper): added to the mean difference before the ratio, which is otherwise
unstable on open ground far from vegetation (see <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a> for what each measured).
<b>Point tolerance around the ground cells</b> (0 = paper, where a point takes its cell's class): a point of a
ground cell is ground only within this height of its window's ground level, so that an image-matching blunder
floating above the surface or sunk below it makes no spike or pit in the DTM (the EVC preset: 0.3 m).</p>
"""


class EVCAlgorithm(GroundFilterAlgorithm):
    FILTER = "evc"  # parameters: core/engine/parameters.py
    SMALL_SCALE = "SMALL_SCALE"
    LARGE_SCALE = "LARGE_SCALE"
    RADIUS = "RADIUS"
    THRESHOLD = "THRESHOLD"
    AUTO_THRESHOLD = "AUTO_THRESHOLD"
    DIFFERENCE = "DIFFERENCE"
    GROUND_OFFSET = "GROUND_OFFSET"
    POINT_TOLERANCE = "POINT_TOLERANCE"
    MIN_CELLS = "MIN_CELLS"
    MAX_RADIUS = "MAX_RADIUS"

    def name(self):
        return "evc"

    def displayName(self):  # noqa: N802
        return "Ground filter (multiscale EVC)"

    def iconName(self):  # noqa: N802
        return "evc.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help(EVC_HELP + COMMON_HELP)


    def completeFilterArguments(self, kwargs):  # noqa: N802
        kwargs["max_radius"] = max(kwargs["radius"], kwargs["max_radius"])  # a window grows from the radius
        return kwargs

class EVCRastersAlgorithm(EVCAlgorithm):
    SMALL_MEAN = "SMALL_MEAN"
    LARGE_MEAN = "LARGE_MEAN"
    DIFFERENCE_RASTER = "DIFFERENCE_RASTER"
    EVC_RASTER = "EVC_RASTER"
    CLASS_RASTER = "CLASS_RASTER"

    #: output name -> the core's raster (core/filters/evc.py EVC_RASTERS: label, f(EVCResult) -> (values, grid[,
    #: format])), read when needed: the plugin loads without the core's packages
    RASTER_KEYS = {SMALL_MEAN: "small_mean", LARGE_MEAN: "large_mean", DIFFERENCE_RASTER: "difference",
                   EVC_RASTER: "evc", CLASS_RASTER: "classes"}

    @property
    def RASTERS(self):  # noqa: N802
        from ..core.filters.evc import EVC_RASTERS
        return {name: EVC_RASTERS[key] for name, key in self.RASTER_KEYS.items()}

    PARAMETER_HELP = dict(
        FILTER_PARAMETER_HELP,
        SMALL_MEAN="The mean elevation of each small-scale cell (GeoTIFF, the cloud's CRS).",
        LARGE_MEAN="The mean elevation of each large-scale cell.",
        DIFFERENCE_RASTER="Each small cell's elevation against the large cell holding its centre (the paper's sign: "
                          "large minus small unless Difference says otherwise).",
        EVC_RASTER="The elevation variation coefficient of each small cell's window (standard deviation / mean of "
                   "the difference), styled by the three intervals of the classes.",
        CLASS_RASTER="1 ground, 2 vegetation area, 3 vegetation boundary (nodata where the small cell is empty), "
                     "loaded with these names and colours.")

    def name(self):
        return "evcrasters"

    def displayName(self):  # noqa: N802
        return "EVC raster workflow (multiscale EVC with its rasters)"

    def group(self):
        return "Raster workflows"

    def groupId(self):  # noqa: N802
        return "rasterworkflows"

    def shortHelpString(self):  # noqa: N802
        return dialog_help(EVC_HELP + """<p>This workflow also writes the filter's intermediate grids as GeoTIFF with
the cloud's CRS: the small- and large-scale mean elevations, the elevation difference, the EVC and
the class raster (1 ground, 2 vegetation area, 3 vegetation boundary, nodata where the small cell
is empty; loaded with these names and colours in its legend), to inspect and to reuse in the modeler.
Each is off by default: tick the ones you want in the dialog, or name them in <code>qgis_process</code>
(<code>--EVC_RASTER=evc.tif --CLASS_RASTER=classes.tif</code> ...).</p>
<p>Reading the class raster: the method compares a fine and a coarse mean surface, so terrain the coarse
cell does not resolve (terrace edges, ditches, banks, slopes that change within a large cell) shows as
bands of vegetation area or boundary along it, in steps of the large cell: they are terrain (a UAV
photogrammetry reviewer's generated scene: most of the ground EVC lost lay along its two breaklines).</p>""" + COMMON_HELP)

    def addExtraOutputParameters(self):  # noqa: N802
        for name, (label, _make) in self.RASTERS.items():
            # Optional and off by default, as every intermediate output of the filters: ticked in
            # the dialog, named in qgis_process (e.g. --EVC_RASTER=evc.tif) or in the modeler.
            self.addParameter(QgsProcessingParameterRasterDestination(
                name, label, optional=True, createByDefault=False))

    def rasterStyles(self, run=None):  # noqa: N802
        from .styles import EVC_CLASS_STYLE, evc_value_style
        out = {self.CLASS_RASTER: EVC_CLASS_STYLE}
        detail = getattr(run, "detail", None)  # an EVCResult (a whole-cloud run), with its threshold
        if detail is not None:
            out[self.EVC_RASTER] = evc_value_style(detail.threshold)
        return out

    def rasterOutputs(self, parameters, context):  # noqa: N802
        return {name: (self.parameterAsOutputLayer(parameters, name, context),
                       lambda run, make=make: make(run.detail))
                for name, (_label, make) in self.RASTERS.items()}

