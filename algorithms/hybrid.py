"""groundsieve:hybrid — Ground filter (learned hybrid): morphological features, a Random Forest."""
from qgis.core import QgsProcessingParameterFile, QgsProcessingParameterNumber

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help

Double = QgsProcessingParameterNumber.Type.Double


class HybridAlgorithm(GroundFilterAlgorithm):
    MODEL = "MODEL"
    PROBABILITY = "PROBABILITY"

    def name(self):
        return "hybrid"

    def displayName(self):  # noqa: N802
        return "Ground filter (learned hybrid)"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points with a Random Forest that sees where the
ground roughly is: for every point, its height above SMRF's provisional ground surface (Pingel et al.
2013, default parameters) and above the minimum surface opened with windows of 2, 6 and 18 m, and the
slope and curvature of that ground surface. Only x, y, z are needed. The features are lengths in
metres and do not depend on the point density, so one model serves sparse airborne and dense UAV
clouds.</p>
<h3>Parameters</h3>
<p><b>Model file</b> (optional): a model trained on the hybrid features (.npz); empty = the model
shipped with the plugin, trained on the ISPRS filter-test samples 11, 21, 23, 31, 41, 51, 52 and 54
(its leave-one-sample-out errors are in <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>). A model trained on other features is
refused.
<b>Ground probability threshold</b>: a point is ground when the forest gives it at least this
probability of being ground (0.5); raise it for fewer non-ground points in the ground, lower it for
fewer ground points lost.</p>
""" + COMMON_HELP)

    def initFilterParameters(self):  # noqa: N802
        self.addParameter(QgsProcessingParameterFile(
            self.MODEL, "Model file (empty = the shipped model)",
            behavior=QgsProcessingParameterFile.Behavior.File, fileFilter="Model (*.npz)", optional=True))
        self.addParameter(QgsProcessingParameterNumber(
            self.PROBABILITY, "Ground probability threshold", type=Double, defaultValue=0.5,
            minValue=0.01, maxValue=0.99))

    def buildFilter(self, parameters, context):  # noqa: N802
        from ..core.learn.hybrid import Hybrid
        return Hybrid(model_path=self.parameterAsFile(parameters, self.MODEL, context) or "",
                      ground_probability=self.parameterAsDouble(parameters, self.PROBABILITY, context))
