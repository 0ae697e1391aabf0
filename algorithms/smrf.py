"""groundsieve:smrf — Ground filter (SMRF, Pingel, Clarke & McBride 2013)."""
from qgis.core import QgsProcessingParameterBoolean, QgsProcessingParameterNumber

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help

Double = QgsProcessingParameterNumber.Type.Double


class SMRFAlgorithm(GroundFilterAlgorithm):
    CELL = "CELL"
    SLOPE = "SLOPE"
    WINDOW = "WINDOW"
    THRESHOLD = "THRESHOLD"
    SCALAR = "SCALAR"
    LOW_OUTLIER_FILL = "LOW_OUTLIER_FILL"

    def name(self):
        return "smrf"

    def displayName(self):  # noqa: N802
        return "Ground filter (SMRF)"

    def iconName(self):  # noqa: N802
        return "smrf.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points with the Simple Morphological Filter
(Pingel, Clarke &amp; McBride 2013, ISPRS J. Photogramm. 77:21-30), as the paper describes it:
a minimum-elevation grid with empty cells filled by harmonic inpainting; low outliers found on the
inverted surface; a progressive opening with disks growing one cell at a time up to the maximum
window, a cell being an object when it drops by more than slope x radius; a provisional ground
surface interpolated over the object cells; finally each point is ground when it lies within
<i>elevation threshold + elevation scalar x local slope</i> of that surface (cubic interpolation).</p>
<h3>Parameters</h3>
<p><b>Cell size (m)</b>: grid cell of the minimum surface (1 m in the paper).
<b>Slope (rise/run)</b>: terrain slope the filter tolerates (0.15 = 15 %).
<b>Maximum window radius (m)</b>: about the radius of the largest building (18 m).
<b>Elevation threshold (m)</b> and <b>elevation scalar</b>: the final point test (0.5 m, 1.25).
<b>Remove low outliers before the opening</b>: low-outlier cells are refilled from their
neighbours before the progressive opening (on by default; Pingel's Python code leaves it off;
it lowers the mean ISPRS total error with the single parameter set, see <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>).</p>
""" + COMMON_HELP)

    def initFilterParameters(self):  # noqa: N802
        self.addParameter(QgsProcessingParameterNumber(
            self.CELL, "Cell size (m)", type=Double, defaultValue=1.0, minValue=0.01))
        self.addParameter(QgsProcessingParameterNumber(
            self.SLOPE, "Slope (rise/run)", type=Double, defaultValue=0.15, minValue=0.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.WINDOW, "Maximum window radius (m)", type=Double, defaultValue=18.0, minValue=0.01))
        self.addParameter(QgsProcessingParameterNumber(
            self.THRESHOLD, "Elevation threshold (m)", type=Double, defaultValue=0.5, minValue=0.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.SCALAR, "Elevation scalar (m per unit slope)", type=Double, defaultValue=1.25, minValue=0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.LOW_OUTLIER_FILL, "Remove low outliers before the opening", defaultValue=True))

    def buildFilter(self, parameters, context):  # noqa: N802
        from ..core.filters.smrf import SMRF
        return SMRF(cell_size_m=self.parameterAsDouble(parameters, self.CELL, context),
                    slope=self.parameterAsDouble(parameters, self.SLOPE, context),
                    window_m=self.parameterAsDouble(parameters, self.WINDOW, context),
                    elevation_threshold_m=self.parameterAsDouble(parameters, self.THRESHOLD, context),
                    elevation_scalar=self.parameterAsDouble(parameters, self.SCALAR, context),
                    low_outlier_fill=self.parameterAsBoolean(parameters, self.LOW_OUTLIER_FILL, context))
