"""Folders that refuse writes, for the robustness cases: a read-only folder (permissions for a
normal user; a read-only tmpfs mount for root, whom permissions do not stop) and a tiny tmpfs
that fills up (a full disk)."""
from __future__ import annotations

import contextlib
import hashlib
import os
import subprocess
from pathlib import Path

import pytest


def sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def everything_in(folder) -> list:
    """Every entry of ``folder``, hidden temporaries included."""
    return sorted(os.listdir(folder))


def _mount(folder: Path, options: str) -> bool:
    return subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                          capture_output=True).returncode == 0


@contextlib.contextmanager
def read_only_folder(base: Path):
    folder = base / "read-only"
    folder.mkdir()
    if os.geteuid() != 0:
        folder.chmod(0o555)
        try:
            yield folder
        finally:
            folder.chmod(0o755)
        return
    if not _mount(folder, "ro,size=64k"):
        pytest.skip("running as root, where permissions do not stop writes, and no read-only tmpfs can be mounted")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=False)


@contextlib.contextmanager
def full_disk(base: Path, size: str):
    """A tmpfs of ``size`` (e.g. "48k"): writes beyond it fail with ENOSPC, as on a full disk."""
    folder = base / "small-disk"
    folder.mkdir()
    if os.geteuid() != 0 or not _mount(folder, f"size={size}"):
        pytest.skip("a small tmpfs (a full disk) can only be mounted as root")
    try:
        yield folder
    finally:
        subprocess.run(["umount", str(folder)], check=False)
