"""The plugin object: registers the Processing provider (desktop and qgis_process)."""
from qgis.core import QgsApplication

from .provider.provider import GroundSieveProvider


class GroundSievePlugin:
    def __init__(self, iface):
        self.iface = iface  # None under qgis_process
        self.provider = None

    def initProcessing(self):  # noqa: N802 (QGIS API name)
        if self.provider is None:
            self.provider = GroundSieveProvider()
            QgsApplication.processingRegistry().addProvider(self.provider)

    def initGui(self):  # noqa: N802 (QGIS API name)
        self.initProcessing()
        if self.iface is not None:
            from .dependencies import TRAINING, missing_dependencies
            missing = missing_dependencies(TRAINING)
            if missing:
                from qgis.core import Qgis
                self.iface.messageBar().pushMessage(
                    "GroundSieve", f"Python packages missing: {', '.join(missing)}. "
                    "The algorithms that need them stop with a message until they are installed "
                    "(see the plugin's README).",
                    level=Qgis.Warning, duration=15)

    def unload(self):
        if self.provider is not None:
            QgsApplication.processingRegistry().removeProvider(self.provider)
            self.provider = None
