"""EVC's point tolerance (ours) against matching blunders: floating points above the surface and clusters
below it, which take their small cell's class in the paper's method.

    .venv/bin/python bench/evc_noise.py [--density 60] [--size 40] [--relief 2] [--slope 3]

Generated photogrammetric scenes of low vegetation (bench/presets.py's ``uav-photo`` kind: the first return of
each pulse, 3 cm of matching noise; seeds 1-3), with 50 clusters/ha of 5 blunders 0.5-4 m below the surface
(``core/synthetic.py`` ``with_low_blunders``) and 400 points/ha 1-8 m above it (floating noise, added here).
EVC runs with the ``uav-photogrammetry-evc`` preset's values and point tolerances of 0 (the paper: every
point takes its cell's class), 0.2, 0.3, 0.5 and 1 m. Said, per seed: the total error against the truth (the
noise is not ground) and how many of the noise points were called ground.
"""
import argparse

from _checkout import REPO  # noqa: F401,E402 (puts this checkout's groundsieve on sys.path)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--density", type=float, default=60.0)
    parser.add_argument("--size", type=float, default=40.0)
    parser.add_argument("--relief", type=float, default=2.0)
    parser.add_argument("--slope", type=float, default=3.0)
    args = parser.parse_args()
    import numpy as np
    from groundsieve.core.engine.presets import load_preset
    from groundsieve.core.metrics import ground_accuracy
    from groundsieve.core.synthetic import SceneSpec, make_scene, photogrammetric, with_low_blunders
    import dataclasses
    preset = load_preset("uav-photogrammetry-evc", "evc").build()
    tolerances = (0.0, 0.2, 0.3, 0.5, 1.0)
    print(f"uav-photo scenes of {args.size:g} m at {args.density:g} points/m², relief {args.relief:g} m, slope "
          f"{args.slope:g} %; EVC with the uav-photogrammetry-evc preset")
    print("| seed | points | noise | " + " | ".join(f"tolerance {t:g} m: total, noise called ground" for t in tolerances)
          + " |\n|---|---:|---:|" + "---:|" * len(tolerances))
    for seed in (1, 2, 3):
        scene = photogrammetric(make_scene(SceneSpec(size_m=args.size, density_per_m2=args.density, trees_per_ha=0.0,
                                                     shrub_fraction=0.35, buildings_per_ha=0.0, relief_m=args.relief,
                                                     slope_pct=args.slope, seed=seed)))
        scene = with_low_blunders(scene, 50.0)
        rng = np.random.default_rng(seed + 100)
        m = int(400.0 * np.ptp(scene.x) * np.ptp(scene.y) / 1e4)
        at = rng.choice(len(scene), m, replace=False)
        x = np.r_[scene.x, scene.x[at] + rng.normal(0, 0.05, m)]
        y = np.r_[scene.y, scene.y[at] + rng.normal(0, 0.05, m)]
        z = np.r_[scene.z, scene.z[at] + rng.uniform(1.0, 8.0, m)]
        truth = np.r_[scene.classification, np.full(m, 18, np.uint8)]
        noise = (truth == 7) | (truth == 18)
        cells = []
        for t in tolerances:
            ground = dataclasses.replace(preset, point_tolerance_m=t)(np.c_[x, y, z])
            acc = ground_accuracy(truth == 2, ground)
            cells.append(f"{100 * acc.total:.2f} %, {int((ground & noise).sum())}")
        print(f"| {seed} | {len(x):,} | {int(noise.sum())} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
