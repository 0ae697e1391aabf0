"""groundsieve:echogrid — Ground filter (return-number grid), Matrone et al. 2024, Method 2."""
from qgis.core import (QgsProcessingParameterDefinition, QgsProcessingParameterEnum,
                       QgsProcessingParameterNumber)

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help

Double = QgsProcessingParameterNumber.Type.Double
MODES = ("faithful", "evidence")


class EchoGridAlgorithm(GroundFilterAlgorithm):
    KERNEL = "KERNEL"
    DZ = "DZ"
    MODE = "MODE"
    NEIGHBOURHOOD = "NEIGHBOURHOOD"
    SLOPE = "SLOPE"

    def name(self):
        return "echogrid"

    def displayName(self):  # noqa: N802
        return "Ground filter (return-number grid)"

    def iconName(self):  # noqa: N802
        return "echogrid.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>The return-number ("echo") grid filter of Matrone et al. (2024, Method 2), made for
UAV LiDAR: square kernels of <i>Kernel size</i> tile the cloud; in each, points higher than the lowest
point + <i>Height above the kernel's lowest point</i> are non-ground; a kernel whose points all have
return number 1 is taken as ground whole, without the height test (bare ground mostly gives single
returns).</p>
<p><b>No return information</b> (photogrammetry, ISPRS text, every point 1 of 1): the filter says so
in the log and applies the height test everywhere.</p>
<p><b>Mode</b>: <i>faithful</i> is the paper's rule. <i>evidence</i> uses the echoes as evidence
rather than as a bypass, as the paper's conclusion asks: a return followed by others is never ground;
a kernel of single returns is bypassed only when its height range is within the threshold and it is
not raised above its neighbours (flat roofs are no longer ground); a raised kernel (its lowest point
more than the threshold above the lowest points within <i>neighbourhood</i>, each raised by
<i>slope</i> x distance) is tested against that height. A neighbourhood of half the largest
building's width also finds the middle of wide roofs, at a cost on steep terrain. Both modes are
measured in <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>.</p>
""" + COMMON_HELP)

    def initFilterParameters(self):  # noqa: N802
        self.addParameter(QgsProcessingParameterNumber(
            self.KERNEL, "Kernel size (m)", type=Double, defaultValue=5.0, minValue=0.01))
        self.addParameter(QgsProcessingParameterNumber(
            self.DZ, "Height above the kernel's lowest point (m)", type=Double, defaultValue=2.0, minValue=0.0))
        self.addParameter(QgsProcessingParameterEnum(
            self.MODE, "Mode", options=["faithful (paper: single-return kernels are ground)",
                                        "evidence (echoes as evidence, not as a bypass)"], defaultValue=0))
        for param in (
                QgsProcessingParameterNumber(self.NEIGHBOURHOOD, "Evidence mode: neighbourhood for raised kernels (m)",
                                             type=Double, defaultValue=5.0, minValue=0.0),
                QgsProcessingParameterNumber(self.SLOPE, "Evidence mode: terrain slope between kernels (rise/run)",
                                             type=Double, defaultValue=0.15, minValue=0.0)):
            param.setFlags(param.flags() | QgsProcessingParameterDefinition.Flag.FlagAdvanced)
            self.addParameter(param)

    def buildFilter(self, parameters, context):  # noqa: N802
        from ..core.filters.echogrid import EchoGrid
        return EchoGrid(kernel_m=self.parameterAsDouble(parameters, self.KERNEL, context),
                        dz_m=self.parameterAsDouble(parameters, self.DZ, context),
                        mode=MODES[self.parameterAsEnum(parameters, self.MODE, context)],
                        neighbourhood_m=self.parameterAsDouble(parameters, self.NEIGHBOURHOOD, context),
                        slope=self.parameterAsDouble(parameters, self.SLOPE, context))
