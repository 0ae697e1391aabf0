"""ISPRS error measures and kappa (core.metrics) against hand-computed and published values."""
from __future__ import annotations

import numpy as np
import pytest

from groundsieve.core.errors import InputError
from groundsieve.core.metrics import GroundAccuracy, ground_accuracy


def test_known_confusion_matrix():
    # 100 ground (80 found, 20 missed), 100 object (10 called ground, 90 right).
    acc = GroundAccuracy(tp=80, fn=20, fp=10, tn=90)
    assert acc.n == 200
    assert acc.type1 == pytest.approx(20 / 100)
    assert acc.type2 == pytest.approx(10 / 100)
    assert acc.total == pytest.approx(30 / 200)
    assert acc.accuracy == pytest.approx(170 / 200)
    # po = 0.85; pe = (100*90 + 100*110) / 200² = 0.5; kappa = (0.85 - 0.5) / 0.5
    assert acc.kappa == pytest.approx(0.7)
    assert acc.precision == pytest.approx(80 / 90)
    assert acc.recall == pytest.approx(0.8)
    assert acc.f1 == pytest.approx(160 / 190)
    np.testing.assert_array_equal(acc.confusion_matrix(), [[80, 20], [10, 90]])
    d = acc.as_dict()
    assert d["tp"] == 80 and d["kappa"] == pytest.approx(0.7) and d["total"] == pytest.approx(0.15)
    s = acc.summary()
    assert "Type I 20.00 %" in s and "Type II 10.00 %" in s and "total 15.00 %" in s and "kappa 70.00 %" in s


def test_unbalanced_matrix_by_hand():
    # 30 ground, 170 object; tp 25, fn 5, fp 15, tn 155
    acc = GroundAccuracy(tp=25, fn=5, fp=15, tn=155)
    po = 180 / 200
    pe = (30 * 40 + 170 * 160) / 200 ** 2
    assert acc.kappa == pytest.approx((po - pe) / (1 - pe))
    assert acc.type1 == pytest.approx(5 / 30)
    assert acc.type2 == pytest.approx(15 / 170)


def test_perfect_and_inverted():
    perfect = GroundAccuracy(tp=40, fn=0, fp=0, tn=60)
    assert perfect.total == 0 and perfect.kappa == pytest.approx(1.0)
    inverted = GroundAccuracy(tp=0, fn=40, fp=60, tn=0)
    assert inverted.total == 1.0 and inverted.kappa < 0
    chance = GroundAccuracy(tp=25, fn=25, fp=25, tn=25)
    assert chance.kappa == pytest.approx(0.0)


def test_degenerate_tables():
    empty = GroundAccuracy(0, 0, 0, 0)
    assert (empty.n, empty.type1, empty.type2, empty.total, empty.kappa, empty.f1) == (0, 0, 0, 0, 0, 0)
    only_ground = GroundAccuracy(tp=10, fn=0, fp=0, tn=0)
    assert only_ground.type2 == 0.0 and only_ground.kappa == 1.0  # pe = 1: agreement is total


def test_ground_accuracy_from_masks():
    rng = np.random.default_rng(0)
    ref = np.array([True] * 100 + [False] * 100)
    pred = np.array([True] * 80 + [False] * 20 + [True] * 10 + [False] * 90)
    perm = rng.permutation(200)
    acc = ground_accuracy(ref[perm], pred[perm])
    assert acc == GroundAccuracy(tp=80, fn=20, fp=10, tn=90)
    assert ground_accuracy(ref.astype(int), pred.astype(np.uint8)) == acc  # any truthy dtype


def test_ground_accuracy_size_mismatch():
    with pytest.raises(InputError, match="differ in size"):
        ground_accuracy(np.ones(5, bool), np.ones(6, bool))


# Sample counts (ground, object) from PUBLISHED_RESULTS.md.
COUNTS = {"samp11": (21786, 16224), "samp12": (26691, 25428), "samp21": (10085, 2875),
          "samp22": (22504, 10202), "samp23": (13223, 11872), "samp24": (5434, 2058),
          "samp31": (15556, 13306), "samp41": (5602, 5629), "samp42": (12443, 30027),
          "samp51": (13950, 3895), "samp52": (20112, 2362), "samp53": (32989, 1389),
          "samp54": (3983, 4625), "samp61": (33854, 1206), "samp71": (13875, 1770)}

# CSF (Zhang et al. 2016, Table 3): Type I %, Type II %, total %, kappa %.
CSF = {"samp11": (7.23, 18.44, 12.01, 75.17), "samp12": (1.15, 4.90, 2.97, 94.04),
       "samp21": (3.89, 1.78, 3.42, 90.47), "samp22": (1.29, 25.90, 8.94, 77.72),
       "samp23": (3.52, 6.21, 4.79, 90.38), "samp24": (1.03, 7.73, 2.87, 92.68),
       "samp31": (0.96, 2.38, 1.61, 96.75), "samp41": (1.48, 8.78, 5.14, 89.73),
       "samp42": (3.28, 0.87, 1.58, 96.18), "samp51": (2.67, 4.57, 3.08, 91.13),
       "samp52": (1.01, 28.79, 3.93, 77.05), "samp53": (3.85, 37.08, 5.20, 46.86),
       "samp54": (3.79, 2.64, 3.18, 93.61), "samp61": (0.87, 18.94, 1.49, 78.10),
       "samp71": (1.61, 37.85, 5.71, 68.03)}

# Pingel's Python re-implementation, optimized parameters (converted Type I/II), same file.
PINGEL_PY = {"samp11": (8.20, 10.52, 9.19, 81.23), "samp21": (0.45, 5.04, 1.47, 95.70),
             "samp23": (2.19, 6.27, 4.12, 91.73), "samp31": (0.44, 2.04, 1.18, 97.63),
             "samp41": (14.00, 9.15, 11.57, 76.86), "samp51": (0.44, 6.14, 1.68, 94.99),
             "samp52": (3.03, 12.79, 4.06, 79.60), "samp54": (2.33, 2.44, 2.39, 95.19)}


def from_rates(sample, type1_pct, type2_pct) -> GroundAccuracy:
    ground, obj = COUNTS[sample]
    fn = round(type1_pct / 100 * ground)
    fp = round(type2_pct / 100 * obj)
    return GroundAccuracy(tp=ground - fn, fn=fn, fp=fp, tn=obj - fp)


def test_csf_samp11_kappa():
    acc = from_rates("samp11", 7.23, 18.44)
    assert (acc.tp, acc.fn, acc.fp, acc.tn) == (20211, 1575, 2992, 13232)
    assert 100 * acc.total == pytest.approx(12.01, abs=0.01)
    assert 100 * acc.kappa == pytest.approx(75.17, abs=0.01)


@pytest.mark.parametrize("sample", sorted(CSF))
def test_csf_rows_are_reproduced(sample):
    t1, t2, total, kappa = CSF[sample]
    acc = from_rates(sample, t1, t2)
    # Type I/II are rounded to 0.01 %: the counts rebuilt from them are that close, no closer.
    assert 100 * acc.total == pytest.approx(total, abs=0.03)
    assert 100 * acc.kappa == pytest.approx(kappa, abs=0.05)


@pytest.mark.parametrize("sample", sorted(PINGEL_PY))
def test_pingel_python_rows_are_reproduced(sample):
    t1, t2, total, kappa = PINGEL_PY[sample]
    acc = from_rates(sample, t1, t2)
    assert 100 * acc.total == pytest.approx(total, abs=0.03)
    assert 100 * acc.kappa == pytest.approx(kappa, abs=0.05)


def test_pingel_python_means_used_by_the_accuracy_tests():
    """The two thresholds of test_smrf's ISPRS tests are these means over the 8 samples."""
    kappas = [v[3] for v in PINGEL_PY.values()]
    assert round(float(np.mean(kappas)), 2) == 89.12
    single_total = [9.49, 1.85, 5.89, 2.61, 11.33, 3.33, 4.10, 4.04]  # "Py Total % (single set)"
    assert round(float(np.mean(single_total)), 2) == 5.33
