"""Worker processes against threads on small and mid-size surveys (issue #10: "measure and keep what
is faster here"): the same folder of generated LAZ blocks filtered (SMRF, 1 m DTM, 200 m tiles) in
this process one tile at a time, on 2 spawned worker processes, and on 2 threads; twice each.

    .venv/bin/python bench/pool_start.py MILLIONS FILES      (e.g. 1 8, then 10 20)
"""
import sys, os, time, tempfile, shutil
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _checkout import REPO  # noqa: F401,E402 (puts this checkout's groundsieve on sys.path)
from cluster import make_blocks
from groundsieve.core.engine.tiles import TileOptions
from groundsieve.core.engine.workflow import DTMOptions, FilterOptions, run_ground_filter
from groundsieve.core.filters.smrf import SMRF
def main():
    base = tempfile.mkdtemp(dir=os.environ.get("TMPDIR"))
    m = float(sys.argv[1]); files = int(sys.argv[2])
    survey, points, nfiles = make_blocks(base, m, files)
    print(points, nfiles)
    for rep in range(2):
        for par, w in (("threads", 1), ("processes", 2), ("threads", 2)):
            out = os.path.join(base, f"o-{par}{w}-{rep}"); os.makedirs(out)
            t = time.perf_counter(); l0 = os.getloadavg()[0]
            lines = []
            run_ground_filter(survey, os.path.join(out, "c.vpc"), SMRF(), options=FilterOptions(tiling=TileOptions(
                workers=w, parallel=par, tile_size_m=200)), dtm_path=os.path.join(out, "d.tif"), dtm=DTMOptions(cell_size_m=1.0), log=lines.append)
            print(f"{par:9s} x{w}: {time.perf_counter()-t:6.1f} s  load {l0:.1f}->{os.getloadavg()[0]:.1f}", [l for l in lines if l.startswith(("Binned","Filtered","Wrote"))], flush=True)
    shutil.rmtree(base)
if __name__ == "__main__":
    main()
