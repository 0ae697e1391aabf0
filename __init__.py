"""GroundSieve QGIS plugin. Importing this package imports no QGIS module, so the
GUI-free ``groundsieve.core`` can be used and tested without QGIS."""


def classFactory(iface):  # noqa: N802 (QGIS API name)
    from .plugin import GroundSievePlugin
    return GroundSievePlugin(iface)
