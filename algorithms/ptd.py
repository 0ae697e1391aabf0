"""groundsieve:ptd — Ground filter (progressive TIN densification, Axelsson 2000)."""

from .base import COMMON_HELP, GroundFilterAlgorithm, dialog_help


class PTDAlgorithm(GroundFilterAlgorithm):
    FILTER = "ptd"  # parameters: core/engine/parameters.py
    SEED_CELL = "SEED_CELL"
    MAX_ANGLE = "MAX_ANGLE"
    MAX_DISTANCE = "MAX_DISTANCE"
    MAX_EDGE = "MAX_EDGE"
    MIN_EDGE = "MIN_EDGE"
    TERRAIN_ANGLE = "TERRAIN_ANGLE"
    OFFSET = "OFFSET"
    MIRROR = "MIRROR"
    LOW_OUTLIERS = "LOW_OUTLIERS"
    LOW_OUTLIER_SUPPORT = "LOW_OUTLIER_SUPPORT"

    def name(self):
        return "ptd"

    def displayName(self):  # noqa: N802
        return "Ground filter (progressive TIN densification)"

    def iconName(self):  # noqa: N802
        return "ptd.svg"

    def shortHelpString(self):  # noqa: N802
        return dialog_help("""<p>Separates ground from non-ground points by progressive TIN densification (Axelsson
2000, "DEM generation from laser scanner data using adaptive TIN models", IAPRS 33(B4)), the method
of TerraScan's ground routine and LAStools' lasground: the lowest point of each cell of a grid as
large as the largest building seeds a triangulated surface (TIN) of the ground; then, round after
round, every triangle adds the point nearest its plane among those that pass Axelsson's two tests:
the point is at most the <i>iteration distance</i> from the triangle's plane, and the lines from
it to the triangle's three corners make at most the <i>iteration angle</i> with the plane. A point
below the triangle only has to pass the distance test. The TIN grows up from the ground and stops
where objects begin; when no point passes, the TIN's points are ground, and so are the points
within the <i>offset</i> of it.</p>
<p>Low outliers: a cell's lowest point that lies far below most of the area around it (an isolated
echo, or a group of multipath echoes) is not ground and does not seed the TIN. In clouds denser
than 2 points/m², only the lowest point of each 1 m square enters the TIN; the others are judged
against the final TIN.</p>
<h3>Parameters</h3>
<p><b>Seed cell size (m)</b>: about the size of the largest building: a building larger than it
has a whole cell on its roof and is taken as ground (30 m; TerraScan suggests 60 m, lasR 50 m).
<b>Iteration angle (degrees)</b>: 30° (lasR's default; smaller keeps more low objects out but
leaves steep or rough ground out too). <b>Iteration distance (m)</b>: 1.4 m.
<b>Maximum edge length (m)</b>: a triangle with a longer edge accepts no point, so the TIN does
not bridge large gaps (water, missing data); 0 = off.</p>
<p>Advanced: <b>Minimum edge length (m)</b>: triangles whose edges are all shorter are not
densified further (their passing points are still ground); 0 = off.
<b>Maximum terrain angle (degrees)</b>: a triangle steeper than this (one stood up along a wall)
accepts no point (75°). <b>Offset (m)</b>: the points this close to the final TIN (above or
below) are ground too (0.2 m; 0 = off). <b>Mirror points</b>: Axelsson's mirroring: a point that
fails is tested again as its mirror image through the nearest corner, which lets the TIN climb
steep slopes but also lets it climb onto objects joined to sloping ground (off).
<b>Reject low outliers</b>: on. <b>Low-outlier test: share of the cells around that must
support a seed</b>: a cell's lowest point is an outlier when fewer than this share of the cells
around it (10 point spacings, at least 5 m) have their lowest point within the iteration distance
and angle above it (0.4; where most cells around one have no point with that support, as under a
closed canopy, they are tried again with half the share, down to 1/16 of it). Under a partly closed
canopy 0.2 keeps more of the ground seen through the gaps (lidR's Megaplot: Type I 6.0 -> 0.03 %) but
accepts groups of multipath echoes as ground.</p>
<p>The defaults and what each choice does on the ISPRS filter-test samples are in
<a href="https://github.com/groundsieve/groundsieve/blob/main/docs/BENCHMARKS.md">the benchmarks</a>.</p>
""" + COMMON_HELP)
