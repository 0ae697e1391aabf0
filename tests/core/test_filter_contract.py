"""What every ground filter promises the driver, checked once for all of them: progress stays
within the range it is given, grows and ends at its top; a cancellation request stops the run
through ``run`` and through ``__call__``. Filter-specific progress counts and mid-run
cancellation are tested in each filter's own module."""
import numpy as np
import pytest

from groundsieve.core.csf import CSF
from groundsieve.core.echogrid import EchoGrid
from groundsieve.core.errors import Cancelled
from groundsieve.core.evc import EVC
from groundsieve.core.pmf import PMF
from groundsieve.core.progress import Steps
from groundsieve.core.ptd import PTD
from groundsieve.core.smrf import SMRF

FILTERS = [SMRF(), PMF(), CSF(), PTD(), EchoGrid(), EVC()]


def plane(size=20.0, density=4.0, seed=0):
    """A gently tilted, slightly noisy plane at UTM-sized coordinates."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, size, (int(size * size * density), 2))
    z = 100.0 + 0.02 * xy[:, 0] + rng.normal(0.0, 0.02, len(xy))
    return np.column_stack([xy + [512000.0, 5403000.0], z])


@pytest.mark.parametrize("algorithm", FILTERS, ids=lambda f: f.name)
def test_progress_within_a_sub_range(algorithm):
    seen = []
    algorithm.run(plane(), Steps(progress=seen.append).sub(0.2, 0.6))
    assert seen, "no progress reported"
    assert min(seen) >= 0.2 - 1e-12 and max(seen) <= 0.6 + 1e-12
    assert seen[-1] == pytest.approx(0.6)
    assert all(b >= a for a, b in zip(seen, seen[1:])), seen


@pytest.mark.parametrize("algorithm", FILTERS, ids=lambda f: f.name)
def test_cancelled_from_the_start(algorithm):
    xyz = plane()
    with pytest.raises(Cancelled):
        algorithm.run(xyz, Steps(is_cancelled=lambda: True))
    with pytest.raises(Cancelled):
        algorithm(xyz, steps=Steps(is_cancelled=lambda: True))
