"""groundsieve:echogrid — Ground filter (return-number grid), Matrone et al. 2024, Method 2."""

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help


class EchoGridAlgorithm(GroundFilterAlgorithm):
    FILTER = "echogrid"  # parameters: core/engine/parameters.py
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
