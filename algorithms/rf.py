"""groundsieve:rftrain — Train Random Forest classifier; groundsieve:rfclassify — Classify with
Random Forest model (Matrone et al. 2024, Method 3)."""
import os

from qgis.core import (QgsProcessingAlgorithm, QgsProcessingException, QgsProcessingOutputNumber,
                       QgsProcessingParameterBoolean, QgsProcessingParameterDefinition,
                       QgsProcessingParameterEnum, QgsProcessingParameterFile,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber,
                       QgsProcessingParameterRasterDestination, QgsProcessingParameterString)
from qgis.PyQt.QtGui import QIcon

from . import pointclouds
from .base import (FILTER_PARAMETER_HELP, SurveyTiles, check_parameter_values, core_modules, dialog_help,
                   dtm_classes_parameter, dtm_extent_parameter, dtm_extent_value, dtm_max_distance_parameter,
                   dtm_cell_set, feedback_callables, kernels_compiled)
from .discovery import Discoverable

_ICONS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "icons")
Double = QgsProcessingParameterNumber.Type.Double
Integer = QgsProcessingParameterNumber.Type.Integer
PRESET_NAMES = ("C5H", "C1", "C2", "C3", "C4", "C5", "custom", "HYBRID")
CRITERIA = ("gini", "entropy")
SCALERS = ("none", "standard", "robust")
CLOUD_FILTER = "Point clouds (*.las *.laz *.LAS *.LAZ)"
SURVEY_FILTER = CLOUD_FILTER + ";;Virtual point clouds (*.vpc);;All files and folders (*)"


def _rf(extra, feedback, name):
    errors, _workflow = core_modules(extra, feedback, kernels_of=name)
    from ..core.engine import learning
    from ..core.learn import rf
    return errors, rf, learning


class _RFBase(Discoverable, QgsProcessingAlgorithm):
    def group(self):
        return "Classification"

    def groupId(self):  # noqa: N802
        return "classification"

    def icon(self):
        return QIcon(os.path.join(_ICONS, "rf.svg"))

    def createInstance(self):  # noqa: N802
        return type(self)()

    def checkParameterValues(self, parameters, context):  # noqa: N802
        """QGIS's check, with what is wrong said in the dialog's words (an ISPRS .txt, a cell of -1)."""
        from ..core.grids.spec import MAX_CELL_M
        ok, message = super().checkParameterValues(parameters, context)
        return check_parameter_values(self, parameters, context, ok, message, strictly_positive=("DTM_CELL", "BLOCK"),
                                      largest={"DTM_CELL": MAX_CELL_M})


class RFTrainAlgorithm(_RFBase):
    PARAMETER_HELP = {
        "INPUT": "A labelled LAS/LAZ: its classification field is what is learnt.",
        "CLASSES": "The ASPRS codes to learn, e.g. 2,1 or 2,11,5,6,14; empty = every class present but 0, 7 and 18 "
                   "(with the hybrid features: ground 2 against all the others).",
        "CUSTOM_FEATURES": "With 'custom list': features by name, e.g. intensity,return_number,planarity_r0p6.",
        "GROUND_VS_REST": "Learn ground (2) against all the other classes (taken as 1), whatever the features: a "
                          "ground model, for a DTM (with x, y, z features only it also runs in Ground filter (learned "
                          "hybrid)). Off: the classes as they are, except with the "
                          "hybrid features and no classes named, which learn ground against the rest.",
        "CRITERION": "How the trees split: gini or entropy.",
        "TREES": "How many trees the forest has.",
        "SCALER": "How the features are scaled before training: none, standard or robust (the paper's grid). A "
                  "forest's splits follow the order of each feature's values, which scaling keeps: the three give "
                  "nearly the same forest (they differ by rounding only).",
        "GRID": "Train the paper's 18 combinations (criterion x trees x scaler) and keep the best on the "
                "validation set; 18 times as long, and the scalers change little (a forest's splits follow the order "
                "of each feature's values, which scaling keeps): kept as the paper ran it. The log names each.",
        "MAX_DEPTH": "The trees' largest depth; 0 = no limit.",
        "SAMPLES_PER_TREE": "Each tree's bootstrap sample at most this many points; 0 = all (bounds the time on "
                            "large clouds).",
        "BLOCK": "Training, validation and test sets are square blocks of this size drawn at random (60/20/20 %), "
                 "so neighbouring points do not leak between sets.",
        "VALIDATION": "A labelled cloud of its own for validation, instead of blocks of the input.",
        "TEST": "A labelled cloud of its own for the test, instead of blocks of the input.",
        "MODEL": "The model (.npz: plain arrays with a checksum, never a pickle): for Classify with Random Forest "
                 "model, and for the learned hybrid filter when trained on its features.",
        "REPORT": "The HTML report (precision, recall, F1, confusion matrices, feature importances), a CSV beside it.",
    }
    INPUT = "INPUT"
    CLASSES = "CLASSES"
    PRESET = "PRESET"
    CUSTOM_FEATURES = "CUSTOM_FEATURES"
    CRITERION = "CRITERION"
    TREES = "TREES"
    SCALER = "SCALER"
    MAX_DEPTH = "MAX_DEPTH"
    SAMPLES_PER_TREE = "SAMPLES_PER_TREE"
    BLOCK = "BLOCK"
    VALIDATION = "VALIDATION"
    TEST = "TEST"
    GRID = "GRID"
    GROUND_VS_REST = "GROUND_VS_REST"
    MODEL = "MODEL"
    REPORT = "REPORT"
    TEST_ACCURACY = "TEST_ACCURACY"

    def name(self):
        return "rftrain"

    def displayName(self):  # noqa: N802
        return "Train Random Forest classifier"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Trains a Random Forest on a labelled point cloud (its classification field is the
label), as Matrone et al. (2024, Method 3) did to test whether the return number helps.</p>
<p><b>Classes</b>: ASPRS codes to learn, e.g. <code>2,1</code> or <code>2,11,5,6,14</code>
(ground, road, vegetation, building, power line); empty = every class present except 0, 7 and 18.</p>
<p><b>Features</b>: the paper's configurations: C1 RGB; C2 RGB + return number; C3 + scan angle and
GPS time; C4 + verticality (0.6 m), planarity (0.6 m), eigenentropy (0.4 m), surface variation
(0.6 m); C5 = C4 without scan angle and GPS time (the paper's best). GPS time enters as the seconds of
its GPS week (adjusted standard time put back on the week), which the Random Forest's 32-bit features
hold to 0.06 s, where the raw time is in steps of 16-128 s. Clouds without colour use the
intensity in place of RGB. <b>C5H</b> (ours) adds the height above the lowest point within
2.5 m and the local point density, which carry the ground contrast on sparse airborne clouds where the
paper's small spheres hold few points. <i>custom</i>: a comma-separated list such as
<code>intensity,return_number,number_of_returns,planarity_r0p6,height_above_min_r2p5</code>. <b>HYBRID</b> (default): the features of
<i>Ground filter (learned hybrid)</i> (heights above SMRF's provisional surface and above the minimum
surface opened with 2, 6 and 18 m windows, that surface's slope and curvature; x, y, z only): train
ground (2) against the other classes on your own data (with <i>Classes to learn</i> empty, every class
but 2 is learnt as 1: a ground model) and use the model there or here. Geometric
features already in the file (from <i>Compute point features</i>) are used as they are.</p>
<p><b>Split</b>: training / validation / test sets are square blocks of <i>Block size</i> drawn at
random (60/20/20 %), so neighbouring points do not leak between sets; or give validation and test
files. <b>Parameter grid</b> runs the paper's 18 combinations (gini/entropy x 100/150/200 trees x
no/standard/robust scaler) and keeps the best on the validation set (weighted F1); it takes 18 times
as long. <b>Samples per tree</b> caps each tree's bootstrap sample (0 = all points), which bounds the
training time on large clouds.</p>
<p><b>Outputs</b>: the model file (.npz: plain arrays with a checksum, never a pickle, so loading it
cannot run code; a changed or foreign file is refused) and an HTML report (per-class precision,
recall, F1, overall accuracy, weighted averages, confusion matrices, impurity and permutation feature
importances, timings) with the same figures in a CSV beside it.</p>""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(pointclouds.offer_point_clouds_in_modeler(QgsProcessingParameterFile(
            self.INPUT, "Labelled point cloud (LAS/LAZ)", behavior=QgsProcessingParameterFile.Behavior.File,
            fileFilter=CLOUD_FILTER)))
        self.addParameter(QgsProcessingParameterString(
            self.CLASSES, "Classes to learn (ASPRS codes, comma-separated; empty = all present)",
            defaultValue="", optional=True))
        self.addParameter(QgsProcessingParameterBoolean(
            self.GROUND_VS_REST, "Learn ground (2) against all other classes (a ground model)", defaultValue=False))
        self.addParameter(QgsProcessingParameterEnum(
            self.PRESET, "Features", options=[
                "C5H: C5 + height above ground minimum and density", "C1: RGB",
                "C2: RGB + return number", "C3: RGB + return number, scan angle, GPS time",
                "C4: C3 + verticality, planarity, eigenentropy, surface variation",
                "C5: RGB + return number + the four geometric features (paper's best)",
                "custom list",
                "HYBRID: heights above SMRF's surface and 2, 6, 18 m openings (x, y, z only; "
                "the model also runs in Ground filter (learned hybrid); default)"],
            defaultValue=PRESET_NAMES.index("HYBRID")))
        self.addParameter(QgsProcessingParameterString(
            self.CUSTOM_FEATURES, "Custom feature list (with 'custom list')", defaultValue="", optional=True))
        self.addParameter(QgsProcessingParameterEnum(self.CRITERION, "Splitting criterion", options=list(CRITERIA),
                                                     defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(self.TREES, "Number of trees", type=Integer,
                                                       defaultValue=100, minValue=1))
        self.addParameter(QgsProcessingParameterEnum(self.SCALER, "Feature scaler", options=list(SCALERS),
                                                     defaultValue=0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.GRID, "Run the paper's parameter grid and keep the best on validation", defaultValue=False))
        advanced = [
            QgsProcessingParameterNumber(self.MAX_DEPTH, "Maximum tree depth (0 = none)", type=Integer,
                                         defaultValue=0, minValue=0),
            QgsProcessingParameterNumber(self.SAMPLES_PER_TREE, "Samples per tree (0 = all)", type=Integer,
                                         defaultValue=100000, minValue=0),
            QgsProcessingParameterNumber(self.BLOCK, "Block size of the spatial split (m)", type=Double,
                                         defaultValue=25.0, minValue=0.0),
            pointclouds.offer_point_clouds_in_modeler(QgsProcessingParameterFile(
                self.VALIDATION, "Validation cloud (instead of blocks)", optional=True,
                behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=CLOUD_FILTER)),
            pointclouds.offer_point_clouds_in_modeler(QgsProcessingParameterFile(
                self.TEST, "Test cloud (instead of blocks)", optional=True,
                behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=CLOUD_FILTER)),
        ]
        for param in advanced:
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
            self.addParameter(param)
        self.addParameter(QgsProcessingParameterFileDestination(self.MODEL, "Model file",
                                                                fileFilter="GroundSieve model (*.npz)"))
        self.addParameter(QgsProcessingParameterFileDestination(self.REPORT, "Report",
                                                                fileFilter="HTML (*.html)"))
        self.addOutput(QgsProcessingOutputNumber(self.TEST_ACCURACY, "Overall accuracy on the test set"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        from ..dependencies import TRAINING
        errors, rf, learning = _rf(TRAINING, feedback, "rftrain")
        try:
            preset = PRESET_NAMES[self.parameterAsEnum(parameters, self.PRESET, context)]
            if preset == "custom":
                text = self.parameterAsString(parameters, self.CUSTOM_FEATURES, context)
                features = tuple(n.strip() for n in text.split(",") if n.strip())
                if not features:
                    raise errors.InvalidParameterError("'custom list' needs a feature list")
            else:
                features = rf.PRESETS[preset]
            text = self.parameterAsString(parameters, self.CLASSES, context).strip()
            try:
                classes = tuple(int(c) for c in text.replace(";", ",").split(",") if c.strip()) or None
            except ValueError:
                raise errors.InvalidParameterError(f"classes must be ASPRS codes separated by commas (got {text!r})")
            depth = self.parameterAsInt(parameters, self.MAX_DEPTH, context)
            samples = self.parameterAsInt(parameters, self.SAMPLES_PER_TREE, context)
            params = rf.ForestParams(
                n_trees=self.parameterAsInt(parameters, self.TREES, context),
                criterion=CRITERIA[self.parameterAsEnum(parameters, self.CRITERION, context)],
                scaler=SCALERS[self.parameterAsEnum(parameters, self.SCALER, context)],
                max_depth=depth or None, max_samples=samples or None)
            options = learning.TrainOptions(features=features, classes=classes, params=params,
                                            block_m=self.parameterAsDouble(parameters, self.BLOCK, context),
                                            grid=self.parameterAsBoolean(parameters, self.GRID, context),
                                            ground_vs_rest=self.parameterAsBoolean(parameters, self.GROUND_VS_REST,
                                                                                   context) or None)
            model_path = self.parameterAsFileOutput(parameters, self.MODEL, context)
            report_path = self.parameterAsFileOutput(parameters, self.REPORT, context)
            run = learning.train_file(
                self.parameterAsFile(parameters, self.INPUT, context), model_path, report_path, options,
                validation_path=self.parameterAsFile(parameters, self.VALIDATION, context) or None,
                test_path=self.parameterAsFile(parameters, self.TEST, context) or None,
                **feedback_callables(feedback))
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        test = run.evaluations["test set"]
        feedback.pushInfo("Test set:\n" + test.table())
        kernels_compiled("rftrain")
        return {self.MODEL: model_path, self.REPORT: report_path, self.TEST_ACCURACY: test.accuracy}


class RFClassifyAlgorithm(SurveyTiles, _RFBase):
    PARAMETER_HELP = {
        "INPUT": "A LAS/LAZ file, a folder of them or a .vpc survey (a survey runs in buffered tiles). Only "
                 "read, never changed.",
        "MODEL": "A model written by Train Random Forest classifier (.npz); a changed or foreign file is refused.",
        "IGNORE_CLASSES": "Points of these classes keep their class, are not predicted and stay out of the DTM "
                          "(7 and 18, noise, by default).",
        "OUTPUT": "The classified LAS/LAZ, every dimension and the CRS of the input kept; a .vpc and a folder of "
                  "files for several input files. Skip it for the DTM alone (on a survey with a DTM extent, only "
                  "the extent's tiles are then classified).",
        "DTM": "A cloud-optimised GeoTIFF of the predicted ground (class 2) points' triangulation.",
        "DTM_CELL": FILTER_PARAMETER_HELP["DTM_CELL"],
        "DTM_FILL": FILTER_PARAMETER_HELP["DTM_FILL"],
        **{name: FILTER_PARAMETER_HELP[name] for name in ("TILE_SIZE", "MEMORY_BUDGET", "WORKERS", "WORK_FOLDER",
                                                          "SCHEDULER", "ONLY")},
        "TILE_BUFFER": "The margin read around each tile so that no seam shows; -1 = the reach of the model's "
                       "features, at least 30 m for the DTM (38 m for the HYBRID preset's).",
    }
    INPUT = "INPUT"
    MODEL = "MODEL"
    OUTPUT = "OUTPUT"
    DTM = "DTM"
    DTM_CELL = "DTM_CELL"
    DTM_FILL = "DTM_FILL"
    DTM_CLASSES = "DTM_CLASSES"
    DTM_MAX_DISTANCE = "DTM_MAX_DISTANCE"
    DTM_EXTENT = "DTM_EXTENT"
    IGNORE_CLASSES = "IGNORE_CLASSES"
    GROUND_COUNT = "GROUND_COUNT"
    POINT_COUNT = "POINT_COUNT"

    def name(self):
        return "rfclassify"

    def displayName(self):  # noqa: N802
        return "Classify with Random Forest model"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Applies a model trained with <i>Train Random Forest classifier</i> to another cloud and
writes it with the predicted ASPRS classes (every other dimension kept); optionally a DTM GeoTIFF
from the points predicted as ground (class 2), as the ground filters make it, and from the points of
the <i>DTM classes</i> of the input (e.g. <code>9</code>, water, for a flood model).</p>
<p><b>Withheld points</b> (the LAS flag: "if set, this point should not be included in processing (synonymous with
Deleted)") and
points of the <b>Ignored classes</b> (default <code>7,18</code>, noise; a list or ranges such as
<code>7,18,20-25</code>; empty = none) keep their class and flags and are left out of the features'
neighbourhoods, the prediction and the DTM, whose grid spans only the other points.</p>
<p><b>Surveys</b>: a folder of LAS/LAZ files, a virtual point cloud (.vpc) or a cloud larger than the memory is classified in
buffered tiles, as the ground filters do (the buffer is the reach of the model's features, at least
30 m for the DTM), with any model: its colour, returns, scan angle or GPS time are read from each tile's
points as a run of the whole cloud reads them, and each point gets the model's class. Every file must
have the model's attributes (a file without its colour is refused by name); each file's colour depth is
judged from all its points, as a run of the file alone judges it, and features outside what the model
learnt are warned about once for the survey, from 50,000 points spread over each of up to 16 of its
files. The tiles, the workers, a Dask cluster and one file of a survey for a job array (<i>Advanced
parameters</i>) are the ground filters'. Skip the
<i>Classified point cloud</i> for the DTM alone: on a survey with a <i>DTM extent</i>, only the tiles that make the
extent's cells are then classified.</p>
<p>The model is refused with a clear message when the file was changed or is not a GroundSieve
model, or when the cloud cannot give the model's features (e.g. colour in one and not the other).
Loading a model never runs code from the file (plain arrays, no pickle).</p>""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(pointclouds.offer_point_clouds_in_modeler(QgsProcessingParameterFile(
            self.INPUT, "Point cloud (LAS/LAZ, a folder of them, or a .vpc survey)",
            behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=SURVEY_FILTER), folders=True))
        self.addParameter(QgsProcessingParameterFile(
            self.MODEL, "Model file", behavior=QgsProcessingParameterFile.Behavior.File,
            fileFilter="GroundSieve model (*.npz)"))
        self.addParameter(QgsProcessingParameterString(
            self.IGNORE_CLASSES, "Ignored classes: kept, not predicted, out of the DTM (e.g. 7,18,20-25)",
            defaultValue="7,18", optional=True))
        self.addTileParameters(reach="the model's reach")
        # optional, made by default, as the ground filters' (a DTM alone: on a survey with a DTM extent,
        # only the extent's tiles are classified)
        self.addParameter(QgsProcessingParameterFileDestination(
            self.OUTPUT, "Classified point cloud (a .vpc for several input files)",
            fileFilter="LAZ (*.laz);;LAS (*.las);;Virtual point cloud (*.vpc)", optional=True, createByDefault=True))
        self.addParameter(QgsProcessingParameterRasterDestination(
            self.DTM, "DTM (ground surface)", optional=True, createByDefault=False))
        self.addParameter(QgsProcessingParameterNumber(
            self.DTM_CELL, "DTM cell size (m)", type=Double, defaultValue=1.0, minValue=0.0))
        self.addParameter(QgsProcessingParameterBoolean(
            self.DTM_FILL, "Fill DTM cells outside the ground hull (nearest value)", defaultValue=False))
        self.addParameter(dtm_classes_parameter(self.DTM_CLASSES))
        self.addParameter(dtm_max_distance_parameter(self.DTM_MAX_DISTANCE))
        self.addParameter(dtm_extent_parameter(self.DTM_EXTENT))
        # the counts the ground filters return too, for a model's next step (a power user's model could
        # not branch on rfclassify's result)
        self.addOutput(QgsProcessingOutputNumber(self.GROUND_COUNT, "Ground points"))
        self.addOutput(QgsProcessingOutputNumber(self.POINT_COUNT, "Points classified"))

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, rf, learning = _rf(None, feedback, "rfclassify")
        from ..core.engine.workflow import DTMOptions
        input_path = self.parameterAsFile(parameters, self.INPUT, context)
        output = pointclouds.classified_output_path(self, parameters, context, self.OUTPUT, input_path) or None
        dtm_path = self.parameterAsOutputLayer(parameters, self.DTM, context) or None
        if not output and not dtm_path:
            raise QgsProcessingException(pointclouds.nothing_to_write(self))
        try:
            dtm = DTMOptions(cell_size_m=self.parameterAsDouble(parameters, self.DTM_CELL, context),
                             cell_set=dtm_cell_set(self, parameters, context, self.DTM_CELL),
                             fill_outside_hull=self.parameterAsBoolean(parameters, self.DTM_FILL, context),
                             classes=self.parameterAsString(parameters, self.DTM_CLASSES, context) or "",
                             max_distance_m=self.parameterAsDouble(parameters, self.DTM_MAX_DISTANCE, context),
                             extent=dtm_extent_value(self, parameters, self.DTM_EXTENT, context, input_path,
                                                     feedback))
            ignored = self.parameterAsString(parameters, self.IGNORE_CLASSES, context) or ""
            tiling = self.tileOptions(parameters, context)
            run = learning.classify_file(input_path, output, self.parameterAsFile(parameters, self.MODEL, context),
                                         dtm_path=dtm_path, dtm=dtm, ignore_classes=ignored, tiling=tiling,
                                         **feedback_callables(feedback))
            ground, points = learning.classified_counts(run, ignored)
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        output, dtm_path = self.tiledOutputs(tiling, run, output, dtm_path)
        results = {self.GROUND_COUNT: ground, self.POINT_COUNT: points}
        if output:
            results[self.OUTPUT] = output
            # loaded as the ground filters load theirs (the same rules for a model's intermediate step)
            pointclouds.load_or_log(context, feedback, output,
                                    self.parameterDefinition(self.OUTPUT).description().split(" (")[0], self.OUTPUT,
                                    parameters.get(self.OUTPUT))
        if dtm_path:
            from . import styles
            results[self.DTM] = dtm_path
            styles.style_when_loaded(context, dtm_path, styles.DTM_STYLE)
        kernels_compiled("rfclassify")
        return results
