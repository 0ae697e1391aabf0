"""groundsieve:smrf — Ground filter (SMRF, Pingel, Clarke & McBride 2013)."""

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help


class SMRFAlgorithm(GroundFilterAlgorithm):
    FILTER = "smrf"  # parameters: core/engine/parameters.py
    CELL = "CELL"
    SLOPE = "SLOPE"
    WINDOW = "WINDOW"
    THRESHOLD = "THRESHOLD"
    SCALAR = "SCALAR"
    LOW_OUTLIER_FILL = "LOW_OUTLIER_FILL"
    LOW_OUTLIER_SLOPE = "LOW_OUTLIER_SLOPE"
    LOW_OUTLIER_MAX_SHARE = "LOW_OUTLIER_MAX_SHARE"

    def name(self):
        return "smrf"

    def displayName(self):  # noqa: N802
        return "Ground filter (SMRF)"

    def iconName(self):  # noqa: N802
        return "smrf.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points with the Simple Morphological Filter
(Pingel, Clarke &amp; McBride 2013, ISPRS J. Photogramm. 77:21-30), as the paper describes it:
a minimum-elevation grid with empty cells filled by harmonic inpainting; low outliers found on the
inverted surface; a progressive opening with disks growing one cell at a time up to the maximum
window, a cell being an object when it drops by more than slope x radius; a provisional ground
surface interpolated over the object cells; finally each point is ground when it lies within
<i>elevation threshold + elevation scalar x local slope</i> of that surface (cubic interpolation).</p>
<h3>Parameters</h3>
<p><b>Cell size (m)</b>: grid cell of the minimum surface (1 m in the paper).
<b>Slope (rise/run)</b>: terrain slope the filter tolerates (0.15 = 15 %).
<b>Maximum window radius (m)</b>: about the radius of the largest building (18 m).
<b>Elevation threshold (m)</b> and <b>elevation scalar</b>: the final point test (0.5 m, 1.25).
<b>Remove low outliers before the opening</b>: low-outlier cells are refilled from their
neighbours before the progressive opening (on by default; Pingel's Python code leaves it off;
it lowers the mean ISPRS total error with the single parameter set, see <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>).
<b>Low-outlier slope</b> (advanced): a cell is a low outlier when it lies more than this many cell
sizes below the cells around it (5, the paper's: 5 m with 1 m cells). A low point less deep stays
ground and leaves a pit in the DTM; 1 catches points 1 m deep, but cuts narrow ditches and steep
ground (ISPRS samp41: 5.1 to 9.6 % total error), so classify isolated low points as noise (7) where you can.
<b>Low-outlier share</b> (advanced): low outliers are refilled only where they are at most this share of the
occupied cells within 10 m (0.05); where more are, they are taken for ground seen through gaps in a
closed canopy and kept. A cloud of surface points (photogrammetry) sees no ground through a canopy:
there 1 refills them all, and with a low-outlier slope of 1 it removes image-matching blunders below
the ground, a few hundred of which made SMRF lose most of the ground of a dense cloud (the shipped
preset <code>uav-photogrammetry-smrf.json</code> sets both).</p>
""" + COMMON_HELP)
