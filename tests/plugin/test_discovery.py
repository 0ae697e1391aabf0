"""Finding the algorithms: QGIS's own toolbox search (QgsProcessingToolboxProxyModel) on the words
users type, and what every algorithm offers besides (short description, help URL, help that
stands on its own inside the plugin zip)."""
import re
from pathlib import Path

import pytest

QUERIES = {
    # what a user types -> GroundSieve algorithms that must be found
    "dtm": {"smrf", "pmf", "csf", "ptd", "echogrid", "evc", "evcrasters", "rfclassify"},
    "lidar": {"smrf", "pmf", "csf", "ptd", "echogrid", "evc", "evcrasters", "features", "rftrain", "rfclassify"},
    "point cloud": {"smrf", "pmf", "csf", "ptd", "echogrid", "evc", "features", "rftrain", "rfclassify"},
    "ground": {"smrf", "pmf", "csf", "ptd", "echogrid", "evc", "rftrain", "rfclassify"},
    "las": {"smrf", "pmf", "csf", "ptd", "echogrid", "evc", "features", "rftrain", "rfclassify"},
    "bare earth": {"smrf", "pmf", "csf", "ptd"},
    "csf": {"csf"},
    "tin": {"ptd"},
    "cloth": {"csf"},
    "random forest": {"rftrain", "rfclassify"},
    "photogrammetry": {"evc", "evcrasters"},
    "accuracy": {"accuracy"},
    "checkpoints": {"accuracy"},
    "rmse": {"accuracy"},
}


def _found(proxy, text):
    from qgis.PyQt.QtCore import QModelIndex
    proxy.setFilterString(text)
    found, stack = set(), [QModelIndex()]
    while stack:
        parent = stack.pop()
        for row in range(proxy.rowCount(parent)):
            index = proxy.index(row, 0, parent)
            algorithm = proxy.toolboxModel().algorithmForIndex(proxy.mapToSource(index))
            if algorithm is not None and algorithm.provider().id() == "groundsieve":
                found.add(algorithm.name())
            stack.append(index)
    return found


@pytest.fixture(scope="module")
def toolbox(groundsieve_provider):
    from qgis.core import QgsApplication
    from qgis.gui import QgsProcessingToolboxProxyModel
    return QgsProcessingToolboxProxyModel(None, QgsApplication.processingRegistry())


@pytest.mark.parametrize("text", sorted(QUERIES))
def test_toolbox_search_finds_the_right_algorithms(toolbox, text):
    found = _found(toolbox, text)
    assert QUERIES[text] <= found, f"searching {text!r} misses {sorted(QUERIES[text] - found)}"


def test_a_specific_search_finds_only_its_algorithm(toolbox):
    assert _found(toolbox, "csf") == {"csf"}
    assert _found(toolbox, "smrf") == {"smrf"}
    assert _found(toolbox, "checkpoints") == {"accuracy"}
    assert _found(toolbox, "nothing-like-this") == set()


def test_every_algorithm_has_tags_description_and_help_url(groundsieve_provider):
    for algorithm in groundsieve_provider.algorithms():
        assert len(algorithm.tags()) >= 5, algorithm.id()
        assert 20 < len(algorithm.shortDescription()) < 200, algorithm.id()
        assert algorithm.helpUrl().startswith("https://"), algorithm.id()


def test_each_algorithms_help_button_leads_to_its_section_of_the_guide(groundsieve_provider):
    """The Help button led every algorithm to the README's list (a QGIS reviewer); it now opens the
    algorithm's own section of the user guide, whose heading must exist."""
    from groundsieve.algorithms.discovery import GUIDE_URL, heading_anchor
    guide = (Path(__file__).resolve().parents[2] / "docs" / "USER_GUIDE.md").read_text(encoding="utf-8")
    anchors = {heading_anchor(line[3:]) for line in guide.splitlines() if line.startswith("## ")}
    assert heading_anchor("Ground filter (SMRF)") == "ground-filter-smrf"
    assert heading_anchor("Classification: features, training, classifying") == \
        "classification-features-training-classifying"
    for algorithm in groundsieve_provider.algorithms():
        url = algorithm.helpUrl()
        assert url.startswith(GUIDE_URL + "#"), (algorithm.id(), url)
        assert url.split("#", 1)[1] in anchors, (algorithm.id(), url)


def test_help_points_at_nothing_the_zip_leaves_out(groundsieve_provider):
    """The zip ships neither docs/, bench/ nor scripts/: the help links to the web instead."""
    for algorithm in groundsieve_provider.algorithms():
        text = re.sub(r'href="[^"]*"', "", algorithm.shortHelpString())
        for folder in ("docs/", "bench/", "scripts/", "tests/"):
            assert folder not in text, f"{algorithm.id()}'s help names {folder}"


def test_raster_outputs_offer_only_geotiff(groundsieve_provider):
    """The save dialog of every raster output lists GeoTIFF alone (QGIS offered 37 formats, all but
    GeoTIFF refused after Run)."""
    from qgis.core import QgsProcessingParameterRasterDestination
    seen = 0
    for algorithm in groundsieve_provider.algorithms():
        for parameter in algorithm.parameterDefinitions():
            if isinstance(parameter, QgsProcessingParameterRasterDestination):
                seen += 1
                assert parameter.supportedOutputRasterLayerExtensions() == ["tif"], algorithm.id()
                assert parameter.defaultFileExtension() == "tif"
                assert "tif" in parameter.createFileFilter().lower() and "png" not in parameter.createFileFilter().lower()
    assert seen >= 9


def test_every_parameter_has_a_tooltip_of_its_own(groundsieve_provider):
    """0-3 parameters of each algorithm had a tooltip, and batch mode hides the help panel (a QGIS plugin
    reviewer): every parameter a user sees has its help (QgsProcessingParameterDefinition.help, in the
    dialog's and the batch table's tooltip), from the panel's paragraph on it where there is one."""
    from qgis.core import QgsProcessingParameterDefinition
    hidden = QgsProcessingParameterDefinition.Flag.FlagHidden
    without = [f"{alg.name()}:{d.name()}" for alg in groundsieve_provider.algorithms()
               for d in alg.parameterDefinitions() if not d.flags() & hidden and len(d.help()) < 20]
    assert without == []
    smrf = groundsieve_provider.algorithm("smrf")
    cell = smrf.parameterDefinition("CELL")
    assert cell.help() == "Grid cell of the minimum surface (1 m in the paper)." and cell.help() in cell.toolTip()
    assert smrf.parameterDefinition("SCALAR").help().startswith("A point is ground within the elevation threshold")
    # (a label's prefix gave the threshold "The final point test (0.5 m, 1.25)", the scalar's default in it)
    assert "0.5 m" in smrf.parameterDefinition("THRESHOLD").help() and "1.25" not in \
        smrf.parameterDefinition("THRESHOLD").help()
    dtm = groundsieve_provider.algorithm("dtm")
    assert "-1 = 40 m" in dtm.parameterDefinition("TILE_BUFFER").help()  # (its own, not a filter's reach)
