"""A large model in tiles on worker processes and on a Dask LocalCluster: what sending it costs.

    .venv/bin/python bench/model_jobs.py [--millions 1] [--files 16] [--tile 25] [--model PATH]

The model is a default ``rftrain`` model (HYBRID features, 100 trees, 100,000 samples a tree) trained on
../shared/data/lasR_bcts/bcts_1.laz (a real labelled survey; its forest is tens of MB), or, without
shared/, on a generated scene; or ``--model``. A generated scene of about N million points cut into
``--files`` LAZ files (bench/cluster.py's survey) is classified by the command line's rfclassify in tiles
of ``--tile`` m, each run in a fresh process: on 2 worker processes, then on a LocalCluster of 2 workers.
Said: the model's pickled size, the tiles, wall seconds and the peak resident memory of each run with its
workers and (for Dask) its scheduler, sampled every 0.1 s; and whether the two runs' classes are the same.
"""
import argparse
import os
import pickle
import re
import sys
import tempfile

from _checkout import REPO  # noqa: E402 (puts this checkout's groundsieve on sys.path)

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster import make_survey  # noqa: E402
from rf_tiles import run  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--millions", type=float, default=1.0)
    parser.add_argument("--files", type=int, default=16)
    parser.add_argument("--tile", type=float, default=25.0)
    parser.add_argument("--model", default=None)
    parser.add_argument("--folder", default=None, help="keep the files here (default: a temporary folder)")
    args = parser.parse_args()
    import laspy
    import numpy as np
    from groundsieve.core.engine import learning
    from groundsieve.core.engine.learning import ModelGround
    work = args.folder or tempfile.mkdtemp(prefix="model_jobs_")
    os.makedirs(work, exist_ok=True)
    survey = os.path.join(work, "survey", "survey")
    if not os.path.isdir(survey):
        os.makedirs(os.path.dirname(survey), exist_ok=True)
        survey = make_survey(os.path.dirname(survey), args.millions, args.files)[0]
    model = args.model
    if model is None:
        model = os.path.join(work, "model.npz")
        bcts = REPO.parent / "shared" / "data" / "lasR_bcts" / "bcts_1.laz"
        if not os.path.exists(model):
            source = str(bcts)
            if not bcts.exists():
                from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
                source = os.path.join(work, "train.laz")
                write_scene(make_scene(SceneSpec(size_m=250.0, density_per_m2=10.0, seed=5)), source)
            learning.train_file(source, model, None, learning.TrainOptions())
            print(f"model trained on {source}")
    size = len(pickle.dumps(ModelGround(model), protocol=pickle.HIGHEST_PROTOCOL))
    points = sum(int(laspy.open(os.path.join(survey, n)).header.point_count) for n in os.listdir(survey))
    print(f"{points:,} points in {len(os.listdir(survey))} files; tiles of {args.tile:g} m; the model pickles to "
          f"{size / 1e6:.1f} MB")
    print("| run | tiles | wall s | peak MB |\n|---|---:|---:|---:|")
    classes = {}
    for label, extra in (("2 worker processes", ["--workers", "2"]), ("Dask LocalCluster, 2 workers",
                                                                     ["--scheduler", "local:2"])):
        out = tempfile.mkdtemp(dir=work)
        seconds, peak, log = run(["rfclassify", "--input", survey, "--model", model, "--output",
                                  os.path.join(out, "classified.vpc"), "--tile-size", str(args.tile)] + extra,
                                 keep_log=True)
        tiles = re.search(r"Filtered ([\d,]+) tile", log)
        print(f"| {label} | {tiles.group(1) if tiles else '?'} | {seconds:.1f} | {peak:,.0f} |", flush=True)
        folder = os.path.join(out, "classified")
        classes[label] = np.concatenate([np.asarray(laspy.read(os.path.join(folder, n)).classification)
                                         for n in sorted(os.listdir(folder))])
    a, b = classes.values()
    print(f"the two runs' classes: {'the same' if np.array_equal(a, b) else 'different'} ({len(a):,} points)")


if __name__ == "__main__":
    main()
