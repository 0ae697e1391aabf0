"""What a run may use of the machine, as a batch system grants it (core/machine.py): a research software
engineer's 2-core SLURM job on a large node planned every core of the node, and a job limited to 1.5 GB ran
a cloud whole that the default budget of the machine's RAM allowed, and died with a traceback."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest

from groundsieve.core import machine
from groundsieve.core.engine import tiles


def _cgroups(tmp_path, lines, files):
    tmp_path.mkdir(parents=True, exist_ok=True)
    proc = tmp_path / "cgroup"
    proc.write_text("".join(line + "\n" for line in lines))
    for rel, text in files.items():
        path = tmp_path / "fs" / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return str(tmp_path / "fs"), str(proc)


def test_a_cgroup_v2_memory_limit_of_the_group_or_a_group_above_it_is_found(tmp_path):
    root, proc = _cgroups(tmp_path, ["0::/slurm/job_42/step_0"], {
        "slurm/job_42/step_0/memory.max": "max\n",
        "slurm/job_42/memory.max": "1610612736\n",   # the job's --mem=1.5G
        "slurm/memory.max": "max\n",
        "memory.max": "max\n"})
    assert machine.cgroup_memory_limit(root, proc) == 1610612736


def test_a_cgroup_v1_memory_limit_is_found_and_its_no_limit_is_none(tmp_path):
    root, proc = _cgroups(tmp_path, ["4:memory:/job", "3:cpu,cpuacct:/job"], {
        "memory/job/memory.limit_in_bytes": "2147483648\n",
        "memory/memory.limit_in_bytes": "9223372036854771712\n"})
    assert machine.cgroup_memory_limit(root, proc) == 2 << 30
    root, proc = _cgroups(tmp_path / "b", ["4:memory:/"], {"memory/memory.limit_in_bytes": "9223372036854771712\n"})
    assert machine.cgroup_memory_limit(root, proc) is None
    assert machine.cgroup_memory_limit(str(tmp_path / "none"), str(tmp_path / "none.txt")) is None


def test_a_cpu_quota_counts_its_cores_rounded_up(tmp_path):
    root, proc = _cgroups(tmp_path, ["0::/kubepods/pod1"], {"kubepods/pod1/cpu.max": "150000 100000\n",
                                                           "kubepods/cpu.max": "max 100000\n"})
    assert machine.cgroup_cpu_limit(root, proc) == 2
    root, proc = _cgroups(tmp_path / "b", ["2:cpu,cpuacct:/docker/x"], {
        "cpu,cpuacct/docker/x/cpu.cfs_quota_us": "-1\n", "cpu,cpuacct/docker/x/cpu.cfs_period_us": "100000\n",
        "cpu,cpuacct/docker/cpu.cfs_quota_us": "300000\n", "cpu,cpuacct/docker/cpu.cfs_period_us": "100000\n"})
    assert machine.cgroup_cpu_limit(root, proc) == 3


def test_every_core_means_the_cores_this_process_may_use(monkeypatch):
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0}, raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 64)
    monkeypatch.setattr(machine, "cgroup_cpu_limit", lambda *a: None)
    assert machine.usable_cpus() == 1
    assert tiles.TileOptions().worker_count == 1 and tiles.TileOptions(workers=3).worker_count == 3
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: set(range(64)), raising=False)
    monkeypatch.setattr(machine, "cgroup_cpu_limit", lambda *a: 4)
    assert tiles.TileOptions().worker_count == 4


def test_the_default_budget_is_a_quarter_of_the_jobs_memory(monkeypatch):
    monkeypatch.setattr(machine, "physical_memory_bytes", lambda: 256 << 30)
    monkeypatch.setattr(machine, "cgroup_memory_limit", lambda *a: 2 << 30)
    monkeypatch.setattr(machine, "address_space_left", lambda first=False: None)
    assert tiles.default_memory_budget_mb() == 512
    monkeypatch.setattr(machine, "cgroup_memory_limit", lambda *a: None)
    assert tiles.default_memory_budget_mb() == 2048


def _limited(before: str, after: str) -> str:
    """The output of Python code run in a process of its own: ``before``, then its address space limited to
    what it uses and 1 GB more, then ``after``."""
    code = ("import resource\n" + before
            + "used = int(next(l.split()[1] for l in open('/proc/self/status') if l.startswith('VmSize:'))) * 1024\n"
            "resource.setrlimit(resource.RLIMIT_AS, (used + (1 << 30), resource.RLIM_INFINITY))\n" + after)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS and /proc are Linux's")
def test_the_default_budget_stays_below_ulimit_v():
    out = _limited("from groundsieve.core.engine import tiles\n"
                   "from groundsieve.core.machine import address_space_left\n"
                   "assert address_space_left() is None, address_space_left()\n"
                   "free = tiles.default_memory_budget_mb()\n",
                   "left = address_space_left()\n"
                   "print(free, tiles.default_memory_budget_mb(), left)\n")
    free, limited, left = map(float, out.split())
    assert 0 < left <= 1 << 30
    assert limited <= 0.6 * left / (1 << 20) + 1 and limited < free


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS, /proc and glibc are Linux's")
def test_under_ulimit_v_malloc_keeps_few_arenas():
    out = _limited("from groundsieve.core.machine import fit_address_space\n"
                   "before = fit_address_space()\n",
                   "print(before, fit_address_space())\n")
    assert out.split() == ["False", "True"]


def test_a_tile_out_of_memory_is_a_memory_error_that_says_what_to_change(tmp_path):
    """Under ulimit -v 1000000 a tile's numpy allocation failed: "tile ... failed: MemoryError", kind "other"
    on the command line. It is the memory kind, with what to change."""
    from groundsieve.core.engine.workflow import FilterOptions, run_ground_filter
    from groundsieve.core.errors import MemoryBudgetError
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    src = tmp_path / "s.laz"
    write_scene(make_scene(SceneSpec(size_m=60.0, density_per_m2=2.0, seed=3)), str(src))

    class Hungry:
        reach_m = 5.0

        def __call__(self, xyz, steps=None):
            raise MemoryError("Unable to allocate 35.6 MiB for an array")
    hungry = Hungry()
    with pytest.raises(MemoryBudgetError, match=r"^tile .* of s.laz: out of memory \(Unable to allocate 35.6 MiB.*\); "
                                                r"give a smaller memory budget \(the log's first lines say this run's\)"):
        run_ground_filter(str(src), None, hungry, options=FilterOptions(tiling=tiles.TileOptions(
            tile_size_m=30.0, workers=1, buffer_m=5.0)))


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="RLIMIT_AS, /proc and glibc are Linux's")
def test_too_little_address_space_is_refused_before_the_run_and_enough_warms_blas():
    """Under ulimit -v 800000 a run tiled, then two threads waited for ever in OpenBLAS's allocation of its
    buffer, SIGTERM unheard (a code reviewer). Too little is refused at once; enough has OpenBLAS take its
    buffers before the tiles (machine.warm_blas)."""
    out = _limited("from groundsieve.core import machine\n"
                   "from groundsieve.core.errors import MemoryBudgetError\n"
                   "need = machine.address_space_reserve(2) + (64 << 20)\n",
                   "try:\n    machine.check_address_space(2)\n    print('ran')\n"
                   "except MemoryBudgetError as err:\n    print('refused' if 'ulimit -v' in str(err) else err)\n"
                   "print(need < (1 << 30))\n")
    assert out.split() == ["ran", "True"]  # (1 GB left: enough, and the warm-up did not hang or fail)
    code = ("import resource\nfrom groundsieve.core import machine\n"
            "used = int(next(l.split()[1] for l in open('/proc/self/status') if l.startswith('VmSize:'))) * 1024\n"
            "resource.setrlimit(resource.RLIMIT_AS, (used + (200 << 20), resource.RLIM_INFINITY))\n"
            "try:\n    machine.check_address_space(2)\n    print('ran')\n"
            "except Exception as err:\n    print(type(err).__name__, err)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    said = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert said.startswith("MemoryBudgetError the address-space limit (ulimit -v) leaves 2") and "raise the limit" in said


def test_running_out_of_memory_reading_a_file_is_said_as_memory_not_damage(tmp_path, monkeypatch):
    """Under ulimit -v 1000000 a file's reading ran out of memory: "cannot read its points ...; the file is
    damaged or truncated", kind input (a code reviewer)."""
    import laspy

    from groundsieve.core.engine.workflow import run_ground_filter
    from groundsieve.core.errors import MemoryBudgetError
    from groundsieve.core.filters.smrf import SMRF
    from groundsieve.core.synthetic import SceneSpec, make_scene, write_scene
    src = tmp_path / "s.laz"
    write_scene(make_scene(SceneSpec(size_m=40.0, density_per_m2=2.0, seed=3)), str(src))

    def no_memory(self, n):
        raise MemoryError("Allocation failed (probably too large).")
    monkeypatch.setattr(laspy.LasReader, "read_points", no_memory)
    for options in (None, _tiled_options()):
        with pytest.raises(MemoryBudgetError, match=r"s.laz: out of memory \(Allocation failed"):
            run_ground_filter(str(src), str(tmp_path / "o.laz"), SMRF(), options=options)


def _tiled_options():
    from groundsieve.core.engine.workflow import FilterOptions
    return FilterOptions(tiling=tiles.TileOptions(tile_size_m=20.0, workers=1))


def test_what_a_cgroup_limit_has_left_is_the_limit_less_its_usage(tmp_path):
    root, proc = _cgroups(tmp_path, ["0::/job"], {"job/memory.max": "2147483648\n", "job/memory.current": "1610612736\n",
                                                 "memory.max": "max\n"})
    assert machine.cgroup_memory_left(root, proc) == 512 << 20
    root, proc = _cgroups(tmp_path / "v1", ["4:memory:/job"], {"memory/job/memory.limit_in_bytes": "1073741824\n",
                                                              "memory/job/memory.usage_in_bytes": "268435456\n"})
    assert machine.cgroup_memory_left(root, proc) == 768 << 20
