"""The Processing provider: lists GroundSieve's algorithms explicitly."""
import configparser
import os

from qgis.core import QgsProcessingProvider
from qgis.PyQt.QtGui import QIcon

from ..algorithms.accuracy import AccuracyAlgorithm
from ..algorithms.csf import CSFAlgorithm
from ..algorithms.dtm import DTMFromClassesAlgorithm
from ..algorithms.echogrid import EchoGridAlgorithm
from ..algorithms.evc import EVCAlgorithm, EVCRastersAlgorithm
from ..algorithms.features import FeaturesAlgorithm
from ..algorithms.hybrid import HybridAlgorithm
from ..algorithms.pmf import PMFAlgorithm
from ..algorithms.ptd import PTDAlgorithm
from ..algorithms.rf import RFClassifyAlgorithm, RFTrainAlgorithm
from ..algorithms.smrf import SMRFAlgorithm
from ..algorithms.tune import TuneAlgorithm

ALGORITHMS = (SMRFAlgorithm, EchoGridAlgorithm, EVCAlgorithm, EVCRastersAlgorithm, PMFAlgorithm, CSFAlgorithm,
              PTDAlgorithm, HybridAlgorithm, FeaturesAlgorithm, RFTrainAlgorithm, RFClassifyAlgorithm, TuneAlgorithm,
              DTMFromClassesAlgorithm, AccuracyAlgorithm)

_ROOT = os.path.dirname(os.path.dirname(__file__))


def plugin_version() -> str:
    parser = configparser.ConfigParser()
    parser.read(os.path.join(_ROOT, "metadata.txt"), encoding="utf-8")
    return parser.get("general", "version", fallback="0")


class GroundSieveProvider(QgsProcessingProvider):
    def loadAlgorithms(self):  # noqa: N802 (QGIS API name)
        for cls in ALGORITHMS:
            self.addAlgorithm(cls())

    def id(self):
        return "groundsieve"

    def name(self):
        return "GroundSieve"

    def longName(self):  # noqa: N802 (QGIS API name)
        return f"GroundSieve {plugin_version()}"

    def icon(self):
        return QIcon(os.path.join(_ROOT, "icons", "groundsieve.svg"))

    def versionInfo(self):  # noqa: N802 (QGIS API name)
        return plugin_version()

    def supportedOutputRasterLayerExtensions(self):  # noqa: N802 (QGIS API name)
        """The core writes GeoTIFF only: the raster outputs' save dialogs offer just that."""
        return ["tif"]

    def defaultRasterFileExtension(self):  # noqa: N802 (QGIS API name)
        return "tif"
