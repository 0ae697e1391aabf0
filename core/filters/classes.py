"""The ground as the input's classes say: no filtering at all.

A vendor's deliverable, or a cloud classified by hand or by an earlier run, already holds its
ground (ASPRS class 2, perhaps model key points 8 and water 9 beside it). Making a DTM from it
should not filter it again: that changes the ground the vendor checked, and costs the filter's
time. :class:`ClassGround` takes the points of the given classes as the ground, so that the
engine's DTM (whole or in buffered tiles) is made from them as from any filter's ground
(PDAL's ``filters.range`` with ``Classification[2:2]`` before ``writers.gdal``; lasR's
``rasterize(1, tin(filter = keep_ground()))``).

It is a ground filter in form only: a small frozen parameter object called on the points of one
cloud or one buffered tile, which reads their class (``point_fields``) and nothing of their x, y, z
but the count.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, InvalidParameterError
from ..io.clouds import class_counts_text, count_classes, parse_classes
from ..progress import Steps
from ..validate import validate_xyz


@dataclass(frozen=True)
class ClassGroundResult:
    ground: np.ndarray
    #: why no point is ground (quoted when the DTM is refused), "" when some are
    no_ground_reason: str = ""


@dataclass(frozen=True)
class ClassGround:
    """The points whose class in the input is one of ``classes`` are the ground."""
    #: ASPRS codes: (2,), "2", "2, 8, 9", "2-3" (as the ignored classes are written)
    classes: object = (2,)
    #: metres per unit of the cloud's coordinates, set by the run (workflow.defaults_in_crs_unit): the
    #: tile buffer is 40 m in any unit (it was 40 ft on a cloud in feet: a code reviewer)
    metres_per_unit: float = 1.0

    name = "classes"
    point_fields = ("classification",)
    #: its ground is of any class (water 9 as well as ground 2): with the input's classes kept, it stays
    #: ground and keeps its class (workflow.classify_cloud)
    ground_of_any_class = True
    #: A tiled run's buffer (m): a tile's DTM cells are triangulated from the ground of the tile and
    #: of this much around it, so a gap in the ground up to this wide (a building, a pond without
    #: returns) is bridged as one triangulation of the whole survey bridges it; wider gaps may show the
    #: tile lines (the run's "Tile buffer" sets another). SMRF's own reach at its defaults is 38 m.
    REACH_M = 40.0
    #: a tile of a few points is still ground (the filters' grids need more: tiles.MIN_TILE_POINTS); a
    #: sparse delivery of key points lost every tile's ground (a code reviewer)
    min_tile_points = 1
    #: how a tiled run's log names the buffer and the tiles' work (it filters nothing)
    reach_words = "the default of a DTM from classes"
    tiles_done_words = "Made the DTM blocks of"
    #: a tile or a whole run costs no memory beyond its points and the DTM's (tiles.whole_run_bytes)
    extra_bytes_per_point = 0

    @property
    def stage_line(self) -> str:
        """What the engine's log says as the stage starts (it filters nothing)."""
        return f"Taking the points of the classes {self._codes()} as the ground ..."

    @property
    def no_ground_in_survey(self) -> str:
        """Why a survey's tiles found no ground (a tiled run's refusal quotes it)."""
        return self._no_ground("in it")

    def _codes(self) -> str:
        return ", ".join(str(c) for c in self.classes)

    def _no_ground(self, where: str) -> str:
        """Why no point is ground, the points named by ``where``, and what to do."""
        return (f"no point of class {self._codes()} {where}: classify the ground first with a ground filter, or "
                "name the classes that hold it")

    @property
    def reach_m(self) -> float:
        """The tile buffer, :data:`REACH_M` metres in the cloud's unit."""
        return self.REACH_M / self.metres_per_unit

    def __post_init__(self):
        if not (isinstance(self.metres_per_unit, (int, float)) and self.metres_per_unit > 0):
            raise InvalidParameterError(f"metres_per_unit must be > 0 (got {self.metres_per_unit!r})")
        codes = parse_classes(self.classes, what="ground classes")
        if not codes:
            raise InvalidParameterError("ground classes: name at least one class (2 is ground)")
        object.__setattr__(self, "classes", codes)

    def __call__(self, xyz, steps=None, **fields) -> np.ndarray:
        return self.run(xyz, steps, **fields).ground

    def run(self, xyz, steps: Steps | None = None, *, classification=None) -> ClassGroundResult:
        steps = steps or Steps()
        xyz = validate_xyz(xyz)
        if classification is None:
            raise InputError("the ground from classes needs the points' classes (a LAS/LAZ file)")
        classification = np.asarray(classification)
        if classification.shape != (xyz.shape[0],):
            raise InputError(f"classification: {classification.shape[0] if classification.ndim else 0:,} values "
                             f"for {xyz.shape[0]:,} points")
        steps.check()
        ground = np.isin(classification, self.classes)
        steps.report(1.0)
        if not ground.any():
            found = class_counts_text(count_classes(classification), most=6, largest_first=True)
            where = f"among the {xyz.shape[0]:,} points (their classes: {found})"
            return ClassGroundResult(ground, self._no_ground(where))
        return ClassGroundResult(ground)
