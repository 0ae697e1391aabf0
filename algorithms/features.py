"""groundsieve:features — Compute point features (Matrone et al. 2024, Method 3: geometric
features of the local neighbourhood, written as LAS extra bytes)."""
import os

from qgis.core import (QgsProcessingAlgorithm, QgsProcessingException,
                       QgsProcessingOutputString, QgsProcessingParameterEnum,
                       QgsProcessingParameterFile, QgsProcessingParameterFileDestination,
                       QgsProcessingParameterNumber, QgsProcessingParameterString)
from qgis.PyQt.QtGui import QIcon

from . import pointclouds
from .base import core_modules, dialog_help, feedback_callables, kernels_compiled, warn_about_crs
from .discovery import Discoverable

_ICONS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "icons")
Double = QgsProcessingParameterNumber.Type.Double

#: The optional features of EXTRA: (core feature, label), in the order of the enum.
EXTRA_FEATURES = (
    ("linearity", "Linearity"),
    ("sphericity", "Sphericity"),
    ("omnivariance", "Omnivariance"),
    ("anisotropy", "Anisotropy"),
    ("eigenvalue_sum", "Sum of eigenvalues"),
    ("density", "Point density (points per m³ in the sphere)"),
    ("height_above_min", "Height above the lowest point in a vertical column (column radius)"),
)


class FeaturesAlgorithm(Discoverable, QgsProcessingAlgorithm):
    INPUT = "INPUT"
    VERTICALITY_RADIUS = "VERTICALITY_RADIUS"
    PLANARITY_RADIUS = "PLANARITY_RADIUS"
    EIGENENTROPY_RADIUS = "EIGENENTROPY_RADIUS"
    SURFACE_VARIATION_RADIUS = "SURFACE_VARIATION_RADIUS"
    EXTRA = "EXTRA"
    EXTRA_RADIUS = "EXTRA_RADIUS"
    COLUMN_RADIUS = "COLUMN_RADIUS"
    IGNORE_CLASSES = "IGNORE_CLASSES"
    OUTPUT = "OUTPUT"
    FEATURES = "FEATURES"
    PARAMETER_HELP = {
        "INPUT": "A LAS/LAZ file or an ISPRS text file; only read, never changed.",
        "VERTICALITY_RADIUS": "The sphere of verticality, 1 - |nz| of the normal (0.6 m, the paper's); 0 leaves it "
                              "out. Choose radii that hold at least a dozen points.",
        "PLANARITY_RADIUS": "The sphere of planarity, (e2 - e3) / e1 (0.6 m, the paper's); 0 leaves it out.",
        "EIGENENTROPY_RADIUS": "The sphere of eigenentropy, -sum e ln e (0.4 m, the paper's); 0 leaves it out.",
        "SURFACE_VARIATION_RADIUS": "The sphere of surface variation, e3 (0.6 m, the paper's); 0 leaves it out.",
        "EXTRA_RADIUS": "The sphere of the other features chosen (one pass over the points for all of them).",
        "COLUMN_RADIUS": "The horizontal radius of the column whose lowest point the height above the column "
                         "minimum is measured from.",
        "IGNORE_CLASSES": "Points of these classes are left out of every neighbourhood and get no value (7 and 18, "
                          "noise, by default), as Classify with Random Forest model computes them.",
        "OUTPUT": "A copy of the cloud with each feature as a float32 extra-bytes dimension.",
    }

    #: (parameter, core feature, label, default radius) of the paper's features.
    PAPER = (
        (VERTICALITY_RADIUS, "verticality", "Verticality radius (m)", 0.6),
        (PLANARITY_RADIUS, "planarity", "Planarity radius (m)", 0.6),
        (EIGENENTROPY_RADIUS, "eigenentropy", "Eigenentropy radius (m)", 0.4),
        (SURFACE_VARIATION_RADIUS, "surface_variation", "Surface variation radius (m)", 0.6),
    )

    def name(self):
        return "features"

    def displayName(self):  # noqa: N802
        return "Compute point features"

    def group(self):
        return "Classification"

    def groupId(self):  # noqa: N802
        return "classification"

    def icon(self):
        return QIcon(os.path.join(_ICONS, "features.svg"))

    def createInstance(self):  # noqa: N802
        return type(self)()

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Computes geometric features of each point's neighbourhood and writes them into a copy
of the cloud as LAS extra bytes (one float32 dimension per feature), to inspect them or to train a
classifier. The defaults are the features and radii of Matrone et al. (2024, Method 3): verticality
0.6 m, planarity 0.6 m, eigenentropy 0.4 m, surface variation 0.6 m.</p>
<h3>Definitions</h3>
<p>The neighbourhood is the sphere of the radius around the point, the point itself included.
With λ1 &ge; λ2 &ge; λ3 the eigenvalues of the covariance of its points and e = λ / (λ1 + λ2 + λ3)
(Weinmann et al. 2015): linearity (e1 - e2)/e1, planarity (e2 - e3)/e1, sphericity e3/e1, anisotropy
(e1 - e3)/e1, omnivariance (e1 e2 e3)^1/3, eigenentropy -&Sigma; e ln e, surface variation e3,
verticality 1 - |n<sub>z</sub>| (n the normal, the eigenvector of λ3), sum of eigenvalues
λ1 + λ2 + λ3 (m²). CloudCompare uses the same ratios but computes omnivariance and eigenentropy
from the raw eigenvalues λ, so those two differ from its values. Point density: points in the sphere per m³. Height above the column minimum: z minus
the lowest z within the column radius (horizontal distance). Points whose sphere holds fewer than
3 points get no value (NaN).</p>
<p>The paper's radii suit dense UAV clouds (hundreds of points per m²). On airborne clouds of about
10 points per m² many spheres of 0.4-0.6 m hold fewer than 3 points (the log says how many): use
larger radii there.</p>
<h3>Parameters</h3>
<p><b>Radius of each paper feature</b> (m): 0 leaves that feature out. <b>Other features</b>: any of
the others, at the <b>radius of the other features</b>, except the height above the column minimum,
which uses the <b>column radius</b>. All features at one radius cost one pass over the points.</p>
<p><b>Withheld points</b> (the LAS flag: "should not be included in processing") and points of the
<b>Ignored classes</b> (default <code>7,18</code>, noise; a list or ranges such as <code>7,18,20-25</code>;
empty = none) are left out of every neighbourhood and get no value (NaN), as in <i>Classify with
Random Forest model</i>: the features written are those the classifier computes.</p>
<h3>Output</h3>
<p>LAS or LAZ (by extension) with every dimension, extra bytes, VLR and the CRS of the input, plus the
features named <code>&lt;feature&gt;_r&lt;radius&gt;</code> with <code>p</code> as the decimal mark,
e.g. <code>verticality_r0p6</code>, <code>eigenentropy_r0p4</code>, <code>height_above_min_r2p5</code>.
An input that already holds a dimension of the same name is refused. Lengths are read in the unit of
the cloud's CRS. The output is written under a temporary name and renamed when complete.</p>
""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(pointclouds.offer_point_clouds_in_modeler(QgsProcessingParameterFile(
            self.INPUT, "Input point cloud (LAS/LAZ, or ISPRS .txt)",
            behavior=QgsProcessingParameterFile.Behavior.File,
            fileFilter="Point clouds (*.las *.laz *.LAS *.LAZ);;ISPRS text (*.txt);;All files (*.*)")))
        for param, _feature, label, default in self.PAPER:
            self.addParameter(QgsProcessingParameterNumber(
                param, label, type=Double, defaultValue=default, minValue=0.0))
        self.addParameter(QgsProcessingParameterEnum(
            self.EXTRA, "Other features", options=[label for _f, label in EXTRA_FEATURES],
            allowMultiple=True, optional=True, defaultValue=[]))
        self.addParameter(QgsProcessingParameterNumber(
            self.EXTRA_RADIUS, "Radius of the other features (m)", type=Double, defaultValue=0.6, minValue=0.0))
        self.addParameter(QgsProcessingParameterNumber(
            self.COLUMN_RADIUS, "Column radius of the height above the column minimum (m)", type=Double,
            defaultValue=2.5, minValue=0.0))
        self.addParameter(QgsProcessingParameterString(
            self.IGNORE_CLASSES, "Ignored classes: out of the neighbourhoods, no value (e.g. 7,18,20-25)",
            defaultValue="7,18", optional=True))
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, "Point cloud with features", fileFilter="LAZ (*.laz);;LAS (*.las)"))
        self.addOutput(QgsProcessingOutputString(self.FEATURES, "Feature names (comma-separated)"))

    def featurePairs(self, parameters, context):  # noqa: N802
        """The (feature, radius) pairs asked for, in the order of the dialog."""
        pairs = []
        for param, feature, _label, _default in self.PAPER:
            radius = self.parameterAsDouble(parameters, param, context)
            if radius != 0.0:
                pairs.append((feature, radius))
        extra_radius = self.parameterAsDouble(parameters, self.EXTRA_RADIUS, context)
        column_radius = self.parameterAsDouble(parameters, self.COLUMN_RADIUS, context)
        for index in self.parameterAsEnums(parameters, self.EXTRA, context):
            feature = EXTRA_FEATURES[index][0]
            pairs.append((feature, column_radius if feature == "height_above_min" else extra_radius))
        return pairs

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, _workflow = core_modules(feedback=feedback, kernels_of="features")
        from ..core.engine import features_run
        from ..core.learn import features
        input_path = self.parameterAsFile(parameters, self.INPUT, context)
        output_path = self.parameterAsFileOutput(parameters, self.OUTPUT, context)
        pairs = self.featurePairs(parameters, context)
        if not pairs:
            raise QgsProcessingException("No feature asked: give a radius above 0 to at least one of the "
                                         "paper's features, or pick other features.")
        try:
            spec = features.FeatureSpec(tuple(pairs))
            feedback.pushInfo("Features: " + ", ".join(spec.names))
            ignore = self.parameterAsString(parameters, self.IGNORE_CLASSES, context) or ""
            run = features_run.run_features(input_path, output_path, spec, ignore_classes=ignore,
                                            **feedback_callables(feedback))
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        warn_about_crs(feedback, input_path, run.cloud.crs_wkt, "every radius")
        kernels_compiled("features")
        return {self.OUTPUT: output_path, self.FEATURES: ",".join(run.names)}
