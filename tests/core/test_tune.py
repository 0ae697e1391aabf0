"""groundsieve:tune's search (core/engine/tune.py) and its report (core/engine/tune_report.py) on
generated labelled patches: the labels it accepts and refuses, the spatial blocks, SMRF's re-scored
last step against the whole filter, the search (deterministic, within its budget, better than the
defaults where they are wrong, honest folds) and the HTML report."""
from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from groundsieve.core.engine import tune as T
from groundsieve.core.engine.tune_report import report_html, write_report
from groundsieve.core.errors import Cancelled, InputError, InvalidParameterError
from groundsieve.core.filters.smrf import SMRF
from groundsieve.core.io.clouds import PointCloud
from groundsieve.tests.core.scenes import add_trees, plane_scene

#: a 40 x 40 m building: larger than SMRF's default window (18 m radius covers it, but the
#: default threshold and a 5 m window miss it); two smaller ones and trees
BIG = (5.0, 45.0, 10.0, 50.0)


def patch_cloud(label=None, seed=1, path="patch.txt"):
    xyz, truth = plane_scene(seed=seed, size=80.0, density=1.5, boxes=[BIG, (55.0, 70.0, 55.0, 72.0)],
                             box_height=8.0, tilt=(0.05, 0.02))
    xyz, truth = add_trees(xyz, truth, 600, seed + 10, size=80.0, tilt=(0.05, 0.02))
    n = len(xyz)
    lab = (~truth).astype(np.uint8) if label is None else label(truth)
    ones = np.ones(n, dtype=np.uint8)
    return PointCloud(path=path, x=xyz[:, 0], y=xyz[:, 1], z=xyz[:, 2], classification=np.zeros(n, np.uint8),
                      return_number=ones, number_of_returns=ones.copy(), reference_label=lab)


@pytest.fixture(scope="module")
def result():
    # a small window start: the defaults' 18 m is replaced by 4 m so that the search must move
    return T.tune(patch_cloud(), "smrf", T.TuneOptions(budget=8, blocks=4), base={"window_m": 4.0})


def test_a_patch_without_ground_or_without_objects_is_refused_naming_the_file():
    with pytest.raises(InputError, match=r"nog\.txt: the tuning patch holds no ground points"):
        T.tune(patch_cloud(lambda t: np.ones(len(t), np.uint8), path="nog.txt"), "smrf", T.TuneOptions(budget=4))
    with pytest.raises(InputError, match=r"noobj\.txt: the tuning patch holds no non-ground points"):
        T.tune(patch_cloud(lambda t: np.zeros(len(t), np.uint8), path="noobj.txt"), "smrf",
               T.TuneOptions(budget=4))
    cloud = patch_cloud(path="nolabel.txt")
    cloud.reference_label = None
    with pytest.raises(InputError, match=r"nolabel\.txt: the tuning patch has no labels"):
        T.tune(cloud, "smrf", T.TuneOptions(budget=4))


def test_options_are_checked():
    for bad in (dict(metric="rmse"), dict(budget=2), dict(blocks=1), dict(blocks=40), dict(seconds=-1),
                dict(selection="lowest"), dict(selection="one-se", blocks=2)):
        with pytest.raises(InvalidParameterError):
            T.TuneOptions(**bad)


def test_spatial_blocks_have_equal_counts_and_follow_the_patch_shape():
    rng = np.random.default_rng(0)
    x, y = rng.uniform(0, 200, 4000), rng.uniform(0, 50, 4000)
    block, (nx, ny) = T.spatial_blocks(x, y, 4)
    assert (nx, ny) == (4, 1)  # a long strip is cut across its length
    assert sorted(np.bincount(block)) == [1000] * 4
    order = [x[block == b].mean() for b in range(4)]
    assert order == sorted(order)
    block, (nx, ny) = T.spatial_blocks(x, x.copy() * 1.0 + y, 6)
    assert nx * ny == 6 and np.bincount(block).min() >= 666


def test_smrf_last_step_rescored_on_one_run_equals_the_whole_filter():
    cloud = patch_cloud()
    xyz = cloud.xyz
    surface = T._smrf_surface(SMRF(window_m=12.0, slope=0.2), xyz, None)
    for thr, scalar in ((0.5, 1.25), (0.1, 0.0), (1.1, 3.8), (0.35, 2.2)):
        fast = T._smrf_ground(surface, xyz, {"elevation_threshold_m": thr, "elevation_scalar": scalar})
        full = SMRF(window_m=12.0, slope=0.2, elevation_threshold_m=thr, elevation_scalar=scalar)(xyz)
        np.testing.assert_array_equal(fast, full)


@pytest.mark.parametrize("keep_bytes", [None, 0])
def test_runs_sharing_one_minimum_surface_equal_fresh_runs(monkeypatch, keep_bytes):
    """The search makes SMRF's minimum surface once and reuses it for every slope and window, with the
    progressive opening's drops per radius (unless they would take too much memory)."""
    import groundsieve.core.filters.smrf as smrf_module
    if keep_bytes is not None:
        monkeypatch.setattr(smrf_module, "KEEP_OPENINGS_BYTES", keep_bytes)
    xyz = patch_cloud().xyz
    shared = {}
    for slope, window in ((0.2, 12.0), (0.05, 30.0), (0.4, 3.0)):
        algorithm = SMRF(window_m=window, slope=slope)
        grid, zpro, slope_grid = T._smrf_surface(algorithm, xyz, None, shared)
        fresh = algorithm.run(xyz)
        np.testing.assert_array_equal(zpro, fresh.provisional_surface)
        np.testing.assert_array_equal(T._smrf_ground((grid, zpro, slope_grid), xyz,
                                                     {"elevation_threshold_m": 0.5, "elevation_scalar": 1.25}),
                                      fresh.ground)
    assert len(shared) == 1
    minimum = next(iter(shared.values()))
    if keep_bytes is None:
        assert len(minimum.openings[1]) == 30  # the drops of radii 1..30 (the 30 m window), kept
    else:
        assert minimum.openings == []  # over the memory cap: nothing kept, progressive_filter as usual
    assert not minimum.zmin.flags.writeable
    with pytest.raises(InvalidParameterError, match="minimum surface"):
        SMRF(cell_size_m=2.0).surface(xyz, None, minimum)


def test_the_search_stays_in_its_budget_and_beats_a_wrong_start(result):
    assert result.runs <= 8
    assert len(result.trials) > result.runs  # threshold and scalar re-scored on each run
    start = result.start_accuracy.total
    assert result.trials[result.default_trial].values["window_m"] == 4.0
    # the 40 m building is kept as ground by a 4 m window: the search must find a larger one
    assert result.best_values["window_m"] > 20.0
    assert result.best_accuracy.total < 0.5 * start
    assert result.cv.total < 0.5 * start
    # every searched value inside its range
    for d in result.dims:
        v = result.best_values[d.field]
        assert (v in d.values) if d.values else d.low <= v <= d.high


def test_the_cross_validation_is_honest(result):
    """Each block's set is chosen without that block: from the design (or the start) and the sets
    the refinement that left the block out proposed itself, never from one that saw it; the CV confusion is the sum
    of the held-out blocks' own counts, and covers every point once."""
    assert [f.block for f in result.folds] == [0, 1, 2, 3]
    for f in result.folds:
        t = result.trials[f.chosen]
        assert t.phase in ("start", "design") or f.block in t.proposed_by
        held = T.accuracy(t.counts[f.block])
        assert held == f.held_out
        others = [b for b in range(4) if b != f.block]
        pool = [i for i, u in enumerate(result.trials) if u.phase in ("start", "design") or f.block in u.proposed_by]
        assert t.loss("total", others) == min(result.trials[i].loss("total", others) for i in pool)
    assert result.cv.n == result.points
    assert result.best == min(range(len(result.trials)), key=lambda i: (result.trials[i].loss("total"), i))


def test_the_search_is_deterministic(result):
    again = T.tune(patch_cloud(), "smrf", T.TuneOptions(budget=8, blocks=4), base={"window_m": 4.0})
    assert [t.values for t in again.trials] == [t.values for t in result.trials]
    assert again.best == result.best and again.cv == result.cv


def _trial(values, errors, n=100):
    """A trial with ``errors[b]`` misclassified points of ``n`` (as fn) in block b."""
    counts = np.array([[n // 2 - e, e, 0, n // 2] for e in errors])
    return T.Trial(dict(values), counts, 0.0, "design")


def test_the_one_standard_error_rule_takes_the_set_nearest_the_start_among_the_near_best():
    dims = [T.Dim("W", "window_m", 2.0, 30.0), T.Dim("S", "slope", 0.0, 1.0)]
    start = {"window_m": 18.0, "slope": 0.15}
    trials = [
        _trial({"window_m": 29.0, "slope": 0.9}, [2, 2, 2, 2]),     # lowest error, far from the start
        _trial({"window_m": 17.0, "slope": 0.2}, [6, 0, 5, 0]),     # 0.75 point worse, noisy: within 1 SE
        _trial({"window_m": 18.0, "slope": 0.15}, [5, 5, 5, 5]),    # the start: 3 points worse, every block
        _trial({"window_m": 10.0, "slope": 0.5}, [3, 1, 4, 1]),     # within 1 SE too, but farther
    ]
    blocks = [0, 1, 2, 3]
    assert T.choose(trials, range(4), blocks, "total") == 0
    assert T.choose(trials, range(4), blocks, "total", "one-se", start, dims) == 1
    # the rule cannot take a set that is worse on every block by more than the spread
    assert T.choose(trials, [0, 2], blocks, "total", "one-se", start, dims) == 0
    # on the blocks it is chosen on only: without blocks 0 and 2, set 1 is the best outright
    assert T.choose(trials, range(4), [1, 3], "total", "one-se", start, dims) == 1
    failed = T.Trial(dict(start), None, 0.0, "design", error="too big")
    assert T.choose(trials + [failed], range(5), blocks, "total", "one-se", start, dims) == 1
    # paired: a set worse by the same 2 points on every block is out, however much the blocks differ
    # (an unpaired standard error of its own block errors, about 3 points here, would let it in)
    paired = [_trial({"window_m": 29.0, "slope": 0.9}, [0, 10, 0, 10]),
              _trial({"window_m": 18.0, "slope": 0.15}, [2, 12, 2, 12])]
    assert T.choose(paired, range(2), blocks, "total", "one-se", start, dims) == 0


def test_the_one_standard_error_rule_with_kappa_and_a_block_of_one_class():
    """A block with ground only: one error there takes its kappa from 1 to 0. A set several times worse
    on the other blocks and with that one error must not pass for a near-best set (the pooled kappa's
    gap, 0.10, is below the standard error of the per-block differences, 0.22; their mean, 0.34, is not)."""
    dims = [T.Dim("W", "window_m", 2.0, 30.0)]
    start = {"window_m": 18.0}
    good = T.Trial({"window_m": 29.0}, np.array([[49, 1, 0, 50], [50, 0, 1, 49], [50, 0, 0, 50], [100, 0, 0, 0]]),
                   0.0, "design")
    bad = T.Trial({"window_m": 18.0}, np.array([[46, 4, 3, 47], [47, 3, 4, 46], [47, 3, 3, 47], [99, 1, 0, 0]]),
                  0.0, "design")
    assert T.choose([good, bad], range(2), [0, 1, 2, 3], "kappa", "one-se", start, dims) == 0
    assert T.choose([good, bad], range(2), [0, 1, 2, 3], "total", "one-se", start, dims) == 0


def test_the_one_standard_error_rule_in_a_search():
    """Folds and preset are chosen by the rule, each on its own blocks; the preset records it."""
    r = T.tune(patch_cloud(), "smrf", T.TuneOptions(budget=8, blocks=4, selection="one-se"),
               base={"window_m": 4.0})
    start = {d.field: r.fixed[d.field] for d in r.dims}
    assert r.selection == "one-se" and T.preset_source(r)["selection"] == "one-se"
    assert r.best == T.choose(r.trials, range(len(r.trials)), [0, 1, 2, 3], "total", "one-se", start, r.dims)
    for f in r.folds:
        others = [b for b in range(4) if b != f.block]
        pool = [i for i, u in enumerate(r.trials) if u.phase in ("start", "design") or f.block in u.proposed_by]
        assert f.chosen == T.choose(r.trials, pool, others, "total", "one-se", start, r.dims)
    best = T.choose(r.trials, range(len(r.trials)), [0, 1, 2, 3], "total")
    assert r.best != best  # on this patch the rule takes another set than the lowest error
    assert "one-standard-error rule" in report_html(r)


def test_kappa_and_f1_are_maximised():
    r = T.tune(patch_cloud(), "smrf", T.TuneOptions(budget=5, metric="kappa"))
    kappas = [T.accuracy(t.counts.sum(axis=0)).kappa for t in r.trials]
    assert r.best_accuracy.kappa == max(kappas)


def test_a_filter_without_rescoring_counts_one_run_per_set():
    r = T.tune(patch_cloud(), "pmf", T.TuneOptions(budget=5, blocks=2))
    assert r.runs == len(r.trials) <= 5
    assert set(r.best_values) == {f for f in r.fixed}


def test_cancel_stops_the_search():
    calls = []

    def cancelled():
        calls.append(1)
        return len(calls) > 3
    with pytest.raises(Cancelled):
        T.tune(patch_cloud(), "smrf", T.TuneOptions(budget=8), is_cancelled=cancelled)


def test_the_report_is_self_contained_with_a_plot_per_parameter(result, tmp_path):
    path = tmp_path / "tune.html"
    write_report(str(path), result)
    text = path.read_text(encoding="utf-8")
    assert "Cross-validated total error" in text and "http://" not in text.replace(
        'xmlns="http://www.w3.org/2000/svg"', "")
    svgs = [text[i:text.index("</svg>", i) + 6] for i in range(len(text)) if text.startswith("<svg", i)]
    assert len(svgs) == len(result.dims) + 1  # one per parameter, and the convergence
    for svg in svgs:
        root = ET.fromstring(svg)  # well-formed
        assert len(root.findall("{http://www.w3.org/2000/svg}circle")) >= 5
    assert f"{100 * result.cv.total:.2f} %" in text
    assert report_html(result) == text.rstrip("\n") + "\n" or report_html(result) == text


def test_a_choice_at_an_end_of_its_range_is_said_in_the_report(result, tmp_path):
    """A chosen value at an end of its searched range may hide a better one beyond: the report (and
    the command line and the dialog's log, from the same sentence) says so; a value inside does not."""
    import dataclasses
    d = next(d for d in result.dims if not d.values)
    best = result.trials[result.best]

    def choosing(value):
        trials = list(result.trials)
        trials[result.best] = dataclasses.replace(best, values=dict(best.values, **{d.field: value}))
        return dataclasses.replace(result, trials=trials)
    high, low, inside = choosing(d.high), choosing(d.low), choosing((d.low + d.high) / 2)
    assert (d, "upper") in high.at_range_ends and (d, "lower") in low.at_range_ends
    assert d not in [e for e, _ in inside.at_range_ends]
    note = high.range_end_note()
    assert f"{d.name} ({d.high:g}) at the upper end of its searched range ({d.low:g} to {d.high:g})" in note
    assert note.count(": the best value may lie beyond") == 1
    path = tmp_path / "edge.html"
    write_report(str(path), high)
    assert "At the end of a range:" in path.read_text(encoding="utf-8")
    if not inside.at_range_ends:
        write_report(str(path), inside)
        assert "At the end of a range" not in path.read_text(encoding="utf-8")


def test_a_window_wider_than_the_patch_is_said_in_the_report(result, tmp_path):
    """SMRF's window is a radius: one whose disk spans more than the patch acts on the patch as any
    larger one would, so its tuned value says little of the survey's; the report (and the command
    line and the dialog's log, from the same list) says so. A window inside the patch does not."""
    import dataclasses
    d = next(d for d in result.dims if d.name == "WINDOW")
    best = result.trials[result.best]
    side = max(result.extent)
    assert side > 10  # the patch's extent is known

    def choosing(value):
        trials = list(result.trials)
        trials[result.best] = dataclasses.replace(best, values=dict(best.values, **{d.field: value}))
        return dataclasses.replace(result, trials=trials)
    wide, narrow = choosing(side * 0.6), choosing(side * 0.4)
    titles = [title for title, _text in wide.warnings]
    assert "Beyond the patch" in titles and "Beyond the patch" not in [t for t, _ in narrow.warnings]
    text = dict(wide.warnings)["Beyond the patch"]
    assert text.startswith(f"WINDOW ({side * 0.6:g} m, a radius) reaches beyond the patch (")
    path = tmp_path / "wide.html"
    write_report(str(path), wide)
    assert "Beyond the patch:" in path.read_text(encoding="utf-8")


def test_a_search_no_better_than_its_start_says_so(result, tmp_path):
    """A geomorphologist's tuned preset scored 4.32 % cross-validated where the defaults, fitted to
    nothing, made 2.92 % on the same patch, and nothing said so: the report, the command line and
    the dialog's log (the same list) now do; a search that beats its start does not."""
    import dataclasses
    assert "No better than the start" not in dict(result.warnings)  # 4 m window: the search wins
    trials = list(result.trials)
    start = trials[result.default_trial]
    perfect = start.counts.copy()
    perfect[:, 0] += perfect[:, 1]  # every ground point found (fn -> tp) ...
    perfect[:, 3] += perfect[:, 2]  # ... and no object called ground (fp -> tn)
    perfect[:, 1] = perfect[:, 2] = 0
    trials[result.default_trial] = dataclasses.replace(start, counts=perfect)
    beaten = dataclasses.replace(result, trials=trials)
    text = dict(beaten.warnings)["No better than the start"]
    assert text.startswith(f"The tuned sets' cross-validated total error ({100 * result.cv.total:.2f} %) is no better "
                           "than the starting set's on the whole patch (0.00 %)")
    path = tmp_path / "nogain.html"
    write_report(str(path), beaten)
    assert "No better than the start:" in path.read_text(encoding="utf-8")
    # kappa and F1 are maximised: a start with kappa 1 is not beaten either; the real start is
    for metric, name in (("kappa", "kappa"), ("f1", "F1")):
        text = dict(dataclasses.replace(beaten, metric=metric).warnings)["No better than the start"]
        assert text.startswith(f"The tuned sets' cross-validated {name} (") and "(100.00 %)" in text
        assert "No better than the start" not in dict(dataclasses.replace(result, metric=metric).warnings)


def test_evc_s_search_takes_in_the_ground_offset_from_the_paper_s_zero():
    """The ground offset (ours; 0 = the paper) was the EVC setting that helped a photogrammetry reviewer's cloud
    most (19.5 % total error with the EVC preset, 15.3 % with 0.1 m), and tune kept it: it is searched from
    the paper's 0 over 0-0.3 m, on a generated photogrammetric patch of low vegetation."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, photogrammetric
    scene = photogrammetric(make_scene(SceneSpec(size_m=30.0, density_per_m2=60.0, trees_per_ha=0.0,
                                                 shrub_fraction=0.35, buildings_per_ha=0.0, seed=4)))
    n = len(scene)
    ones = np.ones(n, dtype=np.uint8)
    cloud = PointCloud(path="photo.txt", x=scene.x, y=scene.y, z=scene.z, classification=np.zeros(n, np.uint8),
                       return_number=ones, number_of_returns=ones.copy(),
                       reference_label=(scene.classification != 2).astype(np.uint8))
    r = T.tune(cloud, "evc", T.TuneOptions(budget=6, blocks=2))
    # 0 is the lowest offset the filter takes: no "the best value may lie beyond" for it (a code reviewer)
    import dataclasses
    at_zero = dataclasses.replace(r, best=0)  # (the start, the paper's 0, taken as the best)
    assert at_zero.best_values["ground_offset_m"] == 0.0
    assert "GROUND_OFFSET" not in {d.name for d, _end in at_zero.at_range_ends}
    assert "GROUND_OFFSET" not in at_zero.range_end_note()
    offsets = [t.values["ground_offset_m"] for t in r.trials]
    assert offsets[0] == 0.0 and r.trials[0].phase == "start"
    assert 0.0 <= min(offsets) < max(offsets) <= 0.3
    assert "ground_offset_m" in r.best_values
