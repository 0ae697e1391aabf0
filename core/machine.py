"""What this process may use of the machine: its memory and its cores, as a batch system grants them.

A job of SLURM, Kubernetes or systemd gets its memory as a control group's limit and its cores as a CPU
set (its affinity) or a CPU quota; Grid Engine's ``h_vmem`` and PBS's ``vmem`` limit the address space
(``ulimit -v``). The machine's RAM and ``os.cpu_count()`` ignore all four: a 2-core job on a 64-core node
planned 64 workers, and a job of 1.5 GB ran whole and died, as a research software engineer found.
"""
from __future__ import annotations

import contextlib
import math
import os
from typing import List, Optional

#: a control group's "no limit" (cgroup v1 writes 2**63 rounded down to a page)
_UNLIMITED = 1 << 60


def physical_memory_bytes() -> int:
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 << 30


def _cgroup_paths(proc_cgroup: str) -> List[tuple]:
    """(hierarchy, path) of this process's control groups: ("", path) for cgroup v2, (controllers, path)
    for v1."""
    paths = []
    with contextlib.suppress(OSError):
        with open(proc_cgroup) as f:
            for line in f:
                parts = line.rstrip("\n").split(":", 2)
                if len(parts) == 3:
                    paths.append((parts[1], parts[2]))
    return paths


def _ancestors(path: str) -> List[str]:
    """``path`` and each folder above it, to the root: a limit set on any of them holds."""
    parts = [p for p in path.split("/") if p]
    return ["/" + "/".join(parts[:i]) if i else "" for i in range(len(parts), -1, -1)]


def _read_number(path: str) -> Optional[int]:
    with contextlib.suppress(OSError, ValueError):
        with open(path) as f:
            text = f.read().split()
        if text and text[0] != "max":
            return int(text[0])
    return None


def _memory_groups(root: str, proc_cgroup: str):
    """(limit, usage or None) of each of this process's control groups, and those above them, that has a memory
    limit (v2 ``memory.max`` and ``memory.current``, v1 ``memory.limit_in_bytes`` and ``memory.usage_in_bytes``).
    A container sees its own group as the mount's root, so the mount's top files count too."""
    for controllers, path in _cgroup_paths(proc_cgroup):
        if controllers == "":
            files = [(f"{root}{p}/memory.max", f"{root}{p}/memory.current") for p in _ancestors(path)]
        elif "memory" in controllers.split(","):
            files = [(f"{root}/memory{p}/memory.limit_in_bytes", f"{root}/memory{p}/memory.usage_in_bytes")
                     for p in _ancestors(path)]
        else:
            continue
        for limit_file, usage_file in files:
            limit = _read_number(limit_file)
            if limit is not None and 0 < limit < _UNLIMITED:
                yield limit, _read_number(usage_file)


def cgroup_memory_limit(root: str = "/sys/fs/cgroup", proc_cgroup: str = "/proc/self/cgroup") -> Optional[int]:
    """The smallest memory limit of this process's control group and those above it; None without one."""
    return min((limit for limit, _used in _memory_groups(root, proc_cgroup)), default=None)


def cgroup_memory_left(root: str = "/sys/fs/cgroup", proc_cgroup: str = "/proc/self/cgroup") -> Optional[int]:
    """What this process's control groups with a memory limit have left of it (limit less usage), the
    smallest; None without a limit. A grid's guard took the whole limit for what was free (a code reviewer)."""
    return min((max(0, limit - (used or 0)) for limit, used in _memory_groups(root, proc_cgroup)), default=None)


def cgroup_cpu_limit(root: str = "/sys/fs/cgroup", proc_cgroup: str = "/proc/self/cgroup") -> Optional[int]:
    """The cores a control group's CPU quota allows (v2 ``cpu.max``, v1 ``cpu.cfs_quota_us`` over
    ``cpu.cfs_period_us``), rounded up; None without a quota."""
    quotas = []
    for controllers, path in _cgroup_paths(proc_cgroup):
        for p in _ancestors(path):
            if controllers == "":
                with contextlib.suppress(OSError, ValueError):
                    with open(f"{root}{p}/cpu.max") as f:
                        quota, period = (f.read().split() + ["100000"])[:2]
                    if quota != "max" and int(period) > 0:
                        quotas.append(int(quota) / int(period))
            elif "cpu" in controllers.split(","):
                quota = _read_number(f"{root}/{controllers}{p}/cpu.cfs_quota_us")
                period = _read_number(f"{root}/{controllers}{p}/cpu.cfs_period_us")
                if quota is not None and quota > 0 and period:
                    quotas.append(quota / period)
    return max(1, math.ceil(min(quotas) - 1e-9)) if quotas else None


def usable_cpus() -> int:
    """The cores this process may run on: its CPU set (``taskset``, SLURM's cpusets), at most its control
    group's quota; ``os.cpu_count()`` where neither can be read."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        n = os.cpu_count() or 1
    quota = cgroup_cpu_limit()
    return max(1, min(n, quota) if quota else n)


#: address_space_left(first=True)'s answer, by limit: what was left the first time it was asked
_FIRST_LEFT: dict = {}


def address_space_left(first: bool = False) -> Optional[int]:
    """What is left below the address-space limit (``ulimit -v``, ``RLIMIT_AS``) when one is set: the limit
    less this process's virtual size now (``first``: when this process first asked, under the same limit,
    so that a run's budget does not shrink as it goes); None without a limit."""
    with contextlib.suppress(ImportError, OSError, ValueError):
        import resource
        soft, _hard = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            if first and soft in _FIRST_LEFT:
                return _FIRST_LEFT[soft]
            used = 0
            with open("/proc/self/status") as f:
                for line in f:
                    if line.startswith("VmSize:"):
                        used = int(line.split()[1]) * 1024
                        break
            left = max(0, soft - used)
            _FIRST_LEFT.setdefault(soft, left)
            return left
    return None


def machine_memory_bytes() -> int:
    """The memory this process's job has: the machine's RAM, at most its control group's limit."""
    limit = cgroup_memory_limit()
    ram = physical_memory_bytes()
    return min(ram, limit) if limit else ram


#: address space a thread that calls BLAS takes on its first call, beyond any budget: OpenBLAS's buffer (a
#: code reviewer saw malloc(134221824) in gdb); when it cannot have it, OpenBLAS retries for ever, and under
#: ulimit -v 800000 two tile threads waited there with the run at 30 %, SIGTERM unheard
BLAS_BUFFER_BYTES = 128 << 20
#: address space a run takes beyond its budget and its BLAS buffers: the threads' stacks (numba's, lazrs's,
#: the pool's), what two malloc arenas keep; a run with one worker and a budget of 120 MB was done where 260 MB
#: were left beyond the budget (ulimit -v 1000000, bench/ulimit.py)
RUN_OVERHEAD_BYTES = 64 << 20


def address_space_reserve(workers: int) -> int:
    """What a run of ``workers`` tiles at a time needs of the address space beyond its memory budget (the
    BLAS buffers are a pool the threads share: one for each thread that calls BLAS at once)."""
    return RUN_OVERHEAD_BYTES + BLAS_BUFFER_BYTES * max(1, int(workers))


def warm_blas(callers: int, seconds: float = 0.1) -> None:
    """Under an address-space limit, have OpenBLAS take its buffers now, one for each of ``callers`` threads
    that call it at once, while the run has not yet filled the address space: a sparse solve (SuperLU, which
    calls BLAS's dtrsv without Python's lock, as the fills of SMRF and PMF do) from that many threads at once.
    OpenBLAS keeps the buffers it made and hands them to later callers; one it cannot make later, it retries
    for ever (a code reviewer's run waited at 30 % with SIGTERM unheard, under ulimit -v 800000, and mine under
    1000000 with a budget and a reserve counted for it). Nothing without a limit."""
    if address_space_left() is None or callers < 1:
        return
    import threading
    import time

    import numpy as np
    try:
        from scipy.sparse import diags, kron, identity
        from scipy.sparse.linalg import splu
    except ImportError:
        return
    n = 40  # a 40 x 40 grid's Laplacian: dense enough for supernodes, which SuperLU solves with dtrsv
    line = diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(n, n))
    lu = splu((kron(line, identity(n)) + kron(identity(n), line)).tocsc())
    rhs = np.ones(n * n)
    start = threading.Barrier(callers)

    def solve():
        start.wait()
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            lu.solve(rhs)
    threads = [threading.Thread(target=solve, name="groundsieve-blas-warm", daemon=True) for _ in range(callers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()


def check_address_space(workers: int) -> None:
    """Refuse a run that an address-space limit (``ulimit -v``) leaves too little to take its BLAS buffers
    and threads (:func:`address_space_reserve`) and some tiles: there OpenBLAS waits for ever (a code reviewer).
    Nothing without a limit."""
    left = address_space_left(first=True)
    need = address_space_reserve(workers) + (64 << 20)
    if left is not None and left < need:
        from .errors import MemoryBudgetError
        raise MemoryBudgetError(
            f"the address-space limit (ulimit -v) leaves {left / 2**20:,.0f} MB to this run, which needs about "
            f"{need / 2**20:,.0f} MB beyond Python and its libraries for {max(1, int(workers))} worker(s) (their BLAS "
            "buffers, threads and some tiles): raise the limit (by "
            f"{(need - left) / 2**20:,.0f} MB or more) or use fewer workers")


#: malloc arenas a process keeps under an address-space limit (glibc's default: 8 a core, each reserving 64 MB)
ARENAS_UNDER_LIMIT = 2


def fit_address_space() -> bool:
    """Under an address-space limit (``ulimit -v``), have glibc's malloc keep ARENAS_UNDER_LIMIT arenas:
    each thread's own arena reserves 64 MB of address space it mostly never uses, and under
    ``ulimit -v 1200000`` a tiled run's threads ended the process at their start ("cannot allocate memory
    for thread-local data: ABORT", no message of ours); with two arenas it ran. True when done; False
    without a limit or where the C library is not glibc."""
    if address_space_left() is None:
        return False
    set_option = mallopt()
    if set_option is None:
        return False
    M_ARENA_MAX = -8  # (malloc.h)
    return bool(set_option(M_ARENA_MAX, ARENAS_UNDER_LIMIT))


def mallopt():
    """glibc's ``mallopt`` (set an option of malloc), or None where the C library is not glibc."""
    import ctypes
    import ctypes.util
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt
    except (OSError, AttributeError):
        return None
