"""groundsieve:pmf — Ground filter (PMF, Zhang et al. 2003)."""

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help


class PMFAlgorithm(GroundFilterAlgorithm):
    FILTER = "pmf"  # parameters: core/engine/parameters.py
    CELL = "CELL"
    MAX_WINDOW = "MAX_WINDOW"
    SLOPE = "SLOPE"
    INITIAL_DISTANCE = "INITIAL_DISTANCE"
    MAX_DISTANCE = "MAX_DISTANCE"
    EXPONENTIAL = "EXPONENTIAL"

    def name(self):
        return "pmf"

    def displayName(self):  # noqa: N802
        return "Ground filter (PMF)"

    def iconName(self):  # noqa: N802
        return "pmf.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points with the Progressive Morphological Filter
(Zhang, Chen, Whitman, Shyu, Yan &amp; Zhang 2003, IEEE TGRS 41(4):872-882), as the paper describes it:
a minimum-elevation grid, empty cells taking the value of the nearest cell; square windows growing
linearly (5, 9, 13, ... cells) or exponentially (3, 5, 9, 17, 33, ... cells) up to the maximum
window; the grid opened (erosion then dilation) with each window in turn, each opening applied to the
previous one; a cell whose elevation drops by more than the threshold of that window is non-ground.
The threshold is the initial distance for the first window, then <i>slope x (window increase) x cell
size + initial distance</i>, at most the maximum distance. A point is ground when its cell is ground
and it lies at most the initial distance above the cell's lowest point.</p>
<p>Objects wider than the maximum window are not removed: set it to about the size of the largest
building. Low outliers are not detected: classify them as noise (7) beforehand.</p>
<h3>Parameters</h3>
<p><b>Cell size (m)</b>: grid cell of the minimum surface, about the point spacing (1 m).
<b>Maximum window size (m)</b>: width of the largest window (33 m).
<b>Slope (rise/run)</b>: terrain slope the thresholds allow for (1.0 = 45°).
<b>Initial distance (m)</b>: threshold of the first window, the tolerance for measurement noise
(0.15 m). <b>Maximum distance (m)</b>: the largest threshold (2.5 m).
<b>Exponential window growth</b>: fewer, faster-growing windows (on by default); off: linear growth,
which follows gradual terrain better at more cost. The defaults are those of PDAL's
<code>filters.pmf</code>; unlike it, every point is filtered unless <i>Filter only last returns</i> is
ticked.</p>
""" + COMMON_HELP)
