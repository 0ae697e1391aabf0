"""groundsieve:tune — Tune a ground filter on a labelled patch (core/engine/tune.py)."""
import os

from qgis.core import (QgsProcessingAlgorithm, QgsProcessingException, QgsProcessingOutputNumber,
                       QgsProcessingParameterDefinition, QgsProcessingParameterEnum, QgsProcessingParameterFile,
                       QgsProcessingParameterFileDestination, QgsProcessingParameterNumber)
from qgis.PyQt.QtGui import QIcon

from .base import check_parameter_values, core_modules, dialog_help, feedback_callables
from .discovery import COMMON_TAGS, FILTER_TAGS, Discoverable
from .presets import PRESET_FILTER

_ICONS = os.path.join(os.path.dirname(os.path.dirname(__file__)), "icons")
#: the filters, in the order of core/engine/parameters.py FILTERS (read without importing numpy)
FILTERS = ("smrf", "pmf", "ptd", "csf", "echogrid", "evc")
FILTER_LABELS = ("SMRF (Pingel et al. 2013)", "PMF (Zhang et al. 2003)", "PTD (Axelsson 2000)",
                 "CSF (Zhang et al. 2016)", "EchoGrid (Matrone et al. 2024)", "EVC (Fan et al. 2023)")
METRICS = ("total", "kappa", "f1")
METRIC_LABELS = ("total error (ISPRS)", "Cohen's kappa", "F1 of the ground class")
SELECTIONS = ("best", "one-se")
SELECTION_LABELS = ("Lowest error", "One-standard-error rule (nearest the starting set)")


class TuneAlgorithm(Discoverable, QgsProcessingAlgorithm):
    INPUT = "INPUT"
    FILTER = "FILTER"
    METRIC = "METRIC"
    BUDGET = "BUDGET"
    BLOCKS = "BLOCKS"
    SECONDS = "SECONDS"
    SELECTION = "SELECTION"
    START_PRESET = "START_PRESET"
    OUTPUT_PRESET = "OUTPUT_PRESET"
    OUTPUT_HTML = "OUTPUT_HTML"
    PARAMETER_HELP = {
        "INPUT": "A small labelled patch of your survey: LAS/LAZ with its ground in class 2 (the rest any other "
                 "class), or an ISPRS text file. It needs ground and non-ground points.",
        "FILTER": "The ground filter whose parameters are searched.",
        "METRIC": "What the search minimises or maximises: the total error, Cohen's kappa or the ground class's F1.",
        "BUDGET": "How many filter runs the search may take (the grid, then the refinement around the best).",
        "BLOCKS": "The patch is cut into this many spatial blocks; each is scored with a set chosen on the others "
                  "only (the cross-validated error).",
        "SECONDS": "Stop the search after this long and keep the best so far; 0 = no limit.",
        "SELECTION": "The set with the lowest error, or the one-standard-error rule: of the sets within one standard "
                     "error of the lowest, the one nearest the starting set (for a small or mixed patch).",
        "START_PRESET": "Search from this preset (e.g. uav-photogrammetry-smrf.json); the parameters the search does not "
                        "cover keep its values.",
        "OUTPUT_PRESET": "The chosen set as a preset file: give it as the filter's Preset to run the survey with it.",
        "OUTPUT_HTML": "The report: the error of every set tried, one plot per parameter and the confusion matrices.",
    }
    CV_TOTAL_ERROR = "CV_TOTAL_ERROR"
    CV_KAPPA = "CV_KAPPA"
    CV_F1 = "CV_F1"

    def name(self):
        return "tune"

    def displayName(self):  # noqa: N802
        return "Tune a ground filter on a labelled patch"

    def group(self):
        return "Ground filters"

    def groupId(self):  # noqa: N802
        return "groundfilters"

    def icon(self):
        return QIcon(os.path.join(_ICONS, "groundsieve.svg"))

    def tags(self):
        return list(COMMON_TAGS + FILTER_TAGS + ("tune", "tuning", "optimise", "optimize", "parameters", "preset",
                                                 "calibrate", "cross-validation"))

    def shortDescription(self):  # noqa: N802
        return ("Finds a ground filter's best parameters on a labelled patch (cross-validated) and saves them "
                "as a preset for the whole survey, with an HTML report.")

    def createInstance(self):  # noqa: N802
        return type(self)()

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Searches the parameters of a ground filter on a small labelled patch of your
survey and saves the best set as a <b>preset</b>: give that file as the <i>Preset</i> of the filter to
filter the whole survey with it.</p>
<p><b>Labelled patch</b>: a LAS/LAZ whose ground points are class 2 (every other class counts as
non-ground, except noise 7 and 18 and withheld points, which are left out), or an ISPRS text file
<code>x y z label</code> (label 0 = ground, 1 = object). It must hold both ground and non-ground
points; a few hundred metres square of typical terrain is enough.</p>
<p><b>Search</b>: the filter's defaults (or the <i>Starting preset</i>), then sets spread evenly over the
ranges spanning the values the papers used or studied (wider where a paper gives one setting or few: EVC's
threshold 0.3-3 and large grid 1-10 m around the paper's 1-2 and up to 6.4 m, and its ground offset 0-0.3 m, ours),
then a local refinement around the best, until the <i>Search budget</i>
(runs of the filter on the patch) or the time limit is spent. A run is one set of parameters, except for
SMRF, whose threshold and scalar are re-scored on each run's surface for free: its log counts more sets
than runs (e.g. 788 sets in 60 runs).</p>
<p><b>Honest figure</b>: the patch is cut into spatial blocks; each block is classified with the set
chosen on the other blocks only (by a search of its own), and the errors of these held-out blocks give
the <b>cross-validated error</b>, what to expect on similar data. The preset carries the set chosen on
the whole patch.</p>
<p><b>Score</b>: total error (ISPRS: misclassified / all), Cohen's kappa, or the F1 of the ground class.</p>
<p><b>Choice of the set</b> (advanced): the set with the lowest error, or by the one-standard-error rule
(3 blocks or more): of the sets whose error is within one standard error of the lowest (from the
blocks' differences), the one nearest the starting set. The rule gives up a little on the patch for sets that hold better
elsewhere (on the 8 ISPRS samples: cross-validated 3.58 % against 3.74 % on average).</p>
<p><b>Report</b>: an HTML page (it opens in the results viewer) with the cross-validated error, the
chosen parameters, the confusion matrices, a plot of the score against each parameter (its
sensitivity) and every set tried.</p>""")

    def initAlgorithm(self, config=None):  # noqa: N802
        self.addParameter(QgsProcessingParameterFile(
            self.INPUT, "Labelled patch (LAS/LAZ with ground = class 2, or ISPRS .txt)",
            behavior=QgsProcessingParameterFile.Behavior.File,
            fileFilter="Point clouds (*.las *.laz *.LAS *.LAZ);;ISPRS text (*.txt);;All files (*)"))
        self.addParameter(QgsProcessingParameterEnum(self.FILTER, "Filter to tune", options=list(FILTER_LABELS),
                                                     defaultValue=0))
        self.addParameter(QgsProcessingParameterEnum(self.METRIC, "Score", options=list(METRIC_LABELS),
                                                     defaultValue=0))
        self.addParameter(QgsProcessingParameterNumber(
            self.BUDGET, "Search budget (filter runs; SMRF re-scores threshold and scalar on each run for free)",
            type=QgsProcessingParameterNumber.Type.Integer, defaultValue=60, minValue=4, maxValue=100000))
        advanced = [
            QgsProcessingParameterNumber(self.BLOCKS, "Spatial blocks of the cross-validation",
                                         type=QgsProcessingParameterNumber.Type.Integer, defaultValue=8,
                                         minValue=2, maxValue=16),
            QgsProcessingParameterNumber(self.SECONDS, "Time limit (s; 0 = none)",
                                         type=QgsProcessingParameterNumber.Type.Double, defaultValue=0.0,
                                         minValue=0.0),
            QgsProcessingParameterEnum(self.SELECTION, "Choice of the set", options=list(SELECTION_LABELS),
                                       defaultValue=0),
            QgsProcessingParameterFile(self.START_PRESET, "Starting preset (its other parameters are kept)",
                                       behavior=QgsProcessingParameterFile.Behavior.File, fileFilter=PRESET_FILTER,
                                       optional=True),
        ]
        for param in advanced:
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
            self.addParameter(param)
        self.addParameter(QgsProcessingParameterFileDestination(self.OUTPUT_PRESET, "Preset",
                                                                fileFilter="GroundSieve preset (*.json)"))
        self.addParameter(QgsProcessingParameterFileDestination(self.OUTPUT_HTML, "Report",
                                                                fileFilter="HTML (*.html)"))
        self.addOutput(QgsProcessingOutputNumber(self.CV_TOTAL_ERROR, "Cross-validated total error (0-1)"))
        self.addOutput(QgsProcessingOutputNumber(self.CV_KAPPA, "Cross-validated kappa"))
        self.addOutput(QgsProcessingOutputNumber(self.CV_F1, "Cross-validated F1 of the ground class (0-1)"))

    def checkParameterValues(self, parameters, context):  # noqa: N802
        """QGIS's checks, said in the dialog's words (the first wrong value, named by its label); a
        shipped preset is taken by its name as the filters' PRESET is."""
        ok, message = super().checkParameterValues(parameters, context)
        return check_parameter_values(self, parameters, context, ok, message)

    def processAlgorithm(self, parameters, context, feedback):  # noqa: N802
        errors, _workflow = core_modules(feedback=feedback)
        from ..core.engine import presets, tune
        from ..core.engine.tune_report import write_report
        name = FILTERS[self.parameterAsEnum(parameters, self.FILTER, context)]
        preset_path = self.parameterAsFileOutput(parameters, self.OUTPUT_PRESET, context)
        report_path = self.parameterAsFileOutput(parameters, self.OUTPUT_HTML, context)
        try:
            start = self.parameterAsFile(parameters, self.START_PRESET, context) \
                if parameters.get(self.START_PRESET) else ""
            base = presets.load_preset(start, name).values if start else None
            tune.check_tune_outputs(self.parameterAsFile(parameters, self.INPUT, context), preset_path, report_path)
            options = tune.TuneOptions(metric=METRICS[self.parameterAsEnum(parameters, self.METRIC, context)],
                                       budget=self.parameterAsInt(parameters, self.BUDGET, context),
                                       blocks=self.parameterAsInt(parameters, self.BLOCKS, context),
                                       seconds=self.parameterAsDouble(parameters, self.SECONDS, context),
                                       selection=SELECTIONS[self.parameterAsEnum(parameters, self.SELECTION,
                                                                                 context)])
            result = tune.tune(self.parameterAsFile(parameters, self.INPUT, context), name, options, base=base,
                               **feedback_callables(feedback))
            presets.write_preset(preset_path, name, tune.preset_values(result), source=tune.preset_source(result),
                                 description=f"tuned on {os.path.basename(result.patch)} ({result.metric}, "
                                             f"{len(result.trials)} sets)")
            write_report(report_path, result)
        except errors.GroundSieveError as err:
            raise QgsProcessingException(str(err)) from err
        cv = result.cv
        feedback.pushInfo(f"{len(result.trials)} sets in {result.runs} filter runs, {result.seconds:.0f} s. "
                          f"Cross-validated: {cv.summary()}. Chosen set on the whole patch: "
                          f"{result.best_accuracy.summary()}.")
        for _title, text in result.warnings:
            feedback.pushWarning(text)
        return {self.OUTPUT_PRESET: preset_path, self.OUTPUT_HTML: report_path,
                self.CV_TOTAL_ERROR: cv.total, self.CV_KAPPA: cv.kappa, self.CV_F1: cv.f1}
