"""The return-number ("echo") grid filter of Matrone et al. (2024), their Method 2.

Faithful rule (the paper's MATLAB listing): square kernels of ``kernel_m`` tiled from the
cloud's lowest x and y (here by default from the multiples of ``kernel_m`` below them, so that a
tile of a survey and the whole survey share their kernels; ``kernel_origin="cloud"`` is the
listing's origin); in each kernel the lowest z; a point more than ``dz_m`` above it is
non-ground; a kernel in which every point has return number 1 is taken as ground whole,
without the height test (bare terrain mostly gives single returns). The paper loops over
every point for every kernel; here one pass gathers the kernel statistics and one classifies,
so the cost is linear in the number of points.

A cloud without return information (photogrammetry, ISPRS text, every point 1 of 1; or first
returns only, every return number 1 whatever the number of returns) would be all ground under that
rule: the filter then warns and applies the height test everywhere. Whether the cloud has echoes
(``echoes="auto"``: a return number above 1 somewhere) is decided once for a whole survey, not per
tile: :meth:`EchoGrid.for_survey` sets ``echoes="yes"`` when an input's header counts later
returns, so that a tile with single returns only still gets the bypass, as in a whole run.

``mode="evidence"`` is the improvement the paper's conclusion asks for, using the echoes as
evidence rather than as a bypass:

- a non-last return (return number < number of returns) is never ground: the pulse went on
  below it;
- a kernel whose lowest point is more than ``dz_m`` above the terrain reachable from the
  kernels within ``neighbourhood_m`` (their lowest points, each raised by ``slope`` times its
  distance) holds no ground (a roof, or a canopy no pulse went through): its points are tested
  against that reachable height instead of its own lowest point. The default neighbourhood is
  one kernel (the 3 x 3 kernels around); about half the width of the largest building (20 m)
  also finds the middle of wide flat roofs, but on the ISPRS sites it let low outliers and
  steep slopes spread and measured worse (mean kappa 53.5 against 66.9 with 5 m; see
  docs/BENCHMARKS.md); ``slope`` is the steepest terrain expected between kernel minima
  (0.15, SMRF's default);
- a kernel of single returns is bypassed only when its z range is within ``dz_m`` and it is
  not raised above its neighbours, so flat roofs and walls are not taken as ground.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import InvalidParameterError
from ..grids.spec import MAX_CELLS, check_memory
from ..progress import WARNING_PREFIX, Steps, run_cancellable
from ..validate import check_choice, check_number, validate_xyz

MODES = ("faithful", "evidence")


@dataclass(frozen=True)
class EchoGridResult:
    ground: np.ndarray
    used_returns: bool     #: False when the cloud had no return information (height test only)
    kernels: int           #: number of kernels holding points
    bypassed: int          #: kernels taken as ground without the height test


def _say_raised_bypass(raised_bypass, bypass, x, y, x0, y0, size, nx, echo, log) -> None:
    """Faithful mode: say how many of the kernels the single-return bypass makes ground whole stand above
    their surroundings (flat roofs are single-return surfaces too: a UAV surveyor's farm had 99.4 % of its
    roof points made ground, the DTM 4.9 m up, and the log spoke of 22 small spikes)."""
    n_raised = int(raised_bypass.sum())
    if not n_raised:
        return
    col = np.floor((x - x0) / size).astype(np.int64)
    row = np.floor((y - y0) / size).astype(np.int64)
    points = int(raised_bypass[row * nx + col].sum())
    log(f"{WARNING_PREFIX}Echo grid: {n_raised:,} of the {int(bypass.sum()):,} kernels the single-return bypass makes "
        f"ground whole ({points:,} points) stand more than {echo.dz_m:g} m above what a slope of {echo.slope:g} "
        f"reaches from the kernels within {echo.neighbourhood_m:g} m: flat roofs, most likely, which are "
        "single-return surfaces too, and these are their edges at least (a wide roof's inner kernels, beside other "
        "roof kernels, are not counted). The paper's rule (mode 'faithful') keeps them ground, and the DTM on them; "
        "mode 'evidence' keeps such raised kernels out (a wide roof's middle may stay ground; SMRF knows roofs).")


@dataclass(frozen=True)
class EchoGrid:
    """Parameters of the return-number grid filter (paper defaults: 5 m kernels, 2 m)."""
    kernel_m: float = 5.0
    dz_m: float = 2.0
    mode: str = "faithful"
    neighbourhood_m: float = 5.0    #: evidence mode only
    slope: float = 0.15             #: evidence mode only (rise/run)
    #: "grid": kernels on multiples of kernel_m (tiles agree with the whole); "cloud": from the
    #: cloud's lowest x, y (the paper's listing)
    kernel_origin: str = "grid"
    #: "auto": the cloud has echoes when a point has a return number above 1; "yes" / "no": given
    #: (a tiled run sets "yes" from the survey's headers, see for_survey)
    echoes: str = "auto"

    name = "echogrid"
    point_fields = ("return_number", "number_of_returns")
    wants_log = True

    def __post_init__(self):
        for name in ("kernel_m", "dz_m", "neighbourhood_m", "slope"):
            check_number(self, name)
        if not (math.isfinite(self.neighbourhood_m) and self.neighbourhood_m >= 0):
            raise InvalidParameterError(f"neighbourhood_m must be >= 0 (got {self.neighbourhood_m})")
        if not (math.isfinite(self.slope) and self.slope >= 0):
            raise InvalidParameterError(f"slope (rise/run) must be >= 0 (got {self.slope})")
        if not (math.isfinite(self.kernel_m) and self.kernel_m > 0):
            raise InvalidParameterError(f"kernel_m must be > 0 (got {self.kernel_m})")
        if not (math.isfinite(self.dz_m) and self.dz_m >= 0):
            raise InvalidParameterError(f"dz_m must be >= 0 (got {self.dz_m})")
        check_choice(self, "mode", MODES)
        check_choice(self, "kernel_origin", ("grid", "cloud"))
        check_choice(self, "echoes", ("auto", "yes", "no"))

    def for_survey(self, infos, log=None) -> "EchoGrid":
        """The filter a tiled run gives every tile (``infos``: the inputs' ``LasInfo``; ``log`` told
        what was decided): with ``echoes="auto"``, "yes" when the headers count points beyond return
        1, so that the bypass does not depend on what one tile holds. Headers that count none leave
        "auto"; so does a survey that mixes files with later returns and files without (first returns
        only, photogrammetry): "yes" would take every kernel of the latter as ground, so each tile
        decides from its own points, and the log says which files differ."""
        if self.echoes != "auto":
            return self
        log = log or (lambda _msg: None)
        counted = [i for i in infos if getattr(i, "count", 0) and getattr(i, "later_returns", None) is not None]
        with_echoes = [i for i in counted if i.later_returns]
        without = [i for i in counted if not i.later_returns]
        if with_echoes and without:
            log(f"{WARNING_PREFIX}Echo grid: {len(without)} file(s) have no later returns by their headers "
                f"({', '.join(os.path.basename(i.path) for i in without[:3])}{', ...' if len(without) > 3 else ''}) "
                f"where {len(with_echoes)} have: each tile decides from its own points whether the cloud has "
                "echoes, so tiles may differ from one another; run such files apart.")
            return self
        if with_echoes:
            log("Echo grid: the headers count later returns, so the cloud has echoes: every tile applies the "
                "paper's single-return bypass where its kernels hold single returns only.")
            return dataclasses.replace(self, echoes="yes")
        if without:  # said once here: a tile's own warning does not reach the run's log
            log(f"{WARNING_PREFIX}Echo grid: the headers count no return beyond the first (photogrammetry, first "
                "returns only, or a file without returns): the single-return bypass is off and every kernel gets "
                "the height test.")
        return self

    @property
    def reach_m(self) -> float:
        """How far (m) points influence a point's class: its own kernel (kernels sit on
        multiples of ``kernel_m``), and in evidence mode the kernels within ``neighbourhood_m``."""
        extra = self.neighbourhood_m if self.mode == "evidence" else 0.0
        return self.kernel_m + extra + self.kernel_m

    def __call__(self, xyz, steps=None, **fields) -> np.ndarray:
        return self.run(xyz, steps, **fields).ground

    def run(self, xyz, steps: Steps | None = None, *, return_number=None, number_of_returns=None,
            log=None) -> EchoGridResult:
        from ._echogrid_kernels import _echo_grid_classify_kernel, _echo_grid_stats_kernel, _lower_envelope_kernel
        steps = steps or Steps()
        log = log or (lambda _msg: None)
        xyz = validate_xyz(xyz)
        n = xyz.shape[0]
        x, y, z = (np.ascontiguousarray(xyz[:, i]) for i in range(3))
        rn = np.ones(n, np.uint8) if return_number is None else np.asarray(return_number, np.uint8)
        nr = np.ones(n, np.uint8) if number_of_returns is None else np.asarray(number_of_returns, np.uint8)
        if rn.shape != (n,) or nr.shape != (n,):
            raise InvalidParameterError("return_number and number_of_returns need one value per point")
        if self.echoes != "auto":
            has_returns = self.echoes == "yes"
        elif self.mode == "faithful":  # the bypass reads the return numbers only
            has_returns = bool((rn > 1).any())
        else:
            has_returns = bool((rn > 1).any() or (nr > 1).any())
        if not has_returns and self.echoes == "auto":
            if (nr > 1).any():
                log(f"{WARNING_PREFIX}Echo grid: every point has return number 1 although number of returns "
                    f"goes up to {int(nr.max())}: first returns only, or return numbers lost; the paper's "
                    "single-return bypass would take every kernel as ground, so it is off and every kernel "
                    "gets the height test (mode 'evidence' uses the number of returns).")
            else:
                log(f"{WARNING_PREFIX}Echo grid: the cloud has no return information (every point "
                    "is 1 of 1, or 0 of 0 as image-matching software writes it: photogrammetry, or a file "
                    "without returns); the single-return bypass is off and every "
                    "kernel gets the height test.")
        size = float(self.kernel_m)
        # Kernels sit on multiples of kernel_m (as GridSpec cells do), not on the cloud's lowest
        # corner: a tile of a survey and the whole survey then share their kernels.
        x0, y0 = float(x.min()), float(y.min())
        if self.kernel_origin == "grid":
            x0, y0 = math.floor(x0 / size) * size, math.floor(y0 / size) * size
        span = max(float(x.max()) - x0, float(y.max()) - y0)
        if size > span:
            log(f"Echo grid: the kernel ({size:g} m) is larger than the cloud ({span:.2f} m across): one "
                "kernel holds every point, so the test is against the cloud's single lowest point.")
        nx = int(math.floor((float(x.max()) - x0) / size)) + 1
        ny = int(math.floor((float(y.max()) - y0) / size)) + 1
        if nx * ny > MAX_CELLS:
            raise InvalidParameterError(f"kernel_m {size:g} makes {nx * ny:,} kernels; use larger kernels")
        # Per kernel: lowest and highest z, two flags, the reachable envelope, the reference (8-byte).
        check_memory(nx * ny * 48.0, what="Echo grid", shape=(ny, nx), cell=size, x=x, y=y)
        zmin = np.empty(nx * ny)
        zmax = np.empty(nx * ny)
        only_first = np.empty(nx * ny, dtype=np.bool_)
        only_single = np.empty(nx * ny, dtype=np.bool_)
        # per-point kernels in a worker thread: cancel honoured at once, the bar moves
        run_cancellable(_echo_grid_stats_kernel, x, y, z, rn, nr, x0, y0, size, nx, ny, zmin, zmax, only_first,
                        only_single, steps=steps.sub(0.0, 0.5), expected_s=3e-8 * n)
        occupied = np.isfinite(zmin)

        def raised_kernels():
            """The kernels whose lowest point stands more than dz above what the slope reaches from the kernels
            around (evidence mode's test; in faithful mode only counted, for the log)."""
            reachable = np.empty((ny, nx))
            run_cancellable(_lower_envelope_kernel, zmin.reshape(ny, nx), int(math.ceil(self.neighbourhood_m / size)),
                            size, float(self.slope), reachable, steps=steps.sub(0.5, 0.6))
            reachable = reachable.ravel()
            return reachable, occupied & (zmin > reachable + self.dz_m)  # empty kernels: inf > inf is False
        if self.mode == "faithful":
            reference = zmin
            bypass = only_first & occupied if has_returns else np.zeros_like(occupied)
            if bypass.any():
                _say_raised_bypass(bypass & raised_kernels()[1], bypass, x, y, x0, y0, size, nx, self, log)
        else:
            reachable, raised = raised_kernels()
            reference = np.where(raised, reachable, zmin)
            flat = (zmax - zmin) <= self.dz_m
            bypass = (only_single & flat & ~raised & occupied) if has_returns else np.zeros_like(occupied)
        ground = np.empty(n, dtype=np.bool_)
        run_cancellable(_echo_grid_classify_kernel, x, y, z, x0, y0, size, nx, np.ascontiguousarray(reference),
                        np.ascontiguousarray(bypass), float(self.dz_m), ground, steps=steps.sub(0.6, 0.99),
                        expected_s=3e-8 * n)
        if self.mode == "evidence" and has_returns:
            ground &= (rn >= nr) | (rn == 0)  # a return followed by others is not the ground (0: no number)
        steps.report(1.0)
        return EchoGridResult(ground, has_returns, int(occupied.sum()), int(bypass.sum()))

