"""groundsieve:hybrid — Ground filter (learned hybrid): morphological features, a Random Forest."""
from qgis.core import QgsProcessingParameterEnum, QgsProcessingParameterFile, QgsProcessingParameterNumber

from .base import COMMON_HELP, FILTER_PARAMETER_HELP, GroundFilterAlgorithm, dialog_help

Double = QgsProcessingParameterNumber.Type.Double


class HybridAlgorithm(GroundFilterAlgorithm):
    MODEL = "MODEL"
    SHIPPED = "SHIPPED"
    #: the SHIPPED enum's values (core: Hybrid.shipped_model) and labels, in that order
    SHIPPED_CHOICES = ("fast", "accurate")
    SHIPPED_LABELS = ("fast (SMRF surfaces)", "accurate (SMRF + PTD surfaces, about 2.4x the filtering time)")
    PROBABILITY = "PROBABILITY"
    PARAMETER_HELP = dict(
        FILTER_PARAMETER_HELP,
        MODEL="A model trained on the hybrid features by Train Random Forest classifier's defaults (.npz); empty = "
              "the shipped model chosen below. A model on other features is refused.",
        SHIPPED="fast (the default) or accurate (also the height above PTD's ground: lower error on the ISPRS "
                "samples, about 2.4x slower). Both learned airborne LiDAR; for UAV photogrammetry train your own.",
        PROBABILITY="A point is ground at this probability or more (0.5): higher for fewer objects in the ground, "
                    "lower for fewer ground points lost.")

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
<p><b>Shipped model</b> (used when no model file is given): both are trained on the ISPRS
filter-test samples 11, 21, 23, 31, 41, 51, 52 and 54 (their leave-one-sample-out errors are in
<a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>).
<i>fast</i> (the default): the features above. <i>accurate</i>: also the height of the point above
the surface of the ground points of progressive TIN densification (PTD, Axelsson 2000, at fixed
settings: 50 m seed cell, 30°, 1 m, offset 0.05 m) and that surface's slope; lower error on the
ISPRS samples, about 2.4x the fast model's filtering time (it runs PTD; less with reading and writing).
<b>Model file</b> (optional): a model trained on the hybrid features (.npz); empty = the shipped
model chosen above. A model trained on other features is refused.
<b>Ground probability threshold</b>: a point is ground when the forest gives it at least this
probability of being ground (0.5); raise it for fewer non-ground points in the ground, lower it for
fewer ground points lost.</p>
""" + COMMON_HELP)

    def initFilterParameters(self):  # noqa: N802
        self.addParameter(QgsProcessingParameterFile(
            self.MODEL, "Model file (empty = the shipped model)",
            behavior=QgsProcessingParameterFile.Behavior.File, fileFilter="Model (*.npz)", optional=True))
        self.addParameter(QgsProcessingParameterEnum(
            self.SHIPPED, "Shipped model (when no model file is given)", options=list(self.SHIPPED_LABELS),
            defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(
            self.PROBABILITY, "Ground probability threshold", type=Double, defaultValue=0.5,
            minValue=0.01, maxValue=0.99))

    def buildFilter(self, parameters, context, log=None):  # noqa: N802
        from ..core.learn.hybrid import Hybrid
        built = Hybrid(model_path=self.parameterAsFile(parameters, self.MODEL, context) or "",
                       ground_probability=self.parameterAsDouble(parameters, self.PROBABILITY, context),
                       shipped_model=self.SHIPPED_CHOICES[self.parameterAsEnum(parameters, self.SHIPPED, context)])
        if log is not None:
            model = built.model_path or f"the shipped {built.shipped_model} model"
            log(f"Learned hybrid: {model}, ground at a probability of {built.ground_probability:g} or more")
        return built
