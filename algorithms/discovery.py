"""What makes an algorithm easy to find and to read up on: toolbox-search tags, the one-line
description shown in the toolbox's tooltip and the dialog, and the URL of the dialog's Help button.
One table for every algorithm, so that the words stay consistent."""

HOMEPAGE = "https://github.com/groundsieve/groundsieve"
HELP_URL = f"{HOMEPAGE}/blob/main/README.md"
BENCHMARKS_URL = f"{HOMEPAGE}/blob/main/docs/BENCHMARKS.md"
GUIDE_URL = f"{HOMEPAGE}/blob/main/docs/USER_GUIDE.md"

#: Words a user types in the toolbox search to find any of GroundSieve's algorithms.
COMMON_TAGS = ("lidar", "point cloud", "pointcloud", "las", "laz", "als", "uav", "drone")
#: ... and to find the ground filters.
FILTER_TAGS = ("ground", "ground filter", "bare earth", "terrain", "dtm", "dem", "classify", "classification",
               "filter")

TAGS = {
    "smrf": FILTER_TAGS + ("smrf", "morphological", "simple morphological filter", "pingel"),
    "pmf": FILTER_TAGS + ("pmf", "morphological", "progressive morphological filter", "zhang"),
    "csf": FILTER_TAGS + ("csf", "cloth", "cloth simulation"),
    "ptd": FILTER_TAGS + ("ptd", "tin", "triangulation", "progressive tin densification", "axelsson",
                          "lasground"),
    "echogrid": FILTER_TAGS + ("returns", "echo", "return number", "multi-return", "matrone", "zenmuse"),
    "evc": FILTER_TAGS + ("evc", "photogrammetry", "low vegetation", "coefficient of variation", "fan"),
    "evcrasters": FILTER_TAGS + ("evc", "photogrammetry", "low vegetation", "raster", "coefficient of variation",
                                 "fan"),
    "hybrid": FILTER_TAGS + ("hybrid", "learned", "machine learning", "random forest"),
    "features": ("features", "eigen", "geometric features", "verticality", "planarity", "eigenentropy",
                 "classification", "machine learning"),
    "rftrain": ("random forest", "train", "training", "machine learning", "classification", "classify",
                "ground", "model", "matrone"),
    "rfclassify": ("random forest", "machine learning", "classification", "classify", "ground", "model", "dtm",
                   "dem", "matrone"),
    "dtm": ("dtm", "dem", "dsm", "bare earth", "terrain", "raster", "rasterize", "tin", "triangulation",
            "classified", "class", "ground class", "las", "laz"),
    "accuracy": ("dtm", "dem", "accuracy", "vertical accuracy", "checkpoints", "check points", "rmse", "rmsez",
                 "nva", "vva", "asprs", "qa", "qc", "quality", "survey", "residuals"),
}

SHORT = {
    "smrf": "Separates ground from objects with the Simple Morphological Filter; the most accurate "
            "general-purpose filter here. Classified LAS/LAZ and an optional DTM.",
    "pmf": "Separates ground from objects with the progressive morphological filter (Zhang et al. 2003); fast.",
    "csf": "Separates ground from objects with the cloth simulation filter; set the cloth resolution and "
           "rigidness for the scene.",
    "ptd": "Separates ground from objects by progressive TIN densification (Axelsson 2000).",
    "echogrid": "A fast first pass for multi-return UAV LiDAR: the lowest points of a grid, using the "
                "return numbers (Matrone et al. 2024).",
    "evc": "Ground of UAV photogrammetry clouds with low vegetation, by the multiscale elevation "
           "coefficient of variation (Fan et al. 2023).",
    "evcrasters": "The multiscale EVC filter with its intermediate rasters (mean elevations, difference, EVC, "
                  "classes) as GeoTIFFs.",
    "hybrid": "Learned ground filter: a Random Forest on heights above morphological ground "
              "surfaces; works on x, y, z alone with the shipped model.",
    "features": "Adds per-point geometric features (verticality, planarity, eigenentropy, ...) to a LAS/LAZ "
                "as extra dimensions.",
    "rftrain": "Trains a Random Forest point classifier on a labelled LAS/LAZ; writes the model and an "
               "HTML report.",
    "rfclassify": "Classifies a LAS/LAZ with a trained Random Forest model; optional DTM from the ground "
                  "points.",
    "dtm": "A DTM from the points a classification already made ground (class 2, or the classes you name), "
           "without filtering them again; surveys in buffered tiles.",
    "accuracy": "Checks a DTM's vertical accuracy against surveyed checkpoints: RMSEz, bias, NVA and VVA "
                "(ASPRS Editions 1 and 2), with an HTML report.",
}


#: The user guide's section on each algorithm (its heading), where the dialog's Help button leads.
GUIDE_SECTIONS = {
    "smrf": "Ground filter (SMRF)",
    "csf": "Ground filter (CSF)",
    "pmf": "Ground filter (PMF)",
    "ptd": "Ground filter (progressive TIN densification)",
    "echogrid": "Ground filter (return-number grid)",
    "evc": "Ground filter (multiscale EVC) and the EVC raster workflow",
    "evcrasters": "Ground filter (multiscale EVC) and the EVC raster workflow",
    "hybrid": "Ground filter (learned hybrid)",
    "features": "Classification: features, training, classifying",
    "rftrain": "Classification: features, training, classifying",
    "rfclassify": "Classification: features, training, classifying",
    "tune": "Tune a ground filter on a labelled patch",
    "dtm": "DTM from classified points",
    "accuracy": "Check DTM accuracy against checkpoints",
}


def heading_anchor(heading: str) -> str:
    """The anchor a Markdown heading gets on GitHub: lower case, punctuation dropped, spaces as '-'."""
    import re
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


class Discoverable:
    """Mixin of every GroundSieve algorithm: tags, short description and help URL by its name, and the
    tooltips of its parameters."""

    #: a parameter's tooltip by its name (QgsProcessingParameterDefinition.setHelp): the dialog shows it on
    #: the parameter's label, batch mode on its cells, where the side panel's help is not shown (a QGIS
    #: plugin reviewer: 0-3 parameters of each algorithm had one)
    PARAMETER_HELP = {}

    def panelHelp(self, description):  # noqa: N802
        """The paragraph of the help panel on the parameter ``description`` (its label up to a unit in
        brackets or a colon, at the start of the paragraph: "Cell size (m): grid cell of ..."), without its
        label; "" when the help has none."""
        head = description.split(" (")[0].split(":")[0].strip().lower()
        for label, text in self._panel_paragraphs():
            if label.lower().startswith(head):
                return text[0].upper() + text[1:]
        return ""

    def _panel_paragraphs(self):
        """(label, text) of the help panel's paragraphs that start with a label, once per class (QGIS makes
        an algorithm's instance for every dialog, model step and run)."""
        cache = type(self).__dict__.get("_PANEL_PARAGRAPHS")
        if cache is None:
            from .base import plain_help
            cache = []
            for paragraph in plain_help(self.shortHelpString(), width=10 ** 6).split("\n\n"):
                label, sep, text = paragraph.replace("\n", " ").partition(": ")
                if sep and len(label) < 120 and text:
                    cache.append((label, text))
            type(self)._PANEL_PARAGRAPHS = cache
        return cache

    def addParameter(self, definition, createOutput=True):  # noqa: N802
        if not definition.help():
            text = self.PARAMETER_HELP.get(definition.name()) or self.panelHelp(definition.description())
            if text:
                definition.setHelp(text)
        return super().addParameter(definition, createOutput)

    def tags(self):
        return list(COMMON_TAGS + TAGS.get(self.name(), ()))

    def shortDescription(self):  # noqa: N802
        return SHORT.get(self.name(), "")

    def helpUrl(self):  # noqa: N802
        """The algorithm's section in the user guide (the README's list of algorithms for any without one)."""
        heading = GUIDE_SECTIONS.get(self.name())
        return f"{GUIDE_URL}#{heading_anchor(heading)}" if heading else f"{HELP_URL}#algorithms"
