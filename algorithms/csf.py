"""groundsieve:csf — Ground filter (CSF, cloth simulation, Zhang et al. 2016)."""

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help


#: Rigidness options as the reference implementation's tools present them: option i is rigidness i + 1.


class CSFAlgorithm(GroundFilterAlgorithm):
    FILTER = "csf"  # parameters: core/engine/parameters.py
    RESOLUTION = "RESOLUTION"
    RIGIDNESS = "RIGIDNESS"
    TIME_STEP = "TIME_STEP"
    CLASS_THRESHOLD = "CLASS_THRESHOLD"
    ITERATIONS = "ITERATIONS"
    SLOPE_SMOOTH = "SLOPE_SMOOTH"
    LOW_OUTLIER = "LOW_OUTLIER"
    INTERSECTION_HEIGHT = "INTERSECTION_HEIGHT"
    CONSTRAINT_SCHEME = "CONSTRAINT_SCHEME"
    SWEEP_ORDER = "SWEEP_ORDER"

    def name(self):
        return "csf"

    def displayName(self):  # noqa: N802
        return "Ground filter (CSF)"

    def iconName(self):  # noqa: N802
        return "csf.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points with the Cloth Simulation Filter (Zhang, Qi,
Wan, Wang, Xie, Wang &amp; Yan 2016, Remote Sensing 8(6):501), after the authors' reference
implementation: the cloud is turned upside down and a grid of cloth particles falls on it under
gravity; particles that reach the (inverted) surface are pinned there, the others are held by their
neighbours, so the cloth bridges buildings and trees; a point is ground when it lies within the class
threshold of the cloth (bilinear interpolation between the four particles around it).</p>
<h3>Parameters</h3>
<p><b>Cloth resolution (m)</b>: distance between particles (1 m by default; 0.5 m in the paper's
ISPRS tests). <b>Rigidness</b>: how stiff the cloth is, by scene: 1 for steep slopes, 2 for relief,
3 for flat terrain (the default). <b>Time step</b>: of the simulation (0.65); the gravity step is
0.2 x time step<sup>4</sup> per iteration, as in the reference library. <b>Class threshold (m)</b>:
largest distance from the cloth of a ground point (0.5 m). <b>Maximum iterations</b> (500): the
simulation stops earlier once the cloth has settled (no particle moved more than 5 mm in an
iteration; with the rotating sweep, 40 mm over a cycle of 8 iterations).
<b>Slope post-processing</b>: pins groups of cloth left hanging over steep slopes onto the
surface from their edges inwards while neighbouring heights differ by less than 0.3 m (on by
default; the paper turns it off for flat scenes).</p>
<p>Advanced: <b>Low-outlier threshold (m)</b>: a point more than this below its surroundings (the
lowest points of the eight 5 m cells around it) is left out of the cloth and is not ground; 0 turns
this off. A single low outlier otherwise pins a tent of cloth tens of metres below the ground. Not in
the reference. <b>Particle heights from</b>: the height each particle cannot fall below is that of the
nearest point (the paper's definition, the default) or, as the reference library does, of the points
that fall in the particle's cell, empty cells taking the first value to the east along their row;
the library's way is much worse where points are sparser than the cloth (see <a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>).
<b>Sweep order</b>: the library updates the particles one after another, row by row from the
south-west corner, each with the new heights of those before it, so the result depends on how the
cloud is oriented (the 8 ISPRS samples turned by 0, 90, 180, 270 degrees: mean total error 6.1 to
7.8 %). <i>Rotating</i> (the default) cycles through the 8 orders of the turned and mirrored cloth,
one per iteration: 5.4 to 5.8 % at every orientation, about 1.3 times the run time. <i>Fixed</i> is
the library's order.
<b>Cloth constraints</b>: how neighbouring particles hold each other. The reference library 1.1.7
(default) relaxes every neighbour pair from both ends each iteration. The authors' 2016 code (which
always runs in its own order) makes rigidness passes over the pairs, and a pinned particle there
pulls only its neighbours to the west, south-west, south and south-east: a softer cloth, the scheme with which the paper's
ISPRS figures are reproduced (mean total error 4.8 % on the 8 samples here against 4.6 % published;
library scheme 5.6 %, 6.1 % in its fixed order), but turned by 90, 180 or 270 degrees the same
samples give 7.0 to 7.6 %.</p>
<p>The run time grows with the area / resolution<sup>2</sup> more than with the number of points.</p>
""" + COMMON_HELP)
