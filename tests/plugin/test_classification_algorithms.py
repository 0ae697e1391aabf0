"""groundsieve:features, groundsieve:rftrain and groundsieve:rfclassify through processing.run."""
import numpy as np
import pytest

from .conftest import classes_of


@pytest.fixture(scope="module")
def labelled_pair(tmp_path_factory):
    """Two generated clouds of the same kind labelled with ASPRS 1 and 2 only."""
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    folder = tmp_path_factory.mktemp("rf")
    paths = []
    for seed in (21, 22):
        scene = make_scene(SceneSpec(size_m=90.0, density_per_m2=8.0, seed=seed))
        scene.classification[:] = np.where(scene.classification == 2, 2, 1)
        path = folder / f"scene{seed}.laz"
        write_scene(scene, str(path))
        paths.append(path)
    return paths


def _run(alg, params):
    import processing
    return processing.run(f"groundsieve:{alg}", params)


def test_train_with_defaults_then_classify_another_cloud(groundsieve_provider, labelled_pair, tmp_path):
    from osgeo import gdal
    from groundsieve.core.metrics import ground_accuracy
    train, test = labelled_pair
    model, report = tmp_path / "model.npz", tmp_path / "report.html"
    result = _run("rftrain", {"INPUT": str(train), "MODEL": str(model), "REPORT": str(report)})
    assert result["TEST_ACCURACY"] > 0.9
    html = report.read_text()
    assert "<svg" in html and "Permutation" in html and "test set" in html
    assert (tmp_path / "report.csv").read_text().startswith("set,class,precision")
    out, dtm = tmp_path / "classified.laz", tmp_path / "dtm.tif"
    counts = _run("rfclassify", {"INPUT": str(test), "MODEL": str(model), "OUTPUT": str(out), "DTM": str(dtm)})
    truth = classes_of(test) == 2
    predicted = classes_of(out)
    # the counts a model's next step takes, as the ground filters return them
    assert counts["GROUND_COUNT"] == int(np.sum(predicted == 2)) and counts["POINT_COUNT"] == len(predicted)
    assert set(np.unique(predicted)) <= {1, 2}
    acc = ground_accuracy(truth, predicted == 2)
    assert acc.total < 0.05, acc.summary()
    ds = gdal.Open(str(dtm))
    assert ds.RasterXSize > 40 and ds.GetRasterBand(1).GetNoDataValue() == -9999.0


def test_tampered_model_is_refused(groundsieve_provider, labelled_pair, tmp_path):
    from qgis.core import QgsProcessingException
    train, test = labelled_pair
    model = tmp_path / "model.npz"
    _run("rftrain", {"INPUT": str(train), "MODEL": str(model), "REPORT": str(tmp_path / "r.html"),
                     "TREES": 5, "PRESET": 2})
    with np.load(model, allow_pickle=False) as data:
        arrays = {name: data[name].copy() for name in data.files}
    arrays["threshold"][:] = 0.0
    with open(model, "wb") as handle:
        np.savez(handle, **arrays)
    out = tmp_path / "o.laz"
    with pytest.raises(QgsProcessingException, match="checksum"):
        _run("rfclassify", {"INPUT": str(test), "MODEL": str(model), "OUTPUT": str(out)})
    assert not out.exists()


def test_features_are_written_as_extra_bytes(groundsieve_provider, labelled_pair, tmp_path):
    import laspy
    train, _ = labelled_pair
    out = tmp_path / "features.laz"
    result = _run("features", {"INPUT": str(train), "OUTPUT": str(out)})
    names = result["FEATURES"].split(",")
    assert {"verticality_r0p6", "planarity_r0p6", "eigenentropy_r0p4", "surface_variation_r0p6"} <= set(names)
    las = laspy.read(str(out))
    for name in names:
        values = np.asarray(las[name])
        assert values.dtype == np.float32 and np.isfinite(values).mean() > 0.5
    np.testing.assert_array_equal(las.classification, laspy.read(str(train)).classification)


def test_training_reuses_features_already_in_the_file(groundsieve_provider, labelled_pair, tmp_path):
    """A cloud from groundsieve:features trains on its stored features (same names)."""
    train, _ = labelled_pair
    with_features = tmp_path / "features.laz"
    _run("features", {"INPUT": str(train), "OUTPUT": str(with_features)})
    result = _run("rftrain", {"INPUT": str(with_features), "MODEL": str(tmp_path / "m.npz"),
                              "REPORT": str(tmp_path / "r.html"), "PRESET": 5, "TREES": 20})
    assert result["TEST_ACCURACY"] > 0.8


def test_bad_classes_and_missing_feature(groundsieve_provider, labelled_pair, tmp_path):
    from qgis.core import QgsProcessingException
    train, _ = labelled_pair
    common = {"INPUT": str(train), "MODEL": str(tmp_path / "m.npz"), "REPORT": str(tmp_path / "r.html")}
    with pytest.raises(QgsProcessingException, match="class 9"):
        _run("rftrain", dict(common, CLASSES="2,9"))
    with pytest.raises(QgsProcessingException, match="red"):
        _run("rftrain", dict(common, PRESET=6, CUSTOM_FEATURES="red,return_number"))
    assert not (tmp_path / "m.npz").exists()


def test_training_without_scikit_learn_says_so(groundsieve_provider, labelled_pair, tmp_path, monkeypatch):
    from qgis.core import QgsProcessingException
    import groundsieve.dependencies as deps
    real = deps.missing_dependencies
    monkeypatch.setattr(deps, "missing_dependencies",
                        lambda extra=None: real(extra) + (["scikit-learn"] if extra else []))
    train, _ = labelled_pair
    with pytest.raises(QgsProcessingException, match="scikit-learn"):
        _run("rftrain", {"INPUT": str(train), "MODEL": str(tmp_path / "m.npz"), "REPORT": str(tmp_path / "r.html")})


def test_rfclassify_on_a_vpc_equals_the_file_run(groundsieve_provider, labelled_pair, tmp_path):
    """rfclassify given a virtual point cloud (two LAZ halves of one cloud) writes one classified file
    per input, with the classes of the run on the whole file (>= 99.9 %)."""
    import laspy
    from groundsieve.core.io.lasfiles import scan_header, write_vpc
    train, test = labelled_pair
    model = tmp_path / "model.npz"
    _run("rftrain", {"INPUT": str(train), "MODEL": str(model), "REPORT": str(tmp_path / "r.html"), "TREES": 10})
    _run("rfclassify", {"INPUT": str(test), "MODEL": str(model), "OUTPUT": str(tmp_path / "whole.laz")})
    whole = classes_of(tmp_path / "whole.laz")
    las = laspy.read(test)
    west = np.asarray(las.x) < np.median(np.asarray(las.x))
    halves = []
    (tmp_path / "tiles").mkdir()
    for name, part in (("west.laz", west), ("east.laz", ~west)):
        piece = laspy.LasData(las.header)
        piece.points = las.points[part]
        piece.write(tmp_path / "tiles" / name)
        halves.append(str(tmp_path / "tiles" / name))
    write_vpc(str(tmp_path / "survey.vpc"), [scan_header(p) for p in halves], halves)
    # a .vpc, and the folder of the two files (its label says it takes one: it once was refused)
    for source, out in ((tmp_path / "survey.vpc", "out"), (tmp_path / "tiles", "out_folder")):
        (tmp_path / out).mkdir()
        counts = _run("rfclassify", {"INPUT": str(source), "MODEL": str(model),
                                     "OUTPUT": str(tmp_path / out / "classified.vpc")})
        ground = 0
        for name, part in (("west.laz", west), ("east.laz", ~west)):
            got = classes_of(tmp_path / out / "classified" / name)
            assert np.mean(got == whole[part]) >= 0.999, (source, name)
            ground += int(np.sum(got == 2))
        assert counts["GROUND_COUNT"] == ground and counts["POINT_COUNT"] == len(whole), source


def test_ground_against_the_rest_for_any_features(groundsieve_provider, scene_laz, tmp_path):
    """GROUND_VS_REST trains a ground model (classes 2 and 1) on the paper's features too: the dialog had no
    route to one but the hybrid features (a UAV surveyor relabelled a patch with laspy)."""
    from groundsieve.core.learn.model_file import load_model
    src, _scene = scene_laz
    for ground, expected in ((False, None), (True, [1, 2])):
        model = tmp_path / f"m{ground}.npz"
        _run("rftrain", {"INPUT": str(src), "MODEL": str(model), "REPORT": str(tmp_path / f"r{ground}.html"),
                         "PRESET": 6, "CUSTOM_FEATURES": "intensity,return_number", "TREES": 3,
                         "GROUND_VS_REST": ground})
        classes = sorted(int(c) for c in load_model(str(model)).classes)
        assert classes == expected if expected else len(classes) > 2, classes
