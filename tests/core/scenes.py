"""Generated scenes with known truth for the ground-filter tests (SMRF, CSF, PMF, PTD): a plane
of uniform random points, lifted boxes (buildings without wall points) and scattered trees.

Import it as ``from groundsieve.tests.core.scenes import X0, Y0, BOX, add_trees, plane_scene``
(``.build/plugins`` on the path makes the checkout the ``groundsieve`` package, see
``tests/conftest.py``). Each scene draws from its own ``np.random.default_rng(seed)``: the same
arguments give the same points, bit for bit.
"""
from __future__ import annotations

import os
import signal

import numpy as np

X0, Y0 = 512000.0, 5403000.0  # UTM-sized coordinates, as real data

#: A 15 x 15 m building on the default 60 m plane, its edges on the 1 m cell edges.
BOX = (20.0, 35.0, 22.0, 37.0)


def plane_scene(seed=0, size=60.0, density=2.0, tilt=(0.0, 0.0), box=None, boxes=(), box_height=10.0,
                noise=0.0):
    """Uniform points on z = 100 + tilt·(x, y) (+ Gaussian noise of standard deviation ``noise``
    metres when not zero), ``density`` points per m² over a ``size`` x ``size`` m square whose
    south-west corner is (X0, Y0).

    ``box`` and each of ``boxes`` = (xmin, xmax, ymin, ymax), in metres from that corner, is lifted
    by ``box_height`` (a building without wall points; where boxes overlap, their heights add).
    Returns xyz (n, 3) and the true ground mask (False on the boxes).

    The random draws are, in this order: x, y, then the noise if any.
    """
    rng = np.random.default_rng(seed)
    n = int(size * size * density)
    x = rng.uniform(0.0, size, n)
    y = rng.uniform(0.0, size, n)
    z = 100.0 + tilt[0] * x + tilt[1] * y
    if noise:
        z = z + rng.normal(0.0, noise, n)
    on_box = np.zeros(n, dtype=bool)
    for b in ([box] if box is not None else []) + list(boxes):
        inside = (x > b[0]) & (x < b[1]) & (y > b[2]) & (y < b[3])
        on_box |= inside
        z = z + box_height * inside
    return np.column_stack([x + X0, y + Y0, z]), ~on_box


def add_trees(xyz, truth, n, seed, size=60.0, tilt=(0.0, 0.0), heights=(4.0, 15.0)):
    """The scene ``xyz``, ``truth`` with ``n`` 'tree' points appended, which are not ground.

    The crowns are uniform over the ``size`` x ``size`` m square at (X0, Y0), each between
    ``heights`` (low, high) metres above the plane z = 100 + tilt·(x, y) (the ground of
    :func:`plane_scene` with the same ``tilt``), drawn from ``np.random.default_rng(seed)``:
    the crowns' (x, y) first, then their heights. Returns the new xyz and truth.
    """
    rng = np.random.default_rng(seed)
    crowns = rng.uniform(0, size, size=(n, 2))
    tree = np.column_stack([crowns[:, 0] + X0, crowns[:, 1] + Y0,
                            100.0 + tilt[0] * crowns[:, 0] + tilt[1] * crowns[:, 1]
                            + rng.uniform(heights[0], heights[1], n)])
    return np.vstack([xyz, tree]), np.concatenate([truth, np.zeros(n, dtype=bool)])


def flaky_smrf(budget: int = 3):
    """A new class of SMRF look-alikes that fail (``RuntimeError("killed")``) after ``budget`` tiles
    while its ``failing`` is set, counting its calls in ``calls``; its repr is the same either way,
    so that a second run finds the first one's working folder (the interrupted-run tests)."""
    from groundsieve.core.filters.smrf import SMRF

    class Flaky:
        reach_m = SMRF().reach_m
        failing, calls = True, 0

        def __repr__(self):
            return "Flaky()"

        def __call__(self, xyz, steps=None):
            type(self).calls += 1
            if type(self).failing and type(self).calls > budget:
                raise RuntimeError("killed")
            return SMRF()(xyz, steps)

    return Flaky


class CountedSMRF:
    """SMRF that appends its process id to ``log_path`` each time it is unpickled: how many times a
    run sent it to its worker processes. (Here, in a module the worker processes can import.)"""

    def __init__(self, log_path):
        from groundsieve.core.filters.smrf import SMRF
        self.log_path, self.reach_m = str(log_path), SMRF().reach_m

    def __repr__(self):
        return "CountedSMRF()"

    def __call__(self, xyz, steps=None):
        from groundsieve.core.filters.smrf import SMRF
        return SMRF()(xyz, steps)

    def __setstate__(self, state):
        self.__dict__.update(state)
        with open(self.log_path, "a") as f:
            f.write(f"{os.getpid()}\n")


def die_once_in(marker, key, function, job):
    """Run ``function(job)``, except the first time the job of tile ``key`` runs anywhere: then the
    worker process running it kills itself (SIGKILL), in the middle of the run. (For the Dask
    tests: here, in a module their worker processes can import.)"""
    if list(job["key"]) == list(key):
        try:
            os.close(os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:
            pass
        else:
            os.kill(os.getpid(), signal.SIGKILL)
    return function(job)


def four_file_survey(root) -> str:
    """A generated 120 m scene (seed 5, 2 points/m²) cut into 4 LAZ files of 60 x 60 m, a.laz (south-west),
    b.laz (south-east), c.laz (north-west) and d.laz (north-east), in ``root``/in; its path."""
    import laspy

    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    whole = os.path.join(root, "whole.laz")
    write_scene(make_scene(SceneSpec(size_m=120.0, density_per_m2=2.0, seed=5)), whole)
    las = laspy.read(whole)
    folder = os.path.join(root, "in")
    os.makedirs(folder)
    x0, y0 = las.header.mins[:2]
    qx, qy = np.asarray(las.x) >= x0 + 60.0, np.asarray(las.y) >= y0 + 60.0
    for name, sel in (("a", ~qx & ~qy), ("b", qx & ~qy), ("c", ~qx & qy), ("d", qx & qy)):
        part = laspy.LasData(las.header)
        part.points = las.points[sel]
        part.write(os.path.join(folder, f"{name}.laz"))
    return folder


def split_west_east(las, folder, names=("west.laz", "east.laz")):
    """Write the points of ``las`` (a laspy LasData) west and east of their median x as two files of
    ``folder`` (made), named ``names``; returns the west mask."""
    import laspy
    os.makedirs(folder, exist_ok=True)
    west = np.asarray(las.x) < np.median(np.asarray(las.x))
    for name, part in zip(names, (west, ~west)):
        piece = laspy.LasData(las.header)
        piece.points = las.points[part]
        piece.write(os.path.join(folder, name))
    return west
